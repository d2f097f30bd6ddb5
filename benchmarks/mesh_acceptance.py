"""Real object models at the door: which mesh files `ipe predict` accepts, how long their first
decomposition takes, and how each accepted one rests on a floor.

    .venv/bin/python benchmarks/mesh_acceptance.py FILE_OR_FOLDER... [--out benchmarks/results/mesh_acceptance]

Each mesh file (OBJ, STL, PLY, GLB; a folder: every one in it) is written into a scene of its own,
standing on a floor (its lowest point at z = 0, as the file is oriented, density 500 kg/m^3), and
read into a fresh decomposition cache, timed; then predicted at the ground truth (`paper`, 2 s):
whether it stays up, and how far it moves. A refusal is recorded with its one line. The files are
not ours: fetch them (benchmarks/HISTORY.md names the set used and its licence); nothing is copied.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import ModelConfig, QuerySpec, SceneError, load_scenes, predict, preset  # noqa: E402
from ipe_ros.engine import Request

FORMATS = (".obj", ".stl", ".ply", ".glb")
QUERY = QuerySpec(queries=frozenset({"fall", "final_pose"}))


def mesh_files(paths: list[str]) -> list[Path]:
    out = []
    for given in map(Path, paths):
        out += sorted(p for p in given.iterdir() if p.suffix.lower() in FORMATS) if given.is_dir() else [given]
    return out


def standing_scene(path: Path, folder: Path) -> Path:
    """A scene of the mesh on a floor, its lowest point at z = 0 (read once to find it)."""
    import trimesh

    lowest = float(trimesh.load(path, force="mesh").bounds[0][2])
    data = {"format": "ipe_ros.scene/2", "name": path.stem, "gravity_m_s2": [0, 0, -9.81],
            "support": {"type": "floor", "height_m": 0.0, "friction": 0.6, "restitution": 0.0},
            "objects": [{"name": path.stem, "shape": {"type": "mesh", "uri": str(path.resolve())},
                         "position_m": [0.0, 0.0, -lowest + 1e-4], "orientation_xyzw": [0, 0, 0, 1],
                         "friction": 0.6, "restitution": 0.0, "density_kg_m3": 500.0}]}
    scene_path = folder / f"{path.stem}.json"
    scene_path.write_text(json.dumps(data))
    return scene_path


def one(path: Path, folder: Path) -> dict:
    row: dict = {"file": path.name, "bytes": path.stat().st_size}
    os.environ["IPE_MESH_PATH"] = str(path.resolve().parent)
    started = time.perf_counter()
    try:
        (scene,) = load_scenes(standing_scene(path, folder))
    except SceneError as exc:
        row.update(accepted=False, seconds=time.perf_counter() - started, refusal=str(exc))
        return row
    row.update(accepted=True, seconds=time.perf_counter() - started)
    shape = scene.objects[0].shape
    row.update(parts=len(shape.parts), points=sum(len(p.shape.vertices_m) for p in shape.parts),
               volume_m3=shape.volume_m3, repaired=shape.source.repaired)  # how an open one was closed
    answer = predict(scene,
                     Request(model=ModelConfig(sigma_m=0.0, samples=1, object_noise=False), settings=preset("paper"),
                             query=QUERY, check=None, budget_s=None))
    if answer.samples:
        outcome = answer.outcomes[0]
        moved = np.linalg.norm(outcome.rollouts[0].final_positions_m[0] - outcome.initial_positions_m[0])
        row.update(fell=bool(answer.object_fall_probability[path.stem]), moved_m=float(moved))
    else:
        row.update(fell=None, moved_m=None, failure=list(answer.failure_reasons))
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results" / "mesh_acceptance")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        os.environ["IPE_CACHE_DIR"] = str(Path(folder) / "cache")  # every first decomposition timed
        for path in mesh_files(args.paths):
            rows.append(one(path, Path(folder)))
            print(json.dumps(rows[-1]), flush=True)
    accepted = [r for r in rows if r["accepted"]]
    summary = {"files": len(rows), "accepted": len(accepted),
               "median_first_seconds": float(np.median([r["seconds"] for r in accepted])) if accepted else None,
               "max_first_seconds": float(max((r["seconds"] for r in accepted), default=0.0))}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "mesh_acceptance.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    print(json.dumps(summary), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
