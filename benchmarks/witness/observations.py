"""Observed motion made by another engine: pybullet's side (the scenes and what to observe).

    .venv/bin/python benchmarks/witness/observations.py CASES.json [--cases 10] [--families slide,bounce,head-on]
    /tmp/mj/bin/python benchmarks/witness/mujoco_observe.py CASES.json OBSERVED_DIR     # MuJoCo makes the frames
    .venv/bin/python benchmarks/inference.py --observed OBSERVED_DIR                    # pybullet infers

The known cases (engine/inference/known.py: a slide, a bounce, two boxes colliding, a tower on a
balance) are written with their true scene in plain terms (``export.scene_dict``: shapes, masses,
pybullet's inertias, surfaces), the observation they ask for (scene, unknowns, actions, frame times,
the tracker's noise) and the truth. MuJoCo then rolls each out and reads the frames, so the
inference never sees a pybullet rollout of the truth: the test of the issue's "do not tune to
pybullet's quirks".
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from ipe_ros.engine.config import preset  # noqa: E402
from ipe_ros.engine.inference.known import CASES  # noqa: E402
from ipe_ros.engine.scene.format import scene_from_dict  # noqa: E402

from export import scene_dict  # noqa: E402


def case_row(family: str, seed: int) -> dict:
    case = CASES[family](seed)
    observation = case.observation
    truth_scene = scene_from_dict(observation["scene"])  # the observation's scene carries the true values
    exported = scene_dict(truth_scene, preset("paper"))
    exported["horizon_s"] = observation["frames"][-1]["t_s"]
    return {"family": family, "seed": seed, "scene": exported,
            "start_m": [list(map(float, b.centre_of_mass_m)) for b in truth_scene.dynamic_objects],
            "start_xyzw": [list(b.orientation_xyzw) for b in truth_scene.dynamic_objects],
            "observation": {**observation, "frames": [{"t_s": f["t_s"], "objects": {}} for f in observation["frames"]]},
            "truth": case.truth, "heavier": list(case.heavier or ()), "scored": list(case.scored)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--cases", type=int, default=10)
    parser.add_argument("--families", default="slide,bounce,head-on,tower")
    args = parser.parse_args()
    rows = [case_row(family, seed) for family in args.families.split(",") for seed in range(args.cases)]
    args.out.write_text(json.dumps({"args": vars(args) | {"out": str(args.out)}, "rows": rows}))
    print(f"wrote {len(rows)} cases to {args.out}", file=sys.stderr)


if __name__ == "__main__":
    main()
