"""Which settings may the self-check use as its converged reference? (issue: a check that costs less)

    .venv/bin/python benchmarks/reference_tier.py [--towers 20] [--per-family 2] [--samples 16] [--out DIR]

Every sample of every scene is run at the reference the self-check uses today (`paper`'s physics,
ending at rest by the strict reading: `paper+rest`), at `paper` with half its step (`paper-half`,
the bar: how closely `paper` agrees with itself), and at candidate cheaper tiers, with the same
seeds (every preset separates the same noisy scene). Per tier against `paper+rest`: the share of
samples whose yes/no outcomes (``fidelity.outcome_flags``: which objects fell, whether anything
fell) are all the same, mean and worst |dP| per object over scenes, and the wall time per sample
(2 workers, the tiers of a scene one after the other). A candidate is admissible where it agrees
with the reference at least as closely as `paper-half` does, family by family. Scenes: the authors'
towers (../shared/data/battaglia2013, generated towers without it) at sigma 0.04 m, and the zoo's
families at their own sigma. Writes ``reference_tier.md`` and ``.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from check_policy import object_p  # noqa: E402 - per object, the share of rollouts in which it fell
from ipe_ros.analysis.paper_data import shared_data_dir  # noqa: E402
from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, WorkerPool, load_scenes  # noqa: E402
from ipe_ros.engine.checking.fidelity import outcome_flags, reference_settings  # noqa: E402
from ipe_ros.engine.sampling.montecarlo import MonteCarlo  # noqa: E402
from ipe_ros.engine.sampling.rollout import lost, run_sample  # noqa: E402
from ipe_ros.engine.predict import make_tasks  # noqa: E402
from ipe_ros.engine.scene.generators import generate_towers  # noqa: E402
from ipe_ros.engine.scene.zoo import family_of, scene_zoo, zoo_sigma_m  # noqa: E402

QUERY = QuerySpec(queries=frozenset({"fall", "any_fall"}))


def tiers() -> dict:
    reference = reference_settings()
    paper = PRESETS["paper"]
    return {
        "paper+rest": reference,
        "paper-half": reference.changed("paper-half", time_step_s=paper.time_step_s / 2),
        "accurate+rest": PRESETS["accurate"].changed("accurate+rest", early_stop={"enabled": True}),
        "paper-30it+rest": reference.changed("paper-30it+rest", solver={"iterations": 30}),
        "fine": PRESETS["fine"],
    }


def scenes(args) -> list[tuple[str, object, float]]:
    path = shared_data_dir() / "stability_all_towers.csv"
    towers = load_scenes(path)[:args.towers] if path.exists() else generate_towers(2013, args.towers)
    out = [("towers", t, 0.04) for t in towers]
    out += [(family_of(s), s, zoo_sigma_m(s)) for s in scene_zoo(args.seed, args.per_family)]
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=20)
    parser.add_argument("--per-family", type=int, default=2)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", default="benchmarks/results/reference_tier")
    args = parser.parse_args()
    settings = tiers()
    rows = []
    chosen = scenes(args)
    with WorkerPool(2) as pool:
        run = MonteCarlo(run_sample, lost, pool.map).run
        run(make_tasks(chosen[0][1], ModelConfig(sigma_m=0.04, samples=2), PRESETS["default"], QUERY, 0))
        for group, scene, sigma in chosen:
            tasks = make_tasks(scene, ModelConfig(sigma_m=sigma, samples=args.samples), PRESETS["default"], QUERY, 11)
            runs, seconds = {}, {}
            for name, tier in settings.items():
                start = time.perf_counter()
                runs[name] = run([t.at(tier) for t in tasks])
                seconds[name] = (time.perf_counter() - start) / len(tasks)
            ref = runs["paper+rest"]
            row = {"group": group, "scene": scene.name, "seconds_per_sample": seconds}
            for name, outcomes in runs.items():
                pairs = [(a, b) for a, b in zip(outcomes, ref) if a.ok and b.ok]
                same = float(np.mean([np.array_equal(outcome_flags(a), outcome_flags(b)) for a, b in pairs]))
                dp = np.abs(object_p(outcomes) - object_p(ref))
                row[name] = {"agreement": same, "mean_dp": float(dp.mean()), "max_dp": float(dp.max(initial=0.0)),
                             "failed": sum(not o.ok for o in outcomes)}
            rows.append(row)
            print(group, scene.name, {n: round(row[n]["mean_dp"], 3) for n in settings},
                  {n: round(s, 3) for n, s in seconds.items()}, flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "reference_tier.json").write_text(json.dumps({"args": vars(args), "rows": rows}, indent=1))
    (out / "reference_tier.md").write_text(report(rows, list(settings), args))
    print(report(rows, list(settings), args))
    return 0


def report(rows: list[dict], names: list[str], args) -> str:
    groups = list(dict.fromkeys(r["group"] for r in rows))
    lines = [f"# Reference tiers against `paper+rest` ({time.strftime('%Y-%m-%d')})", "",
             f"`benchmarks/reference_tier.py --towers {args.towers} --per-family {args.per_family} --samples "
             f"{args.samples}`: per group, the share of samples with every yes/no outcome as the reference's, "
             "mean / worst |dP| per object over scenes, and seconds per sample (2 workers). `paper-half` is the bar.",
             "", "| group | scenes | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for group in groups + ["all"]:
        mine = [r for r in rows if group in ("all", r["group"])]
        cells = []
        for name in names:
            agreement = np.mean([r[name]["agreement"] for r in mine])
            mean_dp = np.mean([r[name]["mean_dp"] for r in mine])
            worst = max(r[name]["max_dp"] for r in mine)
            per_sample = np.mean([r["seconds_per_sample"][name] for r in mine])
            cells.append(f"{agreement:.3f} / {mean_dp:.3f} / {worst:.2f} / {per_sample:.3f} s")
        lines.append(f"| {group} | {len(mine)} | " + " | ".join(cells) + " |")
    lines += ["", "Each cell: per-sample agreement / mean |dP| / worst |dP| / seconds per sample."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
