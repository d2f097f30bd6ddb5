"""Time the `default` preset against `paper` in one run (ratios, since this machine is shared).

    .venv/bin/python benchmarks/preset_speed.py [--towers 6] [--samples 48] [--workers 2]

Generated 10-block paper-style towers (runs without ../shared), sigma = 0.04 m, phi = 0. Prints a
Markdown table: wall time per prediction, rollouts per second, and |delta fall fraction| against
`paper` with the same seeds (hence the same noisy initial scenes). The full accuracy-versus-time sweep
is issue 4's benchmark.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, predict, preset  # noqa: E402
from ipe_ros.engine.generators import generate_towers  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--towers", type=int, default=6)
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    scenes = generate_towers(2013, args.towers)
    model = ModelConfig(sigma_m=0.04, samples=args.samples)
    query = QuerySpec()
    rows = {}
    with WorkerPool(args.workers) as pool:
        pool.warm()
        for name in ("paper", "default"):
            start = time.perf_counter()
            fractions = [predict(s, model, preset(name), query, seed=i, map_fn=pool.map).fall_fraction
                         for i, s in enumerate(scenes)]
            rows[name] = (time.perf_counter() - start, np.array(fractions))
    paper_wall = rows["paper"][0]
    print(f"{args.towers} generated towers, k = {args.samples}, sigma = 0.04 m, phi = 0, {args.workers} workers\n")
    print("| preset | wall s / prediction | rollouts / s | speed-up vs paper | mean abs dFF | max abs dFF |")
    print("|---|---|---|---|---|---|")
    for name, (wall, fractions) in rows.items():
        delta = np.abs(fractions - rows["paper"][1])
        print(f"| {name} | {wall / args.towers:.2f} | {args.towers * args.samples / wall:.0f} | "
              f"{paper_wall / wall:.2f}x | {delta.mean():.3f} | {delta.max():.3f} |")


if __name__ == "__main__":
    main()
