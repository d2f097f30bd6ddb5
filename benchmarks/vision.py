"""What the vision system costs: renders/s of our rasteriser against pybullet's software renderer on the
same scenes, and Metropolis-Hastings steps/s with incremental rendering against rendering from scratch.

    .venv/bin/python benchmarks/vision.py [--towers 5] [--steps 300] [--out benchmarks/results/vision]

Paper towers from ../shared/data/battaglia2013/willitfall.csv (generated towers without it); one
process, the SI's three views. Silhouette agreement (intersection over union of the covered pixels)
is reported beside the timings.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from datetime import date
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.analysis.paper_data import shared_data_dir  # noqa: E402
from ipe_ros.analysis.runs import load_tower_stimuli  # noqa: E402
from ipe_ros.engine.vision import VisionSettings, default_cameras  # noqa: E402
from ipe_ros.engine.vision.mcmc import ImageModel  # noqa: E402
from ipe_ros.engine.vision.render import BACKGROUND_GREY, render, render_views, scene_mesh  # noqa: E402
from ipe_ros.engine.vision.tinyrenderer import grey_with_pybullet  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def _per_second(fn, repeats: int) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return repeats / (time.perf_counter() - start)


def measure(scenes, resolution: int, steps: int, rng: np.random.Generator) -> dict:
    ours_rate, theirs_rate, ious, incremental, scratch = [], [], [], [], []
    for scene in scenes:
        cameras = default_cameras(scene, resolution_px=resolution)
        mesh = scene_mesh(scene)
        camera = cameras[0]
        ours_rate.append(_per_second(lambda: render(mesh, camera), 20))
        theirs_rate.append(_per_second(lambda: grey_with_pybullet(scene, camera), 5))
        for cam in cameras:
            _, mask = grey_with_pybullet(scene, cam)
            mine = render(mesh, cam) != BACKGROUND_GREY
            ious.append(float((mine & mask).sum() / max((mine | mask).sum(), 1)))
        model = ImageModel(mesh, cameras, render_views(mesh, cameras), VisionSettings(resolution_px=resolution))
        state = mesh.positions_m.copy()
        model.start(state)
        dynamic = len(scene.dynamic_objects)
        moves = [(int(rng.integers(0, dynamic)), rng.standard_normal(2) * 0.04) for _ in range(steps)]

        def incremental_steps():
            for body, shift in moves:
                moved = state[body].copy()
                moved[:2] += shift
                model.propose(body, moved)

        def scratch_steps():
            for body, shift in moves[: max(1, steps // 10)]:
                trial = state.copy()
                trial[body, :2] += shift
                model.log_likelihood(trial)
        incremental.append(_per_second(incremental_steps, 1) * steps)
        scratch.append(_per_second(scratch_steps, 1) * max(1, steps // 10))
    return {"resolution_px": resolution, "renders_per_s": float(np.mean(ours_rate)),
            "pybullet_renders_per_s": float(np.mean(theirs_rate)), "silhouette_iou_mean": float(np.mean(ious)),
            "silhouette_iou_min": float(np.min(ious)), "mh_steps_per_s": float(np.mean(incremental)),
            "mh_steps_per_s_from_scratch": float(np.mean(scratch))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=5)
    parser.add_argument("--steps", type=int, default=300, help="MH proposals timed per tower")
    parser.add_argument("--resolutions", default="64,128,256")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "vision"))
    args = parser.parse_args()
    stim = load_tower_stimuli("willitfall.csv", shared_data_dir(), args.towers)
    rng = np.random.default_rng(0)
    rows = [measure(stim.scenes, int(r), args.steps, rng) for r in args.resolutions.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"date": date.today().isoformat(), "towers": len(stim.scenes), "source": stim.source,
              "steps": args.steps, "rows": rows}
    (out / "vision.json").write_text(json.dumps(result, indent=1))
    lines = [f"# Vision system cost ({result['date']})", "",
             f"{len(stim.scenes)} towers from {stim.source}; three views; one process; {args.steps} MH proposals "
             "per tower (one block moved each).", "",
             "| px | our renders/s | pybullet renders/s | speed-up | silhouette IoU mean (min) | MH steps/s "
             "(3 views) | from scratch | chain of 5000 s |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['resolution_px']} | {r['renders_per_s']:.0f} | {r['pybullet_renders_per_s']:.0f} | "
                     f"{r['renders_per_s'] / r['pybullet_renders_per_s']:.1f}x | {r['silhouette_iou_mean']:.3f} "
                     f"({r['silhouette_iou_min']:.3f}) | {r['mh_steps_per_s']:.0f} | {r['mh_steps_per_s_from_scratch']:.0f} "
                     f"| {5000 / r['mh_steps_per_s']:.1f} |")
    (out / "vision.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
