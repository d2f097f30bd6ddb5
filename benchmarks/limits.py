"""Where the validity ranges of ipe_ros/engine/scene/limits.py come from: the engine measured past them.

    .venv/bin/python benchmarks/limits.py [--out benchmarks/results/limits]

Ranges are checked by ``validate_scene``, so this script builds the scenes past the limits directly
(no validation) and runs the ground-truth model (one rollout, ``default`` and ``paper``) on:

- size: a standing two-block stack and one leaning past its edge, scaled from 0.2 mm to 200 m:
  the step each gets, steps per rollout, seconds per rollout, and whether the answers are right
  (standing stays, leaning falls) with the end penetration;
- mass ratio: a heavy block on a light one, 10:1 to 30,000:1: the end penetration and whether
  ``default`` and ``paper`` agree (nothing falls);
- position: the leaning stack moved 1 km to 1e15 m from the origin: the largest difference of its
  final state from the same stack at the origin (in units of its size).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import Box, Floor, ModelConfig, QuerySpec, Scene, preset  # noqa: E402
from ipe_ros.engine.sampling.rollout import SampleTask, run_sample  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def stack(size_m: float, offset_fraction: float, heavy_ratio: float = 1.0, origin=(0.0, 0.0, 0.0)) -> Scene:
    """Two cubes of side ``size_m``, the top one shifted by ``offset_fraction`` of a side."""
    x, y, z = origin
    bottom = Box(name="bottom", extents_m=(size_m,) * 3, position_m=(x, y, z + size_m / 2), orientation_xyzw=IDENTITY,
                 friction=0.6, restitution=0.0, mass_kg=1.0)
    top = Box(name="top", extents_m=(size_m,) * 3, position_m=(x + offset_fraction * size_m, y, z + 1.5 * size_m),
              orientation_xyzw=IDENTITY, friction=0.6, restitution=0.0, mass_kg=heavy_ratio)
    return Scene(name="stack", objects=(bottom, top), support=Floor(friction=0.6, restitution=0.0, height_m=z),
                 gravity_m_s2=(0.0, 0.0, -9.81))


def ground_truth(scene: Scene, preset_name: str):
    task = SampleTask(scene=scene, model=ModelConfig(), settings=preset(preset_name),
                      query=QuerySpec(queries=frozenset({"fall", "direction"})), index=0,
                      seed=np.random.SeedSequence(0))
    start = time.perf_counter()
    outcome = run_sample(task)
    seconds = time.perf_counter() - start
    if not outcome.ok:
        return {"error": outcome.error, "seconds": seconds}
    r = outcome.rollouts[0]
    return {"fell": bool(r.fallen.any()), "penetration": float(r.penetration_fraction), "seconds": seconds,
            "final": r.final_positions_m, "simulated_s": r.simulated_s}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/limits"))
    args = parser.parse_args()
    settings = preset("default")
    sizes = []
    for size in (2e-4, 5e-4, 1e-3, 5e-3, 0.2, 5.0, 10.0, 20.0, 50.0, 100.0):
        dt = settings.time_step_for(size, 9.81)
        standing, leaning = ground_truth(stack(size, 0.1), "default"), ground_truth(stack(size, 0.7), "default")
        sizes.append({"size_m": size, "time_step_s": dt, "steps_per_2s": int(round(2.0 / dt)),
                      "standing_stands": standing.get("fell") is False, "leaning_falls": leaning.get("fell") is True,
                      "end_penetration": max(standing.get("penetration", np.nan), leaning.get("penetration", np.nan)),
                      "seconds_per_rollout": leaning["seconds"]})
    ratios = []
    for ratio in (10.0, 100.0, 1000.0, 3000.0, 10000.0, 30000.0):
        fast, slow = ground_truth(stack(0.2, 0.0, ratio), "default"), ground_truth(stack(0.2, 0.0, ratio), "paper")
        ratios.append({"mass_ratio": ratio, "default_fell": fast.get("fell"), "paper_fell": slow.get("fell"),
                       "default_end_penetration": fast.get("penetration"), "paper_end_penetration": slow.get("penetration"),
                       "errors": [r["error"] for r in (fast, slow) if "error" in r]})
    positions = []
    at_origin = ground_truth(stack(0.2, 0.7), "default")
    for distance in (1e3, 1e4, 1e5, 1e7, 1e15):
        moved = ground_truth(stack(0.2, 0.7, origin=(distance, 0.0, 0.0)), "default")
        if "final" in moved:
            shifted = moved["final"] - np.array([distance, 0.0, 0.0])
            difference = float(np.abs(shifted - at_origin["final"]).max() / 0.2)
        else:
            difference = None
        positions.append({"distance_m": distance, "same_outcome": moved.get("fell") == at_origin.get("fell"),
                          "max_difference_sizes": difference, "error": moved.get("error")})
    report = {"date": time.strftime("%Y-%m-%d"), "preset": "default", "sizes": sizes, "mass_ratios": ratios,
              "positions": positions}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "limits.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    lines = [f"# Validity ranges measured ({report['date']})", "",
             "`.venv/bin/python benchmarks/limits.py`: ground truth (one rollout) of a two-cube stack, `default` "
             "unless named.", "",
             "| cube side m | step ms | steps per 2 s | standing stands | leaning falls | end penetration | s per rollout |",
             "|---|---|---|---|---|---|---|"]
    for r in sizes:
        lines.append(f"| {r['size_m']:g} | {1e3 * r['time_step_s']:.3g} | {r['steps_per_2s']} | {r['standing_stands']} | "
                     f"{r['leaning_falls']} | {r['end_penetration']:.1%} | {r['seconds_per_rollout']:.2f} |")
    lines += ["", "| heavy:light | default falls | paper falls | default end penetration | paper end penetration |",
              "|---|---|---|---|---|"]
    for r in ratios:
        pen = lambda v: "-" if v is None else f"{v:.1%}"  # noqa: E731
        lines.append(f"| {r['mass_ratio']:g}:1 | {r['default_fell']} | {r['paper_fell']} | "
                     f"{pen(r['default_end_penetration'])} | {pen(r['paper_end_penetration'])} |")
    lines += ["", "| moved from the origin by m | same outcome | largest difference / size |", "|---|---|---|"]
    for r in positions:
        diff = "-" if r["max_difference_sizes"] is None else f"{r['max_difference_sizes']:.2g}"
        lines.append(f"| {r['distance_m']:g} | {r['same_outcome']} | {diff} |")
    (out / "limits.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
