"""pybullet's side of the cross-engine witness: the scenes, their noisy starts and pybullet's ends.

    .venv/bin/python benchmarks/witness/export.py OUT.json [--per-family 2] [--samples 8] [--seed 2026]
                                                  [--families launch,drop] [--preset paper] [--removals]
                                                  [--solver-iterations N] [--warm-start F]

Then, in a venv of its own (MuJoCo is a witness, not a dependency):

    python3 -m venv /tmp/mj && /tmp/mj/bin/pip install mujoco==4.0.0 numpy
    /tmp/mj/bin/python benchmarks/witness/mujoco_run.py OUT.json [--md REPORT.md]

Two kinds of rows. The mechanics cases (``MECHANICS``: slides, a push, an incline, rolling, a bounce, a
collision; each with its closed form, each pointed along an axis and turned) run as ground truth.
The zoo's families run ``--samples`` noisy starts each, the same for both engines: each sample's
start is pybullet's after the overlaps are removed and heights set down (every body's centre of
mass, orientation, mass and principal inertia as pybullet built it), so the engines differ only in
what they do from there. Every shape is written in plain terms (box, sphere, cylinder, capsule, hull
points; a compound's parts with their poses about the centre of mass), and so are the surfaces.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset  # noqa: E402
from ipe_ros.engine import Request
from ipe_ros.engine.scene import shapes as shapes_module  # noqa: E402
from ipe_ros.engine.scene.bodies import Body, Box, Floor, Scene  # noqa: E402
from ipe_ros.engine.scene.shapes import BoxShape, Capsule, Compound, ConvexHull, Cylinder, Sphere  # noqa: E402
from ipe_ros.engine.scene.zoo import FAMILIES, zoo_scene, zoo_sigma_m  # noqa: E402
from ipe_ros.engine.simulation import build_world  # noqa: E402

G = 9.81
QUERY = QuerySpec(queries=frozenset({"fall", "final_pose"}))


def _yaw(angle_rad: float):
    return (0.0, 0.0, math.sin(angle_rad / 2), math.cos(angle_rad / 2))


def _planar(angle_rad: float, length: float, z: float = 0.0):
    return (length * math.cos(angle_rad), length * math.sin(angle_rad), z)


def _ball(name, position_m, radius_m=0.05, **fields) -> Body:
    fields.setdefault("mass_kg", 1.0)
    fields.setdefault("friction", 0.5)
    fields.setdefault("restitution", 0.0)
    return Body(name=name, shape=Sphere(radius_m), position_m=tuple(position_m), orientation_xyzw=(0, 0, 0, 1),
                **fields)


def _floor(*bodies, friction=1.0, restitution=0.0, gravity=(0.0, 0.0, -G), horizon_s=None, name="mechanics"):
    return Scene(name=name, objects=tuple(bodies), support=Floor(friction=friction, restitution=restitution),
                 gravity_m_s2=gravity, horizon_s=horizon_s)


def mechanics_cases() -> list[tuple[str, Scene, dict]]:
    """(name, scene, closed form) for each mechanics case: what the answer should be, per body."""
    cases = []
    coulomb_m = 2.0 ** 2 / (2 * 0.5 * G)
    for heading_deg, yaw_deg in ((0, 0), (30, 0), (45, 0), (30, 30), (45, 45)):
        for restitution in (0.0, 0.2):
            box = Box("box", (0.1, 0.1, 0.05), (0.0, 0.0, 0.025), _yaw(math.radians(yaw_deg)), friction=0.5,
                      restitution=restitution, mass_kg=1.0,
                      linear_velocity_m_s=_planar(math.radians(heading_deg), 2.0))
            cases.append((f"slide {heading_deg} deg, box at {yaw_deg} deg, e {restitution}",
                          _floor(box, restitution=restitution),
                          {"travel_m": coulomb_m, "heading_deg": float(heading_deg)}))
    for downhill_deg in (0, 45):
        incline = math.radians(29.0)
        gravity = (*_planar(math.radians(downhill_deg), G * math.sin(incline))[:2], -G * math.cos(incline))
        cube = Box("cube", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), (0, 0, 0, 1), friction=0.5, restitution=0.0, mass_kg=1.0)
        cases.append((f"incline 29 deg facing {downhill_deg} deg, mu 0.5", _floor(cube, gravity=gravity, horizon_s=1.0),
                      {"travel_m": 0.5 * G * (math.sin(incline) - 0.5 * math.cos(incline)),
                       "heading_deg": float(downhill_deg)}))
        incline = math.radians(10.0)
        gravity = (*_planar(math.radians(downhill_deg), G * math.sin(incline))[:2], -G * math.cos(incline))
        cases.append((f"ball rolling 10 deg facing {downhill_deg} deg",
                      _floor(_ball("ball", (0, 0, 0.05)), gravity=gravity, horizon_s=1.0),
                      {"travel_m": 0.5 * 5 / 7 * G * math.sin(incline), "heading_deg": float(downhill_deg)}))
    for e in (0.25, 0.64):
        h, radius = 0.5, 0.05
        landing = math.sqrt(2 * G * h)
        apex_s = round(landing / G + e * landing / G, 3)
        ball = _ball("ball", (0.0, 0.0, h + radius), restitution=math.sqrt(e))
        cases.append((f"bounce e {e}", _floor(ball, restitution=math.sqrt(e), horizon_s=apex_s),
                      {"height_m": e ** 2 * h + radius}))
    for heading_deg in (0, 45):
        heading = math.radians(heading_deg)
        a = _ball("a", _planar(heading, 0.0, 0.05), friction=0.0, restitution=0.7,
                  linear_velocity_m_s=_planar(heading, 1.0))
        b = _ball("b", _planar(heading, 0.3, 0.05), friction=0.0, restitution=0.7)
        e = 0.49  # 0.7 x 0.7; A meets B at 0.2 s, then A at (1 - e) / 2, B at (1 + e) / 2 for 0.8 s
        cases.append((f"head-on collision e 0.49 at {heading_deg} deg", _floor(a, b, friction=0.0, horizon_s=1.0),
                      {"along_m": [0.2 + 0.8 * (1 - e) / 2, 0.3 + 0.8 * (1 + e) / 2], "heading_deg": float(heading_deg)}))
    return cases


def shape_dict(shape, offset_m) -> list[dict]:
    """The shape's parts, each placed in the body's centre-of-mass frame (``offset_m``: minus the
    centre of mass in the object frame)."""
    def one(sub, position, orientation):
        placed = {"pos": [float(v) for v in np.asarray(position) + 0.0], "quat_xyzw": [float(v) for v in orientation]}
        if isinstance(sub, BoxShape):
            return {"type": "box", "half_m": [e / 2 for e in sub.extents_m], **placed}
        if isinstance(sub, Sphere):
            return {"type": "sphere", "radius_m": sub.radius_m, **placed}
        if isinstance(sub, Cylinder):
            return {"type": "cylinder", "radius_m": sub.radius_m, "half_length_m": sub.length_m / 2, **placed}
        if isinstance(sub, Capsule):
            return {"type": "capsule", "radius_m": sub.radius_m, "half_length_m": sub.length_m / 2, **placed}
        if isinstance(sub, ConvexHull):
            return {"type": "hull", "points_m": [[float(v) for v in p] for p in sub.vertices_m], **placed}
        raise ValueError(f"no witness shape for {type(sub).__name__}")

    offset = np.asarray(offset_m, float)
    if isinstance(shape, Compound):
        return [one(part.shape, np.asarray(part.position_m) + offset, part.orientation_xyzw) for part in shape.parts]
    return [one(shape, offset, (0.0, 0.0, 0.0, 1.0))]


def scene_dict(scene: Scene, settings) -> dict:
    masses = [b.resolved_mass_kg for b in scene.dynamic_objects]
    world = build_world(scene, np.array([b.centre_of_mass_m for b in scene.dynamic_objects]), np.array(masses),
                        settings)
    dynamic = [{"name": b.name, "parts": shape_dict(b.shape, -shapes_module.centre_of_mass_m(b.shape)),
                "mass_kg": m, "inertia_kg_m2": [float(v) for v in world.inertia_kg_m2[i]],
                "friction": b.friction, "restitution": b.restitution,
                "linear_velocity_m_s": list(b.linear_velocity_m_s), "angular_velocity_rad_s": list(b.angular_velocity_rad_s),
                "smallest_extent_m": b.smallest_extent_m}
               for i, (b, m) in enumerate(zip(scene.dynamic_objects, masses))]
    static = [{"name": b.name, "parts": shape_dict(b.shape, np.zeros(3)), "position_m": list(b.position_m),
               "quat_xyzw": list(b.orientation_xyzw), "friction": b.friction, "restitution": b.restitution}
              for b in scene.static_objects]
    support = scene.support
    if not isinstance(support, Floor):
        raise ValueError("the witness takes floor scenes")
    return {"name": scene.name, "gravity_m_s2": list(scene.gravity_m_s2),
            "horizon_s": settings.horizon_for(scene.horizon_s), "floor": {"height_m": support.height_m,
                                                                           "friction": support.friction,
                                                                           "restitution": support.restitution},
            "dynamic": dynamic, "static": static}


def export_row(kind: str, label: str, scene: Scene, model: ModelConfig, settings, seed: int,
               closed_form: dict | None = None) -> dict:
    prediction = predict(scene,
                         Request(model=model, settings=settings, query=QUERY, seed=seed, check=None, budget_s=None))
    samples = []
    for outcome in prediction.outcomes:
        if not outcome.ok:
            continue
        rollout = outcome.rollouts[0]
        samples.append({"initial_m": outcome.initial_positions_m.tolist(),
                        "initial_xyzw": outcome.initial_orientations_xyzw.tolist(),
                        "pybullet_final_m": rollout.final_positions_m.tolist(),
                        "pybullet_fallen": [bool(v) for v in rollout.fallen]})
    return {"kind": kind, "label": label, "scene": scene_dict(scene, settings), "closed_form": closed_form,
            "fall_threshold_fraction": QUERY.fall_threshold_fraction, "preset": settings.name,
            "failed_samples": prediction.failed_samples, "samples": samples}


def removal_rows(settings, samples: int) -> list[dict]:
    """The tower without each of its blocks in turn (the blocks above it hang and land on what is
    below), at sigma 5 mm: where a dropped block's impact runs down the stack."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from actions import stable_tower
    from ipe_ros.engine.actions.kinds import Remove, applied

    tower = stable_tower()
    rows = []
    for body in tower.dynamic_objects:
        variant = applied(tower, Remove((body.name,)))
        rows.append(export_row("removal", f"{tower.name} without {body.name}", variant,
                               ModelConfig(sigma_m=0.005, samples=samples), settings, 1))
        print(rows[-1]["label"], file=sys.stderr, flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("--per-family", type=int, default=2)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--families", default=None, help="comma-separated (default: every family)")
    parser.add_argument("--preset", default="paper")
    parser.add_argument("--no-mechanics", action="store_true")
    parser.add_argument("--removals", action="store_true",
                        help="also each removal variant of the robot questions' 10-block tower (benchmarks/actions.py) "
                             "at a robot's 5 mm noise: what a support graph simulates")
    parser.add_argument("--solver-iterations", type=int, default=None,
                        help="the preset's solver with this many iterations (how far from converged its answer is)")
    parser.add_argument("--warm-start", type=float, default=None, help="the preset's solver with this warm start factor")
    args = parser.parse_args()
    settings = preset(args.preset)
    solver = {key: value for key, value in (("iterations", args.solver_iterations),
                                            ("warm_start_factor", args.warm_start)) if value is not None}
    if solver:
        settings = settings.changed(settings.name + "".join(f"-{k}={v}" for k, v in solver.items()), solver=solver)
    rows = []
    if args.removals:
        rows += removal_rows(settings, args.samples)
    if not args.no_mechanics:
        for label, scene, closed_form in mechanics_cases():
            rows.append(export_row("mechanics", label, scene, ModelConfig(sigma_m=0.0, samples=1), settings, 0,
                                   closed_form))
            print(label, file=sys.stderr, flush=True)
    for family in (args.families.split(",") if args.families else FAMILIES):
        for index in range(args.per_family):
            scene = zoo_scene(family, args.seed, index)
            try:
                row = export_row(family, scene.name, scene, ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.samples),
                                 settings, 1)
            except ValueError as exc:
                print(f"{scene.name}: left out ({exc})", file=sys.stderr)
                continue
            rows.append(row)
            print(scene.name, file=sys.stderr, flush=True)
    args.out.write_text(json.dumps({"args": vars(args) | {"out": str(args.out)}, "rows": rows}))


if __name__ == "__main__":
    main()
