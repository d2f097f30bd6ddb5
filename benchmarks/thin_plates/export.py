"""The zoo's thin plates, where `default` and `paper` part: pybullet's answers per sample and each
sample's start state, for a third engine (mujoco_plates.py).
Usage: export.py OUT.json [scene ...] [--samples K]

Scenes are ``zoo.scene_zoo(2026, 6, ("plates",))[i]`` at seed i (default: 3 and 5, the two where
`default` unchecked differs from `paper` by more than the yardstick). Per sample: which plates fell
under `paper` (multibodies, 1 ms), `paper` in plain rigid bodies, `default` (plain rigid bodies)
and `default` in multibodies; and the start state after depenetration (the same for every preset),
each plate's centre, orientation, mass, diagonal inertia, half extents and friction.
"""
import argparse
import json
import os
import sys

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, WorkerPool, predict  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.sampling.perturb import dynamic_masses  # noqa: E402
from ipe_ros.engine.scene.zoo import family_queries, scene_zoo, zoo_sigma_m  # noqa: E402

PAPER, DEFAULT = PRESETS["paper"], PRESETS["default"]
PHYSICS = {"paper": PAPER,
           "paper, plain rigid bodies": PAPER.changed("paper-rigid", solver={"maximal_coordinates": True}),
           "default": DEFAULT,
           "default, multibodies": DEFAULT.changed("default-multibody", solver={"maximal_coordinates": False})}


def start_states(scene, model, reference) -> list[dict]:
    """Each sample's start state, read from a prediction's outcomes: every preset separates a
    sample's noisy scene identically, so `paper`'s initial poses are every physics' start."""
    masses = dynamic_masses(scene, model.mu)
    samples = []
    for outcome in reference.outcomes:
        bodies = []
        for i, body in enumerate(scene.dynamic_objects):
            e, m = np.asarray(body.shape.extents_m), float(masses[i])
            bodies.append({"name": body.name, "mass": m, "half": (e / 2).tolist(),
                           "com": outcome.initial_positions_m[i].tolist(),
                           "quat_xyzw": outcome.initial_orientations_xyzw[i].tolist(), "friction": body.friction,
                           "inertia": [m / 12 * (e[1] ** 2 + e[2] ** 2), m / 12 * (e[0] ** 2 + e[2] ** 2),
                                       m / 12 * (e[0] ** 2 + e[1] ** 2)]})
        samples.append({"bodies": bodies})
    return samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out")
    parser.add_argument("scenes", nargs="*", type=int, default=[3, 5])
    parser.add_argument("--samples", type=int, default=16)
    args = parser.parse_args()
    scenes = scene_zoo(2026, 6, ("plates",))
    query = QuerySpec(queries=family_queries("plates"))
    rows = []
    with WorkerPool(2) as pool:
        for i in args.scenes:
            scene = scenes[i]
            model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.samples)
            predictions = {name: predict(scene,
                                         Request(model=model, settings=settings, query=query, seed=i, check=None,
                                                 budget_s=None),
                                         Context(map_fn=pool.map))
                           for name, settings in PHYSICS.items()}
            fallen = {name: [[bool(x) for x in o.rollouts[0].fallen] for o in p.outcomes]
                      for name, p in predictions.items()}
            rows.append({"scene": scene.name, "floor_friction": scene.support.friction,
                         "fall_threshold_fraction": query.fall_threshold_fraction,
                         "names": [b.name for b in scene.dynamic_objects], "pybullet_fallen": fallen,
                         "samples": start_states(scene, model, predictions["paper"])})
            print(scene.name, {n: np.mean(f, axis=0).round(2).tolist() for n, f in fallen.items()}, flush=True)
    with open(args.out, "w") as f:
        json.dump(rows, f)


if __name__ == "__main__":
    main()
