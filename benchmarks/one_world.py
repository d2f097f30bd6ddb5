"""Several samples' worlds in one pybullet world, against one world per sample (issue 32: measure,
keep only if it pays).

    .venv/bin/python benchmarks/one_world.py [--copies 1,4,8,16] [--steps 480]

N noisy copies of a 10-block paper tower, each built and separated as a sample is; then either N
worlds each stepped ``--steps`` times (as the engine runs samples today), or one world holding all N
copies 10 m apart (no two copies can touch: the broadphase keeps them apart, as collision groups
would) stepped the same number of times. Only stepping is timed (building is the same work either
way), at the default preset's time step, no early termination: the most one world can save is
pybullet's per-call overhead. Single process, interleaved repeats, medians.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from actions import stable_tower  # noqa: E402
from ipe_ros.engine import ModelConfig, preset, simulation  # noqa: E402
from ipe_ros.engine.sampling.perturb import draw_sample_inputs  # noqa: E402
from ipe_ros.engine.sampling.rollout import separated_world  # noqa: E402

SPACING_M = 10.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--copies", default="1,4,8,16")
    parser.add_argument("--steps", type=int, default=480)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    tower, settings = stable_tower(), preset("default")
    model = ModelConfig(sigma_m=0.04, samples=1)
    p = simulation.bullet.pybullet()
    rows = []
    for n in map(int, args.copies.split(",")):
        samples = []
        for i, seed in enumerate(np.random.SeedSequence(0).spawn(n)):
            inputs = draw_sample_inputs(tower, model, np.random.default_rng(seed))
            positions, orientations = simulation.read_poses(separated_world(tower, settings, inputs))
            samples.append((positions, orientations, inputs.masses_kg))
        merged = dataclasses.replace(tower, objects=tuple(
            dataclasses.replace(b, name=f"s{i}_{b.name}") for i in range(n) for b in tower.objects))

        def separate_worlds() -> float:
            spent = 0.0
            for positions, orientations, masses in samples:
                world = simulation.build_world(tower, positions, masses, settings, orientations_xyzw=orientations)
                start = time.perf_counter()
                for _ in range(args.steps):
                    p.stepSimulation(physicsClientId=world.client)
                spent += time.perf_counter() - start
            return spent

        def one_world() -> float:
            positions = np.vstack([s[0] + [i * SPACING_M, 0, 0] for i, s in enumerate(samples)])
            world = simulation.build_world(merged, positions, np.concatenate([s[2] for s in samples]), settings,
                                           orientations_xyzw=np.vstack([s[1] for s in samples]))
            start = time.perf_counter()
            for _ in range(args.steps):
                p.stepSimulation(physicsClientId=world.client)
            return time.perf_counter() - start

        times = {"separate": [], "one": []}
        for _ in range(args.repeats):
            times["separate"].append(separate_worlds())
            times["one"].append(one_world())
        sep, one = statistics.median(times["separate"]), statistics.median(times["one"])
        rows.append({"copies": n, "separate_worlds_s": sep, "one_world_s": one, "speedup": sep / one})
        print(f"{n:>3} copies: {args.steps} steps in {n} worlds {sep:.3f} s, in one world {one:.3f} s: "
              f"{sep / one:.2f}x", flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "steps": args.steps, "rows": rows},
                                             indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
