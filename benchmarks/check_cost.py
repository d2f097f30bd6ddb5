"""Where a self-checked prediction's time goes, map call by map call, against the unchecked one.

    .venv/bin/python benchmarks/check_cost.py --towers 60 --samples 48
    .venv/bin/python benchmarks/check_cost.py --zoo 6 --samples 16    # the scene zoo, per family

Each tower is predicted twice on the same seeds and the same warm pool (2 workers, `default`,
queries fall), unchecked and self-checked, one after the other. The checked prediction's map calls
are sorted by what they ran: the fast samples with the verification (the first map), the last
quarter with the coverage sample picked ahead, a round of confirmation or coverage, and the
escalation (every sample at the reference). Per tower and overall: wall seconds per part, the
reference reruns, the verdict. It measures the floor that the README's "Self-checking answers"
argues: what the check adds beyond the fast samples, and which of its parts add it. Authors'
towers need ``../shared``; without it generated towers are used. With ``--zoo N`` the scenes are N
per zoo family (benchmarks/zoo.py's scenes, noise and queries) instead, and the parts are given per
family too.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from accuracy_vs_time import REPO, SIGMA_M, load_towers  # noqa: E402 - the same towers and noise
from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, preset  # noqa: E402
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK, NO_CHECK  # noqa: E402
from ipe_ros.engine.predict import predict  # noqa: E402
from ipe_ros.engine.predict import Context, Request
from ipe_ros.engine.scene.zoo import FAMILIES, family_of, family_queries, scene_zoo, zoo_sigma_m  # noqa: E402

PARTS = ("fast + verification", "last quarter + coverage", "confirmation or coverage round", "escalation")


def _part(n: int, tasks: int, references: int, samples: int) -> str:
    """What a checked prediction's n-th map call ran (its tasks, of them at the reference)."""
    if n == 0:
        return PARTS[0]
    if references > samples // 4:  # more than a round's few: every sample at the reference
        return PARTS[3]
    if n == 1 and tasks > references:  # the last quarter's fast samples, with or without a reference
        return PARTS[1]
    return PARTS[2]


def queries_for(scene, zoo: bool) -> QuerySpec:
    """The towers' benchmark asks fall; the zoo's asks what benchmarks/zoo.py asks (the node's default)."""
    return QuerySpec(queries=family_queries(family_of(scene)) if zoo else frozenset({"fall"}))


def model_for(scene, zoo: bool, samples: int) -> ModelConfig:
    """The towers' noise, or the zoo's (5% of each scene's smallest body, as benchmarks/zoo.py)."""
    return ModelConfig(sigma_m=zoo_sigma_m(scene) if zoo else SIGMA_M, samples=samples)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=60)
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--zoo", type=int, default=0, help="scenes per zoo family instead of towers")
    parser.add_argument("--families", default=",".join(FAMILIES), help="with --zoo: which families")
    parser.add_argument("--out", default=None, help="default: benchmarks/results/check_cost (or check_cost_zoo)")
    args = parser.parse_args()
    args.out = args.out or str(REPO / "benchmarks/results" / ("check_cost_zoo" if args.zoo else "check_cost"))
    if args.zoo:
        towers = scene_zoo(2026, args.zoo, tuple(args.families.split(",")))
        source = f"the scene zoo, {args.zoo} scenes per family (seed 2026)"
    else:
        towers, _, source = load_towers(args.towers)
    settings = preset("default")
    rows = []
    with WorkerPool(args.workers) as pool:
        pool.warm()
        calls: list[tuple[int, int, float]] = []

        def timed_map(fn, items, on_lost=None):
            items = list(items)
            start = time.perf_counter()
            out = pool.map(fn, items, on_lost)
            calls.append((len(items), sum(1 for t in items if t.settings.name != settings.name),
                          time.perf_counter() - start))
            return out

        predict(towers[0],
                Request(model=model_for(towers[0], args.zoo, 2), settings=settings,
                        query=queries_for(towers[0], args.zoo), budget_s=None),
                Context(map_fn=timed_map))  # imports, caches
        for i, tower in enumerate(towers):
            model, query = model_for(tower, args.zoo, args.samples), queries_for(tower, args.zoo)
            walls = {}
            for name, check in (("unchecked", NO_CHECK), ("checked", DEFAULT_CHECK)):
                calls.clear()
                start = time.perf_counter()
                prediction = predict(tower,
                                     Request(model=model, settings=settings, query=query, seed=i, check=check,
                                             budget_s=None),
                                     Context(map_fn=timed_map))
                walls[name] = time.perf_counter() - start
            parts = Counter()
            for n, (tasks, references, wall) in enumerate(calls):
                parts[_part(n, tasks, references, args.samples)] += wall
            rows.append({"tower": tower.name, "family": family_of(tower) if args.zoo else "towers",
                         "unchecked_s": walls["unchecked"], "checked_s": walls["checked"],
                         "verdict": prediction.fidelity, "maps": [list(c) for c in calls],
                         "reference_reruns": sum(r for _, r, _ in calls), "parts_s": dict(parts)})
            print(f"{tower.name}: unchecked {walls['unchecked']:.2f} s, checked {walls['checked']:.2f} s "
                  f"({prediction.fidelity}), maps {[(t, r, round(w, 2)) for t, r, w in calls]}", flush=True)
    unchecked = float(np.mean([r["unchecked_s"] for r in rows]))
    checked = float(np.mean([r["checked_s"] for r in rows]))
    per_part = {part: float(np.sum([r["parts_s"].get(part, 0.0) for r in rows])) / len(rows) for part in PARTS}
    verdicts = Counter(r["verdict"] for r in rows)
    summary = {"date": time.strftime("%Y-%m-%d"), "source": source, "towers": len(rows), "samples": args.samples,
               "workers": args.workers, "unchecked_s": unchecked, "checked_s": checked,
               "checked_over_unchecked": checked / unchecked, "per_part_s": per_part,
               "predictions_with_part": {part: sum(1 for r in rows if part in r["parts_s"]) for part in PARTS},
               "reference_reruns_per_prediction": float(np.mean([r["reference_reruns"] for r in rows])),
               "verdicts": dict(verdicts)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = [f"# Where the self-check's time goes ({summary['date']})", "",
             f"`.venv/bin/python benchmarks/check_cost.py "
             + (f"--zoo {args.zoo}" if args.zoo else f"--towers {args.towers}")
             + (f" --families {args.families}" if args.zoo and args.families != ",".join(FAMILIES) else "") + f" --samples {args.samples}`; {source}, "
             f"k = {args.samples}, "
             + ("sigma 5% of each scene's smallest body, the zoo's queries" if args.zoo else f"sigma {SIGMA_M:g} m, queries fall")
             + f", `default`, {args.workers} workers, unchecked and checked "
             "one after the other on the same seeds.", "",
             f"Unchecked {unchecked:.2f} s per prediction, checked {checked:.2f} s ({checked / unchecked:.2f}x); "
             f"{summary['reference_reruns_per_prediction']:.2f} reference reruns per prediction; verdicts "
             + ", ".join(f"{v} {n}" for v, n in sorted(verdicts.items())) + ".", "",
             "| part of the checked prediction | s per prediction (mean over all) | predictions with it |", "|---|---|---|"]
    lines += [f"| {part} | {per_part[part]:.3f} | {summary['predictions_with_part'][part]} |" for part in PARTS]
    families = list(dict.fromkeys(r["family"] for r in rows))
    if len(families) > 1:
        summary["per_family"] = {}
        for family in families:
            mine = [r for r in rows if r["family"] == family]
            summary["per_family"][family] = {
                "unchecked_s": float(np.mean([r["unchecked_s"] for r in mine])),
                "checked_s": float(np.mean([r["checked_s"] for r in mine])),
                "per_part_s": {part: float(np.sum([r["parts_s"].get(part, 0.0) for r in mine])) / len(mine)
                               for part in PARTS},
                "verdicts": dict(Counter(r["verdict"] for r in mine))}
        lines += ["", "Per family (s per prediction, by part of the checked prediction):", "",
                  "| family | unchecked | checked | " + " | ".join(PARTS) + " | verdicts |",
                  "|---|---|---|" + "---|" * len(PARTS) + "---|"]
        lines += [f"| {family} | {f['unchecked_s']:.2f} | {f['checked_s']:.2f} | "
                  + " | ".join(f"{f['per_part_s'][part]:.2f}" for part in PARTS) + " | "
                  + ", ".join(f"{v} {n}" for v, n in sorted(f["verdicts"].items())) + " |"
                  for family, f in summary["per_family"].items()]
    (out / "check_cost.json").write_text(json.dumps({"summary": summary, "towers": rows}, indent=1) + "\n")
    (out / "check_cost.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
