"""Depth perception on images that share none of its assumptions (issue 49): calibration for visible and
hidden objects, error of the posterior mean against the detector's guess, and time.

    .venv/bin/python benchmarks/depth_independent.py [--scenes 50] [--predict-workers 2] [--out DIR]

(``--predict-workers N``: each scene also predicted end to end on N workers - the chains, one per
worker, then k = 48 samples self-checked - and timed: the robot-time goal; and P(anything falls)
scored against what the true tower does, with the samples set down and with their heights as drawn. ``--tilt-sd RAD``: every
box on another lies tilted by N(0, RAD) about x and y, published flat: the tilts' coverage.)

benchmarks/depth.py renders its evidence with pybullet and adds the likelihood's own noise; this one
can disagree with the code it measures:
- **rendering**: depth ray-cast from ROS's camera_info pinhole model alone (``tests/analytic_camera.py``:
  pixel centres at integer coordinates, its own quaternions and box intersections);
- **camera**: 640 x 480, fx ~ 525 px with fy 0-1% apart, the principal point up to 8 px off centre, a
  roll of up to 0.1 rad; read through ``camera_from_info`` from a CameraInfo-style K and P;
- **sensor** unlike the likelihood's: white noise 1.2 mm/m^2 x depth^2 plus spatially correlated
  noise (2-pixel blur, 1 mm), a bias of +0.5 mm and +0.1% of the range, 1 mm quantisation (16UC1),
  70% dropout at depth edges (> 3 cm between neighbours) and 2% of pixels missing;
- **scenes**: towers of 2-6 boxes, in half of them a published static board (0.1-0.4 m high) in
  front hiding part or all of the tower; the detector's guess 2 cm (x, y; SD), 5 mm (height) and
  0.05 rad off.
Objects are "visible" when >= 80% of their silhouette is the nearest surface, "hidden" when <= 20%.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from ipe_ros.engine import Body, Box, Floor, Scene  # noqa: E402
from ipe_ros.engine.scene.shapes import BoxShape  # noqa: E402
from ipe_ros.engine.vision import depth as D  # noqa: E402
from ipe_ros.engine.vision.camera import camera_from_info  # noqa: E402
from tests.analytic_camera import cast, optical_orientation, pixel_rays, visible_fraction  # noqa: E402

WIDTH, HEIGHT = 640, 480


def tower(rng: np.random.Generator) -> list[tuple]:
    """(centre, yaw, half sizes) of 2-6 stacked boxes."""
    boxes, z, x, y = [], 0.0, 0.0, 0.0
    for _ in range(int(rng.integers(2, 7))):
        size = rng.uniform(0.05, 0.16, 3)
        size[2] = min(size[2], 0.1)
        x += rng.uniform(-1, 1) * min(size[0], 0.1) / 4
        y += rng.uniform(-1, 1) * min(size[1], 0.1) / 4
        boxes.append(((x, y, z + size[2] / 2), float(rng.uniform(-0.4, 0.4)), tuple(size / 2)))
        z += size[2]
    return boxes


def camera_info(rng: np.random.Generator, target) -> tuple[dict, tuple, tuple]:
    """A CameraInfo-style dict (K and P of a rectified image) and the optical frame's pose."""
    azimuth, elevation = rng.uniform(0, 2 * math.pi), math.radians(rng.uniform(20, 45))
    distance = rng.uniform(1.0, 1.6)
    eye = np.asarray(target) + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                                    math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    fx = rng.uniform(515, 535)
    fy, cx, cy = fx * rng.uniform(1.0, 1.01), 319.5 + rng.uniform(-8, 8), 239.5 + rng.uniform(-8, 8)
    info = {"width": WIDTH, "height": HEIGHT, "k": [fx, 0, cx, 0, fy, cy, 0, 0, 1],
            "p": [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], "d": [0.0] * 5}
    return info, tuple(map(float, eye)), optical_orientation(eye, target, rng.uniform(-0.1, 0.1))


def board_between(eye, target, rng: np.random.Generator) -> tuple:
    """A thin upright board 30% of the way from the tower to the camera, hiding its lower part or a side."""
    eye, target = np.asarray(eye), np.asarray(target)
    spot = target + 0.3 * (eye - target)
    yaw = math.atan2(eye[1] - target[1], eye[0] - target[0])
    sideways = np.array([-math.sin(yaw), math.cos(yaw), 0.0]) * rng.uniform(-0.08, 0.08)
    height = rng.uniform(0.1, 0.4)
    return ((spot[0] + sideways[0], spot[1] + sideways[1], height / 2), yaw, (0.01, rng.uniform(0.05, 0.15), height / 2))


#: the sensor's departures from the likelihood, each of which ``--without`` can switch off to see its share
SENSOR_PARTS = ("bias", "correlated", "quantisation", "dropout")


def sensor(depth: np.ndarray, rng: np.random.Generator, without: frozenset = frozenset()) -> np.ndarray:
    """What a structured-light camera would send (16UC1 read back in metres; 0: no reading)."""
    from scipy.ndimage import gaussian_filter

    d = np.where(np.isfinite(depth), depth, 0.0)
    correlated = gaussian_filter(rng.standard_normal(d.shape), 2.0)
    correlated *= 0.001 / correlated.std() * ("correlated" not in without)
    bias = (d * 0.001 + 0.0005) * ("bias" not in without)
    measured = d + bias + 0.0012 * d ** 2 * rng.standard_normal(d.shape) + correlated
    edge = np.zeros(d.shape, bool)
    edge[:, 1:] |= np.abs(np.diff(d, axis=1)) > 0.03
    edge[1:, :] |= np.abs(np.diff(d, axis=0)) > 0.03
    edge[:, :-1] |= edge[:, 1:].copy()
    edge[:-1, :] |= edge[1:, :].copy()
    dropped = (edge & (rng.random(d.shape) < 0.7) & ("dropout" not in without)) | (rng.random(d.shape) < 0.02) | (d == 0)
    return np.where(dropped, 0.0, measured if "quantisation" in without else np.round(measured * 1000) / 1000)


def _tilted_scene(boxes, static: tuple | None) -> Scene:
    """``scene_of`` with each box's tilts (about the scene's x and y, after its yaw) applied."""
    from ipe_ros.engine.vision.depth import scene_at_pose

    flat = scene_of([(c, np.atleast_1d(pose)[0], half) for c, pose, half in boxes], static)
    tilts = np.array([np.atleast_1d(pose)[1:3] if np.size(pose) > 1 else (0.0, 0.0) for _, pose, _ in boxes])
    positions = np.array([c for c, _, _ in boxes], float)
    return dataclasses.replace(scene_at_pose(flat, positions, np.zeros(len(boxes)), tilts), name="independent")


def scene_of(boxes, static: tuple | None) -> Scene:
    objects = [Box(name=f"b{i}", extents_m=tuple(2 * np.asarray(half)), position_m=tuple(map(float, centre)),
                   orientation_xyzw=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), friction=0.6, restitution=0.0,
                   mass_kg=1.0) for i, (centre, yaw, half) in enumerate(boxes)]
    if static is not None:
        centre, yaw, half = static
        objects.append(Body(name="board", shape=BoxShape(tuple(2 * np.asarray(half))), position_m=centre,
                            orientation_xyzw=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), friction=0.6,
                            restitution=0.0, static=True))
    return Scene(name="independent", objects=tuple(objects), support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


#: the samples of the end-to-end prediction (``--predict-workers``), as the robot-time goal counts them
PREDICTION_K = 48


def one_scene(rng: np.random.Generator, chain_seed: int, settings: D.DepthSettings,
              without: frozenset = frozenset(), pool=None, tilt_sd_rad: float = 0.0) -> list[dict]:
    boxes = tower(rng)
    if tilt_sd_rad > 0:  # every box on another lies tilted (the detector publishes it flat)
        boxes = boxes[:1] + [(c, (yaw, *(tilt_sd_rad * rng.standard_normal(2))), half) for c, yaw, half in boxes[1:]]
    top = max(c[2] + h[2] for c, _, h in boxes)
    info, eye, orientation = camera_info(rng, (boxes[0][0][0], boxes[0][0][1], top / 2))
    board = board_between(eye, (0.0, 0.0, top / 2), rng) if rng.random() < 0.5 else None
    everything = boxes + ([board] if board else [])
    rays = pixel_rays(info["k"][0], info["k"][4], info["k"][2], info["k"][5], WIDTH, HEIGHT, orientation)
    clean, hit_by = cast(rays, eye, everything)
    observation = D.DepthObservation(camera_from_info(info, eye, orientation), sensor(clean, rng, without))
    guess_boxes = [((c[0] + 0.02 * rng.standard_normal(), c[1] + 0.02 * rng.standard_normal(),
                     c[2] + 0.005 * rng.standard_normal()), yaw + 0.05 * rng.standard_normal(), half)
                   for c, yaw, half in ((c, np.atleast_1d(yaw)[0], half) for c, yaw, half in boxes)]
    start = time.perf_counter()
    guess = scene_of(guess_boxes, board)
    perceived = D.perceive_depth(guess, PREDICTION_K, (observation,), settings, np.random.default_rng(chain_seed),
                                 map_fn=pool.map if pool is not None else None)
    posterior, wall_s = perceived.posterior, time.perf_counter() - start
    predict_s, outcome = None, {}
    if pool is not None:  # end to end: the prediction from the posterior's scenes, self-checked
        from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset
        from ipe_ros.engine import Context, Request
        from ipe_ros.engine.config import DEFAULT_QUERIES

        # the guess's heights are 5 mm off: one that sinks a box into the floor is refused as a scene, as
        # a detector would not publish it; the samples are the posterior's, heights estimated
        on_floor = dataclasses.replace(guess, objects=tuple(
            dataclasses.replace(b, position_m=(*b.position_m[:2], max(b.position_m[2], b.extents_m[2] / 2)))
            if i == 0 else b for i, b in enumerate(guess.objects)))
        queries = QuerySpec(queries=DEFAULT_QUERIES)
        start = time.perf_counter()
        answer = predict(on_floor,
                         Request(model=ModelConfig(perception="depth", samples=PREDICTION_K),
                                 settings=preset("default"), query=queries, budget_s=None),
                         Context(map_fn=pool.map, perceived=perceived))
        predict_s = time.perf_counter() - start
        # what the tower does (its true poses, simulated as given), against the answer, and against the
        # same posterior's samples with their heights as drawn (no set-down): the benchmark's own truth
        truth = predict(scene_of(boxes, board) if tilt_sd_rad == 0 else _tilted_scene(boxes, board),
                        Request(model=ModelConfig(samples=1, object_noise=False), settings=preset("default"),
                                query=queries, budget_s=None),
                        Context(map_fn=pool.map))
        as_drawn = dataclasses.replace(perceived, scenes=tuple(dataclasses.replace(s, set_down_m=0.0)
                                                               for s in perceived.scenes))
        unset = predict(on_floor,
                        Request(model=ModelConfig(perception="depth", samples=PREDICTION_K),
                                settings=preset("default"), query=queries, budget_s=None),
                        Context(map_fn=pool.map, perceived=as_drawn))
        outcome = {"fell": truth.any_fall_probability, "p_any_falls": answer.any_fall_probability,
                   "p_any_falls_as_drawn": unset.any_fall_probability}
    low, high = posterior.interval95()
    tilts = posterior.tilts()
    rows = []
    for i, ((centre, pose, _), (guessed, guessed_yaw, _)) in enumerate(zip(boxes, guess_boxes)):
        yaw, *tilt = (pose, 0.0, 0.0) if np.isscalar(pose) else pose
        truth = np.array([*centre, math.remainder(yaw - guessed_yaw, 2 * math.pi)])
        tilt_low, tilt_high = np.quantile(tilts[:, i], 0.025, axis=0), np.quantile(tilts[:, i], 0.975, axis=0)
        mean_xy = posterior.positions_m[:, i, :2].mean(axis=0)
        rows.append({"visible": visible_fraction(rays, eye, everything, hit_by, i),
                     "covered": [bool(low[i, j] <= truth[j] <= high[i, j]) for j in range(4)],
                     "error_m": float(np.hypot(*(mean_xy - truth[:2]))),
                     "guess_error_m": float(np.hypot(guessed[0] - centre[0], guessed[1] - centre[1])),
                     "height_error_m": float(abs(posterior.positions_m[:, i, 2].mean() - centre[2])),
                     "guess_height_error_m": float(abs(guessed[2] - centre[2])),
                     "sd_m": float(posterior.positions_m[:, i, :2].std(axis=0).mean()), "wall_s": wall_s,
                     "predict_s": predict_s, "tilted": i > 0 and tilt_sd_rad > 0,
                     "effective_sample_size": perceived.effective_sample_size,
                     "tilt_covered": [bool(tilt_low[j] <= tilt[j] <= tilt_high[j]) for j in range(2)],
                     "tilt_error_rad": float(np.hypot(*(tilts[:, i].mean(axis=0) - tilt))),
                     "guess_tilt_error_rad": float(np.hypot(*tilt)),
                     "boxes": len(boxes), "board": board is not None, "first": i == 0,
                     **(outcome if i == 0 else {})})
    return rows


def summary(rows: list[dict], scenes: int) -> dict:
    def group(selected):
        if not selected:
            return None
        covered = np.array([r["covered"] for r in selected])
        return {"objects": len(selected), "coordinates": covered.size, "coverage": float(covered.mean()),
                "coverage_x_y_z_yaw": covered.mean(axis=0).tolist(),
                "error_mm_median": 1000 * float(np.median([r["error_m"] for r in selected])),
                "guess_error_mm_median": 1000 * float(np.median([r["guess_error_m"] for r in selected])),
                "height_error_mm_median": 1000 * float(np.median([r["height_error_m"] for r in selected])),
                "guess_height_error_mm_median": 1000 * float(np.median([r["guess_height_error_m"] for r in selected])),
                "sd_mm_median": 1000 * float(np.median([r["sd_m"] for r in selected]))}

    per_scene = [r["wall_s"] for r in rows if r["first"]]
    totals = [r["wall_s"] + r["predict_s"] for r in rows if r["first"] and r.get("predict_s") is not None]
    return {"scenes": scenes, "all": group(rows), "visible": group([r for r in rows if r["visible"] >= 0.8]),
            "partly_hidden": group([r for r in rows if 0.2 < r["visible"] < 0.8]),
            "hidden": group([r for r in rows if r["visible"] <= 0.2]),
            "chain_s_median": float(np.median(per_scene)),
            "end_to_end_s_median": float(np.median(totals)) if totals else None,
            "end_to_end_within_2_s": sum(t <= 2.0 for t in totals) if totals else None,
            "effective_sample_size_median": float(np.median([r["effective_sample_size"] for r in rows if r["first"]])),
            "scenes_with_ess_at_least_half_k": sum(r["effective_sample_size"] >= PREDICTION_K / 2
                                                   for r in rows if r["first"]),
            "tilts": _tilt_summary([r for r in rows if r.get("tilted")]),
            "outcomes": _outcome_summary([r for r in rows if r["first"] and "fell" in r])}


def _outcome_summary(scenes: list[dict]) -> dict | None:
    """P(anything falls) against what the true tower does: Brier score and the mean P where it stands
    and where it falls, from the answer and from the same samples with their heights as drawn."""
    if not scenes:
        return None
    fell = np.array([r["fell"] for r in scenes], float)
    out = {"scenes": len(scenes), "fell": int(fell.sum())}
    for key in ("p_any_falls", "p_any_falls_as_drawn"):
        p = np.array([r[key] for r in scenes], float)
        out[key] = {"brier": float(np.mean((p - fell) ** 2)),
                    "mean_p_where_it_stands": float(p[fell == 0].mean()) if (fell == 0).any() else None,
                    "mean_p_where_it_falls": float(p[fell == 1].mean()) if (fell == 1).any() else None,
                    "scenes_wrong_side_of_half": int(np.sum((p >= 0.5) != (fell == 1)))}
    return out


def _tilt_summary(tilted: list[dict]) -> dict | None:
    """Coverage of the tilts (about the scene's x and y) of the boxes that lie tilted on another."""
    if not tilted:
        return None
    return {"objects": len(tilted), "coverage": float(np.mean([r["tilt_covered"] for r in tilted])),
            "error_rad_median": float(np.median([r["tilt_error_rad"] for r in tilted])),
            "guess_error_rad_median": float(np.median([r["guess_tilt_error_rad"] for r in tilted]))}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=49)
    parser.add_argument("--without", action="append", choices=SENSOR_PARTS, default=[],
                        help="switch off one of the sensor's departures from the likelihood (repeatable)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a DepthSettings field for this run (e.g. offset_prior_sd_m=0)")
    parser.add_argument("--label", default="", help="a name for this run in the report (e.g. the commit)")
    parser.add_argument("--tilt-sd", type=float, default=0.0, metavar="RAD",
                        help="every box on another lies tilted by N(0, RAD) about x and y (published flat)")
    parser.add_argument("--predict-workers", type=int, default=0, metavar="N",
                        help="also predict each scene end to end (the chains and k = 48 samples, self-checked) on N "
                             "worker processes, and time it")
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/depth_independent"))
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    fields = {f.name: f.type for f in dataclasses.fields(D.DepthSettings)}
    settings = D.DepthSettings(**{k: int(v) if fields[k] == "int" else float(v)
                                  for k, v in (item.split("=", 1) for item in args.set)})
    rows = []
    pool = None
    if args.predict_workers:
        from ipe_ros.engine import WorkerPool

        pool = WorkerPool(args.predict_workers)
        pool.warm()
    try:
        for s in range(args.scenes):
            rows.extend(one_scene(rng, args.seed * 1000 + s, settings, frozenset(args.without), pool, args.tilt_sd))
            print(f"scene {s + 1}/{args.scenes}: {rows[-1]['wall_s']:.1f} s", flush=True)
    finally:
        if pool is not None:
            pool.close()
    result = {"date": time.strftime("%Y-%m-%d"), "label": args.label, "summary": summary(rows, args.scenes),
              "objects": rows}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "depth_independent.json").write_text(json.dumps(result, indent=1) + "\n")
    s = result["summary"]
    command = " ".join(["--scenes", str(args.scenes), *([f"--seed {args.seed}"] if args.seed != 49 else []),
                        *([f"--predict-workers {args.predict_workers}"] if args.predict_workers else []),
                        *([f"--tilt-sd {args.tilt_sd:g}"] if args.tilt_sd else []),
                        *(f"--set {x}" for x in args.set),
                        *(f"--without {x}" for x in args.without)])
    lines = [f"# Depth perception on independent images ({result['date']}{', ' + args.label if args.label else ''})",
             "", f"`.venv/bin/python benchmarks/depth_independent.py {command}`", "",
             "| objects | n | 95% coverage (x / y / z / yaw) | posterior mean error, median | guess error, median | "
             "posterior SD, median | height error: posterior / guess, median |", "|---|---|---|---|---|---|---|"]
    for name in ("visible", "partly_hidden", "hidden", "all"):
        g = s[name]
        if g is not None:
            x, y, z, yaw = g["coverage_x_y_z_yaw"]
            lines.append(f"| {name.replace('_', ' ')} | {g['objects']} | {g['coverage']:.1%} ({x:.0%} / {y:.0%} / "
                         f"{z:.0%} / {yaw:.0%}) | {g['error_mm_median']:.2f} mm | {g['guess_error_mm_median']:.1f} mm | "
                         f"{g['sd_mm_median']:.2f} mm | {g['height_error_mm_median']:.2f} / "
                         f"{g['guess_height_error_mm_median']:.1f} mm |")
    lines += ["", f"Effective sample size of the chains (k = {PREDICTION_K} scenes drawn), median "
                  f"{s['effective_sample_size_median']:.0f}; at least k/2 in {s['scenes_with_ess_at_least_half_k']} "
                  f"of {args.scenes} scenes."]
    lines += ["", f"Chains per scene, median {s['chain_s_median']:.1f} s"
              + (f" (on {args.predict_workers} workers); end to end with the prediction (k = {PREDICTION_K}, "
                 f"self-checked), median {s['end_to_end_s_median']:.2f} s, within 2 s in "
                 f"{s['end_to_end_within_2_s']} of {args.scenes} scenes." if args.predict_workers else " (one process).")]
    if s["outcomes"] is not None:
        o = s["outcomes"]
        lines += ["", f"P(anything falls) against what the true tower does ({o['fell']} of {o['scenes']} fall; "
                      "simulated as given, default preset):", "",
                  "| samples | Brier | mean P where it stands | mean P where it falls | wrong side of 0.5 |",
                  "|---|---|---|---|---|"]
        for key, name in (("p_any_falls", "set down (the answer)"), ("p_any_falls_as_drawn", "heights as drawn")):
            g = o[key]
            shown = [f"{v:.3f}" if v is not None else "-" for v in (g["brier"], g["mean_p_where_it_stands"],
                                                                       g["mean_p_where_it_falls"])]
            lines.append(f"| {name} | {' | '.join(shown)} | {g['scenes_wrong_side_of_half']} |")
    if s["tilts"] is not None:
        t = s["tilts"]
        lines += ["", f"Tilts of the {t['objects']} boxes lying tilted on another: 95% intervals cover "
                      f"{t['coverage']:.1%} of {2 * t['objects']}; error {1000 * t['error_rad_median']:.1f} mrad "
                      f"(median; published flat: {1000 * t['guess_error_rad_median']:.1f} mrad)."]
    (out / "depth_independent.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
