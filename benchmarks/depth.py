"""Depth perception (issue 33): calibration of the posterior, a hidden block, and what it costs.

    .venv/bin/python benchmarks/depth.py [--scenes 50] [--out benchmarks/results/depth]

Synthetic scenes with known truth: towers of 2-5 boxes (0.06-0.2 m, offsets up to a third of a
block), one depth camera 1-1.6 m away at a random azimuth and 20-45 degrees elevation, 320 x 240
with a Kinect-like field of view. The measured image is pybullet's renderer's (not ours), with
noise sd = 2 mm + 2.5 mm/m^2 x depth^2 and 5% of the pixels missing. The detector's guess (the
published scene) is the truth moved by N(0, 1 cm) in x and y and N(0, 0.05 rad) in yaw per block.
Reported: how often each coordinate's 95% interval covers the truth (goal 90-98%), the posterior SD
of blocks in view against blocks hidden behind another, and the chain's cost. Then: a 10-block
paper tower at k = 48 from one image, end to end (chain + IPE), with the share spent in the chain.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import Box, Floor, ModelConfig, Scene, preset  # noqa: E402
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK  # noqa: E402
from ipe_ros.engine.vision import depth as D  # noqa: E402
from ipe_ros.engine.vision import depth_io  # noqa: E402
from ipe_ros.engine.vision.camera import PinholeCamera, look_at  # noqa: E402
from ipe_ros.engine.vision.tinyrenderer import depth_with_pybullet  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
NOISE = dict(sd_m=0.002, sd_per_m2=0.0025, missing=0.05)


def noisy(depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    out = depth + (NOISE["sd_m"] + NOISE["sd_per_m2"] * depth ** 2) * rng.standard_normal(depth.shape)
    out[rng.random(depth.shape) < NOISE["missing"]] = 0.0
    return out


def tower(rng: np.random.Generator, blocks: int) -> Scene:
    objects, z = [], 0.0
    x = y = 0.0
    for i in range(blocks):
        size = rng.uniform(0.06, 0.2, 3)
        size[2] = min(size[2], 0.12)
        x += rng.uniform(-1, 1) * min(size[0], 0.1) / 3
        y += rng.uniform(-1, 1) * min(size[1], 0.1) / 3
        yaw = rng.uniform(-0.3, 0.3)
        objects.append(Box(name=f"b{i}", extents_m=tuple(map(float, size)), position_m=(x, y, z + size[2] / 2),
                           orientation_xyzw=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), friction=0.6,
                           restitution=0.0, mass_kg=1.0))
        z += size[2]
    return Scene(name="tower", objects=tuple(objects), support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


def camera_for(scene: Scene, rng: np.random.Generator) -> PinholeCamera:
    top = max(b.position_m[2] for b in scene.objects)
    azimuth, elevation = rng.uniform(0, 2 * math.pi), math.radians(rng.uniform(20, 45))
    distance = rng.uniform(1.0, 1.6)
    target = np.array([0.0, 0.0, top / 2])
    eye = target + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                        math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    return look_at(eye, target)


def detected(scene: Scene, rng: np.random.Generator, sd_m: float = 0.01, yaw_sd_rad: float = 0.05) -> Scene:
    """The detector's guess: every block moved and turned a little (heights kept)."""
    positions, yaws = [], []
    for b in scene.objects:
        yaws.append(yaw_sd_rad * rng.standard_normal())
        dx, dy = sd_m * rng.standard_normal(2)
        positions.append((b.position_m[0] + dx, b.position_m[1] + dy, b.position_m[2]))
    return D.scene_at_pose(scene, np.array(positions), np.array(yaws))


def yaw_of(q) -> float:
    return 2 * math.atan2(q[2], q[3])


def coverage(n_scenes: int, settings: D.DepthSettings, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    covered, total, visible_sd, hidden_sd, walls = 0, 0, [], [], []
    per_coordinate = np.zeros(4)
    for s in range(n_scenes):
        truth = tower(rng, int(rng.integers(2, 6)))
        camera = camera_for(truth, rng)
        observation = D.DepthObservation(camera, noisy(depth_with_pybullet(truth, camera), rng))
        guess = detected(truth, rng)
        start = time.perf_counter()
        posterior = D.run_depth_chain(guess, (observation,), settings, np.random.default_rng(seed + s))
        walls.append(time.perf_counter() - start)
        low, high = posterior.interval95()
        for i, (true_body, guessed) in enumerate(zip(truth.objects, guess.objects)):
            true_values = [*true_body.position_m,
                           math.remainder(yaw_of(true_body.orientation_xyzw) - yaw_of(guessed.orientation_xyzw),
                                          2 * math.pi)]
            hit = [(low[i, j] <= true_values[j] <= high[i, j]) for j in range(4)]
            per_coordinate += hit
            covered += sum(hit)
            total += 4
            sd = float(np.mean(posterior.positions_m[:, i, :2].std(axis=0)))
            (hidden_sd if _hidden_fraction(truth, camera, i) > 0.8 else visible_sd).append(sd)
    return {"scenes": n_scenes, "coordinates": total, "coverage": covered / total,
            "coverage_x_y_z_yaw": (per_coordinate / (total / 4)).tolist(),
            "visible_sd_m_median": float(np.median(visible_sd)) if visible_sd else None,
            "hidden_sd_m_median": float(np.median(hidden_sd)) if hidden_sd else None,
            "hidden_blocks": len(hidden_sd), "chain_s_median": float(np.median(walls))}


def _hidden_fraction(scene: Scene, camera: PinholeCamera, i: int) -> float:
    """Share of block i's pixels that another block covers in front of it."""
    from ipe_ros.engine.vision.render import body_patch, scene_mesh

    mesh = scene_mesh(scene)
    mine = body_patch(mesh, camera, i, mesh.positions_m[i])
    if mine.v1 <= mine.v0:
        return 1.0
    seen = np.isfinite(mine.depth)
    front = np.full(mine.depth.shape, np.inf)
    for j in range(len(scene.objects)):
        if j == i:
            continue
        other = body_patch(mesh, camera, j, mesh.positions_m[j])
        v0, v1 = max(other.v0, mine.v0), min(other.v1, mine.v1)
        u0, u1 = max(other.u0, mine.u0), min(other.u1, mine.u1)
        if v0 < v1 and u0 < u1:
            window = front[v0 - mine.v0:v1 - mine.v0, u0 - mine.u0:u1 - mine.u0]
            np.minimum(window, other.depth[v0 - other.v0:v1 - other.v0, u0 - other.u0:u1 - other.u0], out=window)
    return float((seen & (front < mine.depth)).sum() / max(1, seen.sum()))


def tower_cost(workers: int = 2, k: int = 48, repeats: int = 3) -> dict:
    """A 10-block paper tower (the built-in example) from one 320 x 240 depth image, end to end: the
    depth chains (one per worker), then the IPE at k on ``workers`` processes, self-checked (as the
    CLI runs it) and not, on the same posterior; ``repeats`` times, interleaved, medians."""
    import tempfile

    from ipe_ros.engine import QuerySpec, WorkerPool, load_scenes, predict
    from ipe_ros.engine import Context, Request
    from ipe_ros.engine.config import DEFAULT_QUERIES
    from ipe_ros.engine.scene.examples import example_scene_path

    with tempfile.TemporaryDirectory() as folder:
        paths = depth_io.write_depth_example(folder, load_scenes(example_scene_path())[0])
        observation = depth_io.load_observation(paths["depth"], paths["camera_info"], paths["camera_pose"].read_text().strip())
        guess = load_scenes(paths["scene"])[0]
    runs = []
    with WorkerPool(workers) as pool:
        pool.warm()
        for _ in range(repeats):
            start = time.perf_counter()
            perceived = D.perceive_depth(guess, k, (observation,), D.DepthSettings(), np.random.default_rng(0),
                                         map_fn=pool.map)
            chain_s = time.perf_counter() - start
            times = {}
            for checked in (True, False):
                start = time.perf_counter()
                prediction = predict(guess, Request(model=ModelConfig(perception="depth", samples=k),
                                                    settings=preset("default"), query=QuerySpec(queries=DEFAULT_QUERIES),
                                                    budget_s=None, check=DEFAULT_CHECK if checked else None),
                                     Context(map_fn=pool.map, perceived=perceived))
                times[checked] = time.perf_counter() - start
            runs.append((chain_s, times[True], times[False]))
    chain_s, checked_s, unchecked_s = (float(np.median(column)) for column in zip(*runs))
    return {"objects": len(guess.dynamic_objects), "k": k, "workers": workers, "repeats": repeats,
            "chain_s": chain_s, "predict_checked_s": checked_s, "predict_unchecked_s": unchecked_s,
            "total_s": chain_s + checked_s, "total_unchecked_s": chain_s + unchecked_s,
            "chain_share": chain_s / (chain_s + checked_s), "effective_sample_size": perceived.effective_sample_size,
            "acceptance_rate": perceived.acceptance_rate, "p_anything_falls": prediction.any_fall_probability}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=50, help="calibration scenes (0: the 10-block tower's time alone)")
    parser.add_argument("--temperature", type=float, default=None)
    parser.add_argument("--tower-k", type=int, default=48, help="k of the end-to-end 10-block tower")
    parser.add_argument("--tower-repeats", type=int, default=3, help="runs of the 10-block tower (median)")
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/depth"))
    args = parser.parse_args()
    settings = D.DepthSettings() if args.temperature is None else D.DepthSettings(temperature=args.temperature)
    report = {"date": time.strftime("%Y-%m-%d"), "settings": dataclasses.asdict(settings), "noise": NOISE,
              "calibration": coverage(args.scenes, settings) if args.scenes else None}
    print(json.dumps(report["calibration"], indent=1), flush=True)
    report["tower"] = tower_cost(k=args.tower_k, repeats=args.tower_repeats)
    print(json.dumps(report["tower"], indent=1), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "depth.json").write_text(json.dumps(report, indent=1) + "\n")
    if report["calibration"] is None:  # --scenes 0: the 10-block tower's time alone, no report
        return 0
    c, t = report["calibration"], report["tower"]
    lines = [f"# Depth perception ({report['date']})", "", "`.venv/bin/python benchmarks/depth.py`", "",
             f"- 95% intervals cover the truth in {c['coverage']:.1%} of {c['coordinates']} coordinates over "
             f"{c['scenes']} synthetic scenes (x {c['coverage_x_y_z_yaw'][0]:.1%}, y {c['coverage_x_y_z_yaw'][1]:.1%}, "
             f"z {c['coverage_x_y_z_yaw'][2]:.1%}, yaw {c['coverage_x_y_z_yaw'][3]:.1%}; goal 90-98%)",
             f"- posterior SD, median: blocks in view {c['visible_sd_m_median'] * 1000:.2f} mm"
             + ("" if c["hidden_sd_m_median"] is None else
                f", hidden blocks ({c['hidden_blocks']}) {c['hidden_sd_m_median'] * 1000:.1f} mm"),
             f"- chain per scene, median {c['chain_s_median']:.2f} s",
             f"- {t['objects']}-block tower from one 320 x 240 image, k = {t['k']}, {t['workers']} workers (median of "
             f"{t['repeats']}): {t['total_s']:.2f} s end to end self-checked, {t['total_unchecked_s']:.2f} s unchecked; "
             f"the chains {t['chain_s']:.2f} s (ESS {t['effective_sample_size']:.0f}, acceptance "
             f"{t['acceptance_rate']:.2f}), the prediction {t['predict_checked_s']:.2f} s checked, "
             f"{t['predict_unchecked_s']:.2f} s unchecked; goal <= 2 s"]
    (out / "depth.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
