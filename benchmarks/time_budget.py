"""Where a prediction's time goes: one process, every sample timed part by part.

    .venv/bin/python benchmarks/time_budget.py [--towers N] [--samples 8] [--preset default]
                                               [--query fall] [--out benchmarks/results/time_budget]

Runs each tower's samples in this process (no worker pool, so the timers see everything) on the
towers of ../shared/data/battaglia2013/willitfall.csv (IPE_SHARED_DATA overrides) or, without that
file, on generated paper-style towers; sigma = 0.2 block short sides (0.04 m), phi = 0. pybullet is
watched through the simulation's probe (``ipe_ros.engine.simulation.Probe``): every pybullet step is
timed and filed by the step it ran at:

- settle: the first ``settle_s`` in substeps (shorter than the world's step),
- fine: the world's own step, until a collapse,
- collapse: the coarser steps after something fell,

and the rest of a sample's time is split into building the world, depenetration, and everything
else (drawing the noise, the rest and divergence checks, reading states, the query). Samples are
also split by outcome (did anything fall?) with their simulated time and how many ran to the horizon.

The projection to k = 48 on W workers multiplies the per-sample cost by 48 / W: it assumes the
near-perfect scaling that accuracy_vs_time.py's worker sweep measures (1.95x on two workers). It
answers "what would have to get cheaper to reach a latency": the ``stepSimulation`` part alone is a
floor for any setting that keeps the same steps.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from accuracy_vs_time import REPO, SIGMA_M, load_towers  # noqa: E402 - the same towers and noise
from ipe_ros.engine import ModelConfig, QuerySpec, preset  # noqa: E402
from ipe_ros.engine.sampling import rollout  # noqa: E402
from ipe_ros.engine.predict import make_tasks  # noqa: E402
from ipe_ros.engine.simulation import PHASES, Probe  # noqa: E402


class TimingProbe(Probe):
    """Times every pybullet step by the phase it ran in, and the build and depenetration parts."""

    def __init__(self) -> None:
        self.steps = dict.fromkeys(PHASES, 0)
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self.parts = {"build": 0.0, "depenetrate": 0.0}

    @contextlib.contextmanager
    def part(self, name):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.parts[name] += time.perf_counter() - start

    def step(self, phase, run):
        start = time.perf_counter()
        run()
        self.seconds[phase] += time.perf_counter() - start
        self.steps[phase] += 1


def measure(scenes, settings_name: str, samples: int, queries: frozenset[str]) -> dict:
    settings = preset(settings_name)
    model = ModelConfig(sigma_m=SIGMA_M, samples=samples)
    query = QuerySpec(queries=queries)
    timed = TimingProbe()
    tasks = [t for i, scene in enumerate(scenes) for t in make_tasks(scene, model, settings, query, seed=i)]
    rollout.run_sample(tasks[0])  # connect and warm up outside the timers
    outcomes = []  # (anything fell, simulated s, wall s)
    start_all = time.perf_counter()
    for task in tasks:
        start = time.perf_counter()
        outcome = rollout.run_sample(task, probe=timed)
        wall = time.perf_counter() - start
        if not outcome.ok:
            raise RuntimeError(f"sample {task.index} failed: {outcome.error}")
        result = outcome.rollouts[0]
        fell = bool(result.fallen.any()) if result.fallen is not None else bool(result.value("any_fell"))
        outcomes.append((fell, result.simulated_s, wall))
    total = time.perf_counter() - start_all
    spent = timed.parts
    n = len(tasks)
    stepping = sum(timed.seconds.values())
    parts = [(f"{phase} steps", timed.seconds[phase], timed.steps[phase]) for phase in PHASES]
    parts += [("world build", spent["build"], None), ("depenetration", spent["depenetrate"], None),
              ("checks, reads, noise, query", total - stepping - spent["build"] - spent["depenetrate"], None)]
    rows = [{"part": name, "ms_per_sample": 1e3 * seconds / n, "share": seconds / total,
             "steps_per_sample": None if steps is None else steps / n,
             "us_per_step": 1e6 * seconds / steps if steps else None}
            for name, seconds, steps in parts]
    horizon = settings.horizon_s
    by_outcome = []
    for fell in (False, True):
        chosen = [o for o in outcomes if o[0] == fell]
        if not chosen:
            continue
        simulated = np.array([o[1] for o in chosen])
        walls = np.array([o[2] for o in chosen])
        by_outcome.append({"anything_fell": fell, "samples": len(chosen), "mean_simulated_s": float(simulated.mean()),
                           "ran_to_horizon": float(np.mean(simulated >= horizon - 1e-9)),
                           "ms_per_sample": 1e3 * float(walls.mean()), "share_of_time": float(walls.sum() / total)})
    return {"preset": settings_name, "samples_run": n, "total_s": total, "ms_per_sample": 1e3 * total / n,
            "step_ms_per_sample": 1e3 * stepping / n, "parts": rows, "by_outcome": by_outcome}


def markdown(report: dict) -> str:
    r = report["result"]
    lines = [f"# Time budget: `{r['preset']}`, {report['towers']} towers x {report['samples']} samples, "
             f"queries {', '.join(report['queries'])}",
             "", f"{report['source']}; sigma = {SIGMA_M} m, phi = 0; one process; {report['machine']}; {report['date']}.",
             "", "| part | ms per sample | share | steps per sample | µs per step |", "|---|---|---|---|---|"]
    for row in r["parts"]:
        steps = "" if row["steps_per_sample"] is None else f"{row['steps_per_sample']:.1f}"
        per_step = "" if row["us_per_step"] is None else f"{row['us_per_step']:.0f}"
        lines.append(f"| {row['part']} | {row['ms_per_sample']:.2f} | {row['share']:.0%} | {steps} | {per_step} |")
    lines.append(f"| **total** | **{r['ms_per_sample']:.2f}** | 100% | | |")
    lines += ["", "| anything fell | samples | mean simulated s | ran to the horizon | ms per sample | share of time |",
              "|---|---|---|---|---|---|"]
    for row in r["by_outcome"]:
        lines.append(f"| {'yes' if row['anything_fell'] else 'no'} | {row['samples']} | {row['mean_simulated_s']:.2f} | "
                     f"{row['ran_to_horizon']:.0%} | {row['ms_per_sample']:.1f} | {row['share_of_time']:.0%} |")
    lines += ["", "Projected k = 48 latency (per-sample cost x 48 / workers, assuming perfect scaling):", "",
              "| workers | everything s | stepSimulation alone s |", "|---|---|---|"]
    for row in report["projection_k48"]:
        lines.append(f"| {row['workers']} | {row['everything_s']:.2f} | {row['steps_only_s']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=None, help="first N towers (default: all 60)")
    parser.add_argument("--samples", type=int, default=8, help="samples per tower")
    parser.add_argument("--preset", default="default")
    parser.add_argument("--query", default="fall")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "time_budget"))
    args = parser.parse_args()
    scenes, _, source = load_towers(args.towers)
    queries = frozenset(args.query.split(","))
    result = measure(scenes, args.preset, args.samples, queries)
    report = {"source": source, "towers": len(scenes), "samples": args.samples, "queries": sorted(queries),
              "machine": f"{os.cpu_count()} CPUs", "date": time.strftime("%Y-%m-%d"), "result": result,
              "projection_k48": [{"workers": w, "everything_s": result["ms_per_sample"] * 48 / w / 1e3,
                                  "steps_only_s": result["step_ms_per_sample"] * 48 / w / 1e3} for w in (1, 2, 4)]}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "time_budget.json").write_text(json.dumps(report, indent=1))
    text = markdown(report)
    (out / "time_budget.md").write_text(text)
    print(text)
    print(f"wrote {out}/time_budget.json, .md")


if __name__ == "__main__":
    main()
