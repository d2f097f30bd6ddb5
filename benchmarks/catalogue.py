"""Accuracy against time and numerical health on the random scene catalogue, beside the towers' table.

    .venv/bin/python benchmarks/catalogue.py [--scenes 40] [--samples 8] [--seed 2026] [--workers 2]
                                             [--out benchmarks/results/catalogue]

The catalogue (ipe_ros.engine.scene.catalogue: mixed shapes, 5 mm to 1 m, mass ratios up to 1000:1,
restitution to 0.9, friction 0-2, bodies thrown at up to 10 m/s) under every preset, with the
queries fall + direction (rollouts run until every body is at rest, not only until it is decided).
Each scene's sigma is 5% of its smallest body. `paper` is the reference, timed in the same run; the
noisy initial scenes are the same for every preset. Per preset: seconds per prediction, speed-up over
`paper`, mean and max |delta fall fraction|, per-sample agreement on "did anything fall?", the worst
end penetration (fraction of a body's smallest extent), the worst energy gain (% of the scene's energy
scale: weight x size + initial kinetic energy), and failed samples.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


from accuracy_vs_time import REPO, compare, run_config  # noqa: E402 - the same comparison as the towers'
from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, WorkerPool  # noqa: E402
from ipe_ros.engine.scene.catalogue import scene_catalogue  # noqa: E402
from ipe_ros.engine.simulation.health import energy_scale_j  # noqa: E402

QUERY = QuerySpec(queries=frozenset({"fall", "direction"}))


def run_catalogue(scenes, settings, samples: int, pool: WorkerPool) -> dict:
    """Like run_config, but each scene gets its own sigma (5% of its smallest body)."""
    start = time.perf_counter()
    predictions = []
    for i, scene in enumerate(scenes):
        model = ModelConfig(sigma_m=0.05 * min(b.smallest_extent_m for b in scene.objects), samples=samples)
        predictions.append(run_config([scene], settings, model, QUERY, pool)["predictions"][0])
    wall = time.perf_counter() - start
    return {"wall_s": wall, "predictions": predictions, "rollouts": sum(p.samples for p in predictions)}


def health(scenes, result: dict) -> dict:
    ok = [(s, p) for s, p in zip(scenes, result["predictions"]) if p.samples]
    return {"max_end_penetration_fraction": max(p.max_penetration_fraction for _, p in ok),
            "max_energy_gain_percent": max(100 * p.max_energy_gain_j / energy_scale_j(s) for s, p in ok),
            "scenes_gaining_over_1_percent": sum(p.max_energy_gain_j > 0.01 * energy_scale_j(s) for s, p in ok)}


def markdown(report: dict) -> str:
    lines = [f"# The scene catalogue: {report['scenes']} scenes (seed {report['seed']}), k = {report['samples']}, "
             "queries fall + direction", "", f"{report['machine']}; {report['date']}; sigma = 5% of each scene's "
             "smallest body.", "",
             "| preset | s / prediction | speed-up | mean \\|ΔFF\\| | max \\|ΔFF\\| | per-sample agreement | "
             "worst end penetration | worst energy gain | scenes gaining > 1% | failed samples |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in report["rows"]:
        lines.append(f"| {row['preset']} | {row['wall_s_per_prediction']:.2f} | {row['speedup_vs_paper']:.1f}x | "
                     f"{row['mean_abs_dff']:.3f} | {row['max_abs_dff']:.3f} | {row['per_sample_agreement']:.1%} | "
                     f"{row['max_end_penetration_fraction']:.1%} | {row['max_energy_gain_percent']:.1f}% | "
                     f"{row['scenes_gaining_over_1_percent']} | {row['failed_samples']} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=40)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "catalogue"))
    args = parser.parse_args()
    scenes = scene_catalogue(args.seed, args.scenes)
    report = {"scenes": len(scenes), "seed": args.seed, "samples": args.samples, "machine": f"{os.cpu_count()} CPUs",
              "date": time.strftime("%Y-%m-%d"), "rows": []}
    with WorkerPool(args.workers) as pool:
        pool.warm()
        reference = run_catalogue(scenes, PRESETS["paper"], args.samples, pool)
        for name in ("paper", "accurate", "fine", "default"):
            result = reference if name == "paper" else run_catalogue(scenes, PRESETS[name], args.samples, pool)
            row = {"preset": name, **compare(result, reference), **health(scenes, result)}
            report["rows"].append(row)
            print(f"{name:<9} {row['wall_s_per_prediction']:6.2f} s  x{row['speedup_vs_paper']:5.2f}  "
                  f"|dFF| {row['mean_abs_dff']:.3f}/{row['max_abs_dff']:.3f}  agree {row['per_sample_agreement']:.3f}  "
                  f"pen {row['max_end_penetration_fraction']:.3f}  dE {row['max_energy_gain_percent']:.2f}%", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "catalogue.json").write_text(json.dumps(report, indent=1))
    (out / "catalogue.md").write_text(markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
