"""The direct solver for impacts only, against it for the whole rollout: time and answers on the zoo.

    .venv/bin/python benchmarks/impacts.py [--per-family 3] [--samples 8] [--seed 2026]
                                           [--presets paper,default] [--families bouncy]
                                           [--out benchmarks/results/impacts]

Every zoo family whose scenes can bounce (a world on the direct solver), in each preset, twice on the
same noisy scenes: as the presets are (``solver.direct_solver_for_impacts_only``: the direct solver
only for steps with an impact, simulation/impacts.py) and with the direct solver for the whole
rollout (as before). Per family: seconds per prediction of each (taking turns scene by scene, one
process: a ratio, not a speed), the share of pybullet steps the direct solver took, and the mean
|dP(object falls)| between the two (what the friction cone changed). Self-check off: the physics alone.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset  # noqa: E402
from ipe_ros.engine import Request
from ipe_ros.engine.config import DEFAULT_QUERIES  # noqa: E402
from ipe_ros.engine.scene.zoo import FAMILIES, zoo_scene, zoo_sigma_m  # noqa: E402
from ipe_ros.engine.simulation import impacts, uses_direct_solver  # noqa: E402


class _CountingWatch(impacts.ImpactWatch):
    """ImpactWatch that adds its steps to the class's tallies (one process, no pool)."""

    steps = 0
    direct = 0

    def choose(self, step_s: float) -> bool:
        direct = super().choose(step_s)
        type(self).steps += 1
        type(self).direct += direct
        return direct


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-family", type=int, default=3)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--presets", default="paper,default")
    parser.add_argument("--families", default=None, help="comma-separated (default: every family)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    from ipe_ros.engine.simulation import stepper
    stepper.ImpactWatch = _CountingWatch
    query = QuerySpec(queries=DEFAULT_QUERIES)
    rows = []
    for name in args.presets.split(","):
        impacts_only = preset(name)
        whole = impacts_only.changed(solver={"direct_solver_for_impacts_only": False})
        for family in (args.families.split(",") if args.families else FAMILIES):
            scenes = [zoo_scene(family, args.seed, i) for i in range(args.per_family)]
            scenes = [s for s in scenes if uses_direct_solver(s, impacts_only, [b.resolved_mass_kg for b in s.dynamic_objects])]
            if not scenes:
                continue
            seconds = {"impacts": 0.0, "whole": 0.0}
            differences = []
            _CountingWatch.steps = _CountingWatch.direct = 0
            for scene in scenes:
                model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.samples)
                answers = {}
                for label, settings in (("impacts", impacts_only), ("whole", whole)):
                    start = time.perf_counter()
                    answers[label] = predict(scene,
                                             Request(model=model, settings=settings, query=query, seed=1, check=None,
                                                     budget_s=None))
                    seconds[label] += time.perf_counter() - start
                a, b = answers["impacts"].object_fall_probability, answers["whole"].object_fall_probability
                differences.extend(abs(a[k] - b[k]) for k in a)
            rows.append({"preset": name, "family": family, "scenes": len(scenes),
                         "s_impacts": seconds["impacts"] / len(scenes), "s_whole": seconds["whole"] / len(scenes),
                         "direct_share": _CountingWatch.direct / max(1, _CountingWatch.steps),
                         "mean_abs_dP": float(np.mean(differences)), "max_abs_dP": float(np.max(differences))})
            r = rows[-1]
            print(f"{name:8s} {family:10s} scenes {r['scenes']}  impacts only {r['s_impacts']:.2f} s  whole "
                  f"{r['s_whole']:.2f} s  ({r['s_whole'] / r['s_impacts']:.2f}x)  direct on "
                  f"{100 * r['direct_share']:.1f}% of steps  |dP| mean {r['mean_abs_dP']:.3f} max {r['max_abs_dP']:.3f}",
                  flush=True)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "impacts.json").write_text(json.dumps({"args": vars(args) | {"out": str(args.out)},
                                                           "rows": rows}, indent=1))
        lines = ["| preset | family | scenes | impacts only s | whole rollout s | impacts only vs whole | "
                 "direct solver on | mean \\|dP\\| | max \\|dP\\| |", "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {r['preset']} | {r['family']} | {r['scenes']} | {r['s_impacts']:.2f} | {r['s_whole']:.2f} | "
                  f"{r['s_whole'] / r['s_impacts']:.2f}x | {100 * r['direct_share']:.1f}% of steps | "
                  f"{r['mean_abs_dP']:.3f} | {r['max_abs_dP']:.3f} |" for r in rows]
        (args.out / "impacts.md").write_text(f"# The direct solver for impacts only, against it for whole rollouts\n\n"
                                             f"`{' '.join(sys.argv)}`\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
