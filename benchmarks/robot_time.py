"""Robot time, side by side (issue 75): what a robot waits for, on every kind of scene, in one run.

    .venv/bin/python benchmarks/robot_time.py [--busy] [--per-family 6] [--towers 60] [--repeats 3]
                                              [--steps zoo_2026,...] [--out benchmarks/results/robot_time]

One after another, each with the default queries and 2 workers, each script writing its own results
under OUT (their own READMEs say what they measure):
- the scene zoo on the standard seed (2026) and the held-out one (2027): `default` checked and
  unchecked against `paper`, with `paper` at half its step as the chaos yardstick (``zoo.py``);
- the authors' towers, `default` against `paper` (``preset_trial.py`` with no change);
- the robot questions: the support graph, "safe to remove the top block?" and the best of 16 places,
  at the paper's 4 cm and a robot's 5 mm, checked and unchecked (``actions.py``);
- the depth example end to end: one 640 x 480 image of the 10-block tower, the chain and the
  prediction (``depth.py --scenes 0``).

``--busy``: the same again with a busy process beside it (one process spinning on a core, as a
robot's computer runs its own stack), started here and ended by its pid; it also ends by itself
when this run does. A summary (``robot_time.md``) puts each figure beside the issue's target.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from ipe_ros.engine.scene.zoo import FAMILIES  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
PYTHON = sys.executable

#: spins one core until its parent (this run) is gone or an hour has passed: a robot's own load
SPINNER = ("import os, time\nparent, end = os.getppid(), time.monotonic() + 3600\n"
           "while os.getppid() == parent and time.monotonic() < end:\n    sum(range(10000))\n")


def steps(args, out: Path) -> list[tuple[str, list[str]]]:
    """(name, command) of each measurement."""
    zoo = [(f"zoo_{seed}", [str(HERE / "zoo.py"), "--per-family", str(args.per_family), "--samples", "16",
                            "--seed", str(seed), "--only", "paper-half-step,default,default-unchecked",
                            "--families", args.families, "--out", str(out / f"zoo_{seed}")]) for seed in (2026, 2027)]
    every = zoo + [
        ("towers", [str(HERE / "preset_trial.py"), "--set", "horizon_s=2.0", "--towers", str(args.towers),
                    "--out", str(out / "towers")]),
        ("questions", [str(HERE / "actions.py"), "--repeats", str(args.repeats), "--heights", "5", "--shelves", "1",
                       "--out", str(out / "questions")]),
        ("depth", [str(HERE / "depth.py"), "--scenes", "0", "--out", str(out / "depth")]),
    ]
    wanted = args.steps.split(",") if args.steps else [name for name, _ in every]
    unknown = sorted(set(wanted) - {name for name, _ in every})
    if unknown:
        raise SystemExit(f"--steps: unknown {unknown[0]!r}; choose from {', '.join(name for name, _ in every)}")
    return [(name, command) for name, command in every if name in wanted]


def run_all(args, out: Path) -> dict[str, float]:
    """Each step in turn; seconds each took."""
    walls = {}
    for name, command in steps(args, out):
        started = time.perf_counter()
        print(f"== {name}: {' '.join(command)}", flush=True)
        subprocess.run([PYTHON, *command], cwd=REPO, check=True)
        walls[name] = time.perf_counter() - started
    return walls


#: issue 75's own targets for the robot questions at a robot's noise (the others: actions.py's, issue 32's)
QUESTION_TARGETS = {"support graph, tower": "<= 2 s checked, within the check's bars of `paper`",
                    "best place": "<= 3 s checked, within the check's bars of `paper`"}


def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def summary(out: Path, ran: list[str]) -> list[str]:
    """The figures the issue sets targets for, read from the results of the steps that ``ran`` (in
    this run or an earlier one into the same folder)."""
    rows = []
    for seed, target in ((2026, 5.0), (2027, 4.0)):
        if f"zoo_{seed}" not in ran:
            continue
        zoo = _json(out / f"zoo_{seed}" / "zoo.json")
        missed = [family for family, v in zoo["verdicts"].items() if not all(v.values())]
        overall = zoo["overall"]
        rows.append((f"zoo, seed {seed}: `default` checked / unchecked vs `paper`",
                     f"{overall['default']:.1f}x / {overall['default-unchecked']:.1f}x; bars missed: "
                     f"{', '.join(missed) or 'none'}", f">= {target:g}x checked, every bar met"))
    if "towers" in ran:
        towers = _json(out / "towers" / "preset_trial.json")["rows"]["default"]
        rows.append(("the authors' towers, `default` vs `paper`",
                     f"{towers['speedup_vs_paper']:.1f}x, mean |dFF| {towers['mean_abs_dff']:.4f}",
                     ">= 10x, |dFF| <= 0.015"))
    questions = _json(out / "questions" / "actions.json")["questions"] if "questions" in ran else []
    for q in questions:
        target = next((t for start, t in QUESTION_TARGETS.items() if q["question"].startswith(start)
                       and q["question"].endswith("sigma 5 mm")), None)
        rows.append((q["question"], f"checked {q['checked_s']:.2f} s ({q['escalated_variants']} escalated, "
                                    f"{q.get('validated_variants', 0)} validated of {q['checked_variants']}), "
                                    f"unchecked {q['sequential_s']:.2f} s",
                     target or ("-" if q["target_s"] is None else f"(issue 32: <= {q['target_s']:g} s)")))
    if "depth" in ran:
        depth = _json(out / "depth" / "depth.json")["tower"]
        rows.append(("depth example end to end (10 blocks, k = 48)",
                     f"{depth['total_s']:.2f} s checked ({depth['chain_s']:.2f} s chain), "
                     f"{depth['total_unchecked_s']:.2f} s unchecked", "answered, not refused"))
    return [f"| {what} | {figure} | {target} |" for what, figure, target in rows]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--busy", action="store_true", help="with a process spinning on a core beside it")
    parser.add_argument("--per-family", type=int, default=6)
    parser.add_argument("--towers", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3, help="runs of each robot question (median)")
    parser.add_argument("--families", default=",".join(FAMILIES), help="the zoo's families")
    parser.add_argument("--steps", default=None, help="only these steps (comma-separated; default: all)")
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/robot_time"))
    args = parser.parse_args()
    out = Path(args.out) / ("busy" if args.busy else "quiet")
    out.mkdir(parents=True, exist_ok=True)
    spinner = subprocess.Popen([PYTHON, "-c", SPINNER]) if args.busy else None
    try:
        walls = run_all(args, out)
    finally:
        if spinner is not None:
            os.kill(spinner.pid, 15)
            spinner.wait(timeout=10)
    # steps run into this folder before (``--steps``) keep their figures and times
    record = out / "walls.json"
    walls = (json.loads(record.read_text()) if record.exists() else {}) | walls
    record.write_text(json.dumps(walls, indent=1) + "\n")
    machine = "beside a process spinning on one core" if args.busy else "a quiet machine"
    lines = [f"# Robot time, side by side ({time.strftime('%Y-%m-%d')}, 2 workers, {machine})", "",
             f"`.venv/bin/python benchmarks/robot_time.py{' --busy' if args.busy else ''} --per-family "
             f"{args.per_family} --towers {args.towers}`; wall {sum(walls.values()) / 60:.0f} min "
             f"({', '.join(f'{k} {v / 60:.0f}' for k, v in walls.items())}). Each step's own results beside this file.",
             "", "| what | measured | target (issue 75) |", "|---|---|---|", *summary(out, list(walls))]
    (out / "robot_time.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
