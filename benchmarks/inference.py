"""Properties from observed motion: coverage, error and cost of ``ipe infer`` on observations made at
known values (engine/inference/known.py: slide, head-on, bounce, tower).

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python benchmarks/inference.py --cases 50 --workers 2

Against the number of frames and unknowns: ``--every N`` keeps every N-th frame (30 Hz -> 30/N Hz),
``--window S`` the first S seconds, ``--also OBJ.PROPERTY=LOW,HIGH`` adds a unknown with a uniform
prior (not scored: it costs and widens). ``--observed DIR``: observations another engine made of the
same cases (benchmarks/witness/observations.py). Writes benchmarks/results/inference/inference.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from ipe_ros.engine.compute.pool import WorkerPool
from ipe_ros.engine.config import preset
from ipe_ros.engine.inference.infer import InferSettings, infer
from ipe_ros.engine.inference.known import CASES, KnownCase
from ipe_ros.engine.inference.observation import observation_from_dict

OUT = Path(__file__).parent / "results" / "inference"


def thinned(observation: dict, every: int = 1, window_s: float | None = None, also: tuple = ()) -> dict:
    """The observation with every ``every``-th frame within ``window_s``, and ``also``'s unknowns
    ((object, property, (low, high)) each) added."""
    frames = [f for f in observation["frames"][every - 1::every] if window_s is None or f["t_s"] <= window_s + 1e-9]
    unknowns = observation["unknowns"] + [{"object": o, "property": p, "prior": {"uniform": list(bounds)}}
                                          for o, p, bounds in also]
    return {**observation, "frames": frames, "unknowns": unknowns}


def observed_cases(folder: Path, family: str) -> list[tuple[int, KnownCase]]:
    """The observations another engine made (benchmarks/witness/mujoco_observe.py) of ``family``, by seed."""
    out = []
    for path in sorted(folder.glob(f"{family}_*.json"), key=lambda p: int(p.stem.rsplit("_", 1)[1])):
        data = json.loads(path.read_text())
        known = {k: data.pop(k) for k in ("truth", "heavier", "scored")}
        data.pop("nominal", None)
        out.append((int(path.stem.rsplit("_", 1)[1]),
                    KnownCase(family, data, known["truth"], tuple(known["heavier"]) or None, tuple(known["scored"]))))
    return out


def run_family(family: str, cases: int, pool, settings: InferSettings, first_seed: int = 0, every: int = 1,
               window_s: float | None = None, also: tuple = (), observed: Path | None = None) -> dict:
    rows = []
    made = observed_cases(observed, family)[:cases] if observed is not None else \
        [(seed, CASES[family](seed)) for seed in range(first_seed, first_seed + cases)]
    for seed, case in made:
        observation = thinned(case.observation, every, window_s, also)
        started = time.perf_counter()
        answer = infer(observation_from_dict(observation), settings, pool.map if pool else None)
        row = {"model_error": None if answer.model_error is None else answer.model_error.median, "seed": seed,
               "seconds": time.perf_counter() - started, "consistent": answer.consistent,
               "frames": len(observation["frames"]), "unknowns": len(observation["unknowns"]),
               "candidates": answer.candidates, "ess": answer.ess, "truth": {k: float(v) for k, v in case.truth.items()}, "covered": {}, "error": {}}
        if answer.consistent:
            for label in case.scored:
                if label == "ratio":
                    pair = next(p for p in answer.heavier if {p.a, p.b} == set(case.heavier))
                    flip = pair.a != case.heavier[0]
                    low, median, high = pair.ratio_low_90, pair.ratio_median, pair.ratio_high_90
                    if flip:
                        low, median, high = 1 / high, 1 / median, 1 / low
                    truth = case.true_ratio
                    row["true_ratio"] = truth
                    if truth >= 2:  # the bar: "which is heavier" at a true ratio of 2 or more
                        row["heavier_right"] = bool((1 - pair.p_a_heavier if flip else pair.p_a_heavier) > 0.5)
                else:
                    e = answer.estimate(label)
                    low, median, high, truth = e.low_90, e.median, e.high_90, case.truth[label]
                row["covered"][label] = bool(low <= truth <= high)
                row["error"][label] = float((median - truth) / truth)
        rows.append(row)
        print(family, seed, f"{row['seconds']:.1f} s", row["covered"], {k: round(v, 3) for k, v in row["error"].items()},
              flush=True)
    covered = [c for r in rows for c in r["covered"].values()]
    summary = {"family": family, "cases": len(rows), "frames": rows[0]["frames"], "unknowns": rows[0]["unknowns"],
               "coverage_90": float(np.mean(covered)) if covered else None,
               "median_abs_error": float(np.median([abs(v) for r in rows for v in r["error"].values()])),
               "median_seconds": float(np.median([r["seconds"] for r in rows])),
               "max_seconds": float(np.max([r["seconds"] for r in rows])),
               "inconsistent": sum(not r["consistent"] for r in rows)}
    if any("heavier_right" in r for r in rows):
        summary["heavier_right"] = float(np.mean([r["heavier_right"] for r in rows if "heavier_right" in r]))
    return {"summary": summary, "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=50)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--families", default=",".join(CASES))
    parser.add_argument("--preset", default="default")
    parser.add_argument("--model-error", type=float, default=None, help="fixed (default: inferred)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--grid", type=int, default=None, metavar="POINTS",
                        help="a plain grid of POINTS per unknown instead of AMIS (the baseline)")
    parser.add_argument("--every", type=int, default=1, metavar="N", help="keep every N-th frame")
    parser.add_argument("--window", type=float, default=None, metavar="S", help="keep the frames of the first S s")
    parser.add_argument("--also", action="append", default=[], metavar="OBJ.PROPERTY=LOW,HIGH",
                        help="another unknown, uniform prior (repeatable)")
    parser.add_argument("--observed", type=Path, default=None, metavar="DIR",
                        help="infer the observations another engine made (benchmarks/witness/mujoco_observe.py)")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args()
    also = tuple((spec.split("=")[0].rsplit(".", 1)[0], spec.split("=")[0].rsplit(".", 1)[1],
                  tuple(float(v) for v in spec.split("=")[1].split(","))) for spec in args.also)
    settings = InferSettings(simulation=preset(args.preset), model_error_fraction=args.model_error, grid_points=args.grid)
    pool = WorkerPool(args.workers) if args.workers else None
    try:
        results = {f: run_family(f, args.cases, pool, settings, args.first_seed, args.every, args.window, also,
                                 args.observed) for f in args.families.split(",")}
    finally:
        if pool:
            pool.close()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "inference.json").write_text(json.dumps({"settings": vars(args) | {"observed": str(args.observed)},
                                                    "results": results}, indent=1))
    for family, result in results.items():
        print(json.dumps(result["summary"]))


if __name__ == "__main__":
    main()
