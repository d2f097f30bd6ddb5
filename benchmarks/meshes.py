"""Objects from meshes: what the decomposition costs, what a mesh object costs in a rollout against the
same object as its convex hull, and how `default` agrees with `paper` on scenes of such objects.

    .venv/bin/python benchmarks/meshes.py [--samples 16] [--out benchmarks/results/meshes]

Objects: a cup (32 sides) and a bowl (engine/scene/household.py), written as OBJ files. Per object:
the CoACD decomposition's time into a fresh cache and read back from it, its parts and points, and
its parts' volume against the mesh's. Scenes: the cup holding a ball, the bowl holding three, each
object also alone; per scene the wall time of a prediction (k samples, 0 workers, `default`) as the
mesh's parts and as the mesh's convex hull (alone: the same object; with balls, the hull cannot hold
them, so only the cost is compared), and P(fall) per object under `default` against `paper` at
sigma 0.01 m (same seeds). Writes ``meshes.md`` and ``meshes.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset  # noqa: E402
from ipe_ros.engine import Request
from ipe_ros.engine.scene import household, shapes  # noqa: E402

OBJECTS = {"cup": household.cup(), "bowl": household.bowl()}
BALLS = {"cup": [(0.0, 0.0)], "bowl": [(-0.03, 0.0), (0.03, 0.0), (0.0, 0.035)]}
BALL_R = 0.015


def scene(name: str, shape: dict, balls: bool) -> dict:
    objects = [{"name": name, "shape": shape, "position_m": [0, 0, 0], "orientation_xyzw": [0, 0, 0, 1],
                "friction": 0.6, "restitution": 0.0, "density_kg_m3": 2000}]
    for i, (x, y) in enumerate(BALLS[name] if balls else []):
        objects.append({"name": f"ball{i}", "shape": {"type": "sphere", "radius_m": BALL_R},
                        "position_m": [x, y, 0.006 + BALL_R + 0.02], "orientation_xyzw": [0, 0, 0, 1],
                        "friction": 0.6, "restitution": 0.0, "mass_kg": 0.02})
    return {"format": "ipe_ros.scene/2", "name": f"{name}{'_balls' if balls else ''}", "gravity_m_s2": [0, 0, -9.81],
            "support": {"type": "floor", "height_m": 0.0, "friction": 0.6, "restitution": 0.0}, "objects": objects}


def load(folder: Path, data: dict):
    path = folder / f"{data['name']}.json"
    path.write_text(json.dumps(data))
    return load_scenes(path)[0]


def timed_prediction(s, settings: str, samples: int, seed: int = 0):
    started = time.perf_counter()
    answer = predict(s,
                     Request(model=ModelConfig(sigma_m=0.01, samples=samples), settings=preset(settings),
                             query=QuerySpec(queries=frozenset({"fall"})), seed=seed, check=None, budget_s=None))
    return time.perf_counter() - started, answer.object_fall_probability


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--out", default="benchmarks/results/meshes")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, runs = [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        os.environ["IPE_CACHE_DIR"] = str(folder / "cache")
        for name, (vertices, faces) in OBJECTS.items():
            household.write_obj(folder / f"{name}.obj", vertices, faces)
            mesh = {"type": "mesh", "uri": f"{name}.obj"}
            started = time.perf_counter()
            alone = load(folder, scene(name, mesh, False))
            first = time.perf_counter() - started
            started = time.perf_counter()
            load(folder, scene(name, mesh, False))
            cached = time.perf_counter() - started
            import trimesh

            exact = trimesh.Trimesh(vertices, faces)
            parts = alone.objects[0].shape.parts
            hulls_only = shapes.Compound(parts)  # what the mass would be without the mesh's own volume
            rows.append({"object": name, "decompose_s": first, "cached_s": cached, "parts": len(parts),
                         "points": sum(len(p.shape.vertices_m) for p in parts),
                         "parts_volume_ratio": shapes.volume_m3(hulls_only) / exact.volume,
                         "com_offset_mm": 1000 * float(np.linalg.norm(shapes.centre_of_mass_m(hulls_only)
                                                                      - exact.center_mass)),
                         "mass_from_mesh": shapes.volume_m3(alone.objects[0].shape) / exact.volume})
            hull = {"type": "convex", "vertices_m": vertices.tolist()}
            for balls in (False, True):
                as_mesh = load(folder, scene(name, mesh, balls))
                as_hull = load(folder, {**scene(name, hull, balls), "name": f"{name}_hull{'_balls' if balls else ''}"})
                mesh_s, p_default = timed_prediction(as_mesh, "default", args.samples)
                hull_s, _ = timed_prediction(as_hull, "default", args.samples)
                paper_s, p_paper = timed_prediction(as_mesh, "paper", args.samples)
                runs.append({"scene": as_mesh.name, "mesh_s": mesh_s, "hull_s": hull_s, "paper_s": paper_s,
                             "p_default": p_default, "p_paper": p_paper,
                             "max_abs_dp": max(abs(p_default[k] - p_paper[k]) for k in p_default)})
    (out / "meshes.json").write_text(json.dumps({"samples": args.samples, "objects": rows, "scenes": runs}, indent=1))
    lines = [f"# Objects from meshes ({time.strftime('%Y-%m-%d')})", "",
             f"`.venv/bin/python benchmarks/meshes.py --samples {args.samples}`; 0 workers, sigma 0.01 m, the fall "
             "query, no self-check, on this project's shared 2-core machine.", "",
             "| object | decomposition, first | read back | parts | points | parts' hulls' volume / mesh's | their "
             "centre of mass off by | the object's volume / mesh's |", "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r['object']} | {r['decompose_s']:.1f} s | {r['cached_s'] * 1000:.0f} ms | {r['parts']} | {r['points']} "
              f"| {r['parts_volume_ratio']:.3f} | {r['com_offset_mm']:.2f} mm | {r['mass_from_mesh']:.3f} |" for r in rows]
    lines += ["", f"| scene | prediction as parts | as its convex hull | parts / hull | `paper` / `default` | "
                  f"max per-object |dP| `default` vs `paper` (k = {args.samples}) |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['scene']} | {r['mesh_s']:.2f} s | {r['hull_s']:.2f} s | {r['mesh_s'] / r['hull_s']:.1f}x | "
              f"{r['paper_s'] / r['mesh_s']:.1f}x | {r['max_abs_dp']:.3f} |" for r in runs]
    (out / "meshes.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
