"""Collapse steps on trial: what each of its two rules does (config.CollapseSettings).

    .venv/bin/python benchmarks/collapse_trial.py [--samples 16] [--per-family 6] [--towers 60]
        [--columns 20:10,10:8,10:7,40:35,40:20] [--families ramp,drop,strike,plates,dominoes]
        [--out benchmarks/results/collapse_trial]

`default` with both rules ("both"), with the collapse steps never undone ("no undo"), never ended at
quiet ("no end at quiet"), undone only above 5% ("undo at 5%"), and with neither ("neither": the
physics before the rules, bit for bit on the authors' towers), all unchecked (the physics alone),
on the same seeds:
- columns of 10 cm cubes with one cube left out (k = 8, sigma 5 mm): P(falls) of the cubes below the
  gap, which `paper` leaves standing;
- the zoo's ramp, drop, strike, plates and dominoes families (the default queries): mean and worst
  |dP(object falls)| against `paper`, speed-up over it, rollouts undone;
- the authors' towers (``--query fall``, k = 48): seconds against "neither", fall fractions moved,
  rollouts undone.
Configurations take turns scene by scene; 2 workers, one run.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

from actions import column  # noqa: E402 - the robot-question benchmark's column of 10 cm cubes
from ipe_ros.engine import ModelConfig, QuerySpec, Scene, WorkerPool, predict, preset, scenes_from_tower_csv  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.config import DEFAULT_QUERIES, DEFAULT_SIGMA_M  # noqa: E402
from ipe_ros.engine.scene.zoo import zoo_scene, zoo_sigma_m  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
NEVER = {"max_created_energy_fraction": 1e9, "quiet_sizes_per_s": 1e-9}
CONFIGURATIONS = {
    "both": {},
    "no undo": {"max_created_energy_fraction": 1e9},
    "no end at quiet": {"quiet_sizes_per_s": 1e-9},
    "undo at 5%": {"max_created_energy_fraction": 0.05},
    "neither": NEVER,
}
COLUMNS = "20:10,10:8,10:7,40:35,40:20"  # cubes : the one left out
FAMILIES = "ramp,drop,strike,plates,dominoes"


def settings(name: str):
    return preset("default").changed(collapse=CONFIGURATIONS[name]) if CONFIGURATIONS[name] else preset("default")


def column_with_a_gap(count: int, gap: int) -> Scene:
    whole = column(count)
    return dataclasses.replace(whole, name=f"column_{count}_without_c{gap}",
                               objects=tuple(b for b in whole.objects if b.name != f"c{gap}"))


def columns(pool, names, spec: str) -> list[dict]:
    rows = []
    query = QuerySpec(queries=frozenset({"fall"}))
    for count, gap in (map(int, item.split(":")) for item in spec.split(",") if item):
        scene = column_with_a_gap(count, gap)
        row = {"scene": scene.name}
        for name in ["paper", *names]:
            p = predict(scene,
                        Request(model=ModelConfig(sigma_m=0.005, samples=8),
                                settings=preset("paper") if name == "paper" else settings(name), query=query, seed=0,
                                check=None, budget_s=None),
                        Context(map_fn=pool.map))
            below = [v for k, v in p.object_fall_probability.items() if int(k[1:]) < gap]
            row[name] = max(below)
        rows.append(row)
        print(row, flush=True)
    return rows


def zoo(pool, names, families: str, per_family: int, samples: int) -> list[dict]:
    query = QuerySpec(queries=DEFAULT_QUERIES)
    rows = []
    for family in families.split(","):
        walls = {n: 0.0 for n in ["paper", *names]}
        diffs = {n: [] for n in names}
        worst = {n: 0.0 for n in names}
        undone = {n: 0 for n in names}
        for i in range(per_family):
            scene = zoo_scene(family, 2026, i)
            model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=samples)
            start = time.perf_counter()
            ref = predict(scene,
                          Request(model=model, settings=preset("paper"), query=query, seed=0, check=None,
                                  budget_s=None),
                          Context(map_fn=pool.map))
            walls["paper"] += time.perf_counter() - start
            for n in names:
                start = time.perf_counter()
                p = predict(scene,
                            Request(model=model, settings=settings(n), query=query, seed=0, check=None, budget_s=None),
                            Context(map_fn=pool.map))
                walls[n] += time.perf_counter() - start
                d = [abs(p.object_fall_probability[o] - ref.object_fall_probability[o])
                     for o in ref.object_fall_probability]
                diffs[n].append(float(np.mean(d)))
                worst[n] = max(worst[n], max(d))
                undone[n] += p.collapse_undone_rollouts
        row = {"family": family, **{n: {"mean": float(np.mean(diffs[n])), "worst": worst[n],
                                        "speedup": walls["paper"] / walls[n], "undone": undone[n]} for n in names}}
        rows.append(row)
        print(row, flush=True)
    return rows


def towers(pool, count: int) -> dict:
    from ipe_ros.analysis.paper_data import shared_data_dir

    csv = shared_data_dir() / "willitfall.csv"
    if not csv.exists():
        return {"skipped": f"{csv} not found"}
    query = QuerySpec(queries=frozenset({"fall"}))
    walls = {"both": 0.0, "neither": 0.0}
    moved, largest, undone = 0, 0.0, 0
    for i, scene in enumerate(scenes_from_tower_csv(csv)[:count]):
        answers = {}
        for n in (["both", "neither"] if i % 2 == 0 else ["neither", "both"]):
            start = time.perf_counter()
            answers[n] = predict(scene,
                                 Request(model=ModelConfig(sigma_m=DEFAULT_SIGMA_M, samples=48), settings=settings(n),
                                         query=query, seed=3, check=None, budget_s=None),
                                 Context(map_fn=pool.map))
            walls[n] += time.perf_counter() - start
        d = abs(answers["both"].fall_fraction - answers["neither"].fall_fraction)
        moved += d > 1e-12
        largest = max(largest, d)
        undone += answers["both"].collapse_undone_rollouts
    return {"towers": count, "time_ratio": walls["both"] / walls["neither"], "answers_moved": moved,
            "largest_move": largest, "rollouts_undone": undone, "rollouts": count * 48}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--per-family", type=int, default=6)
    parser.add_argument("--towers", type=int, default=60)
    parser.add_argument("--columns", default=COLUMNS, help="cubes:left-out pairs, comma-separated")
    parser.add_argument("--families", default=FAMILIES)
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/collapse_trial"))
    args = parser.parse_args()
    names = list(CONFIGURATIONS)
    with WorkerPool(2) as pool:
        pool.warm()
        report = {"date": time.strftime("%Y-%m-%d"), "columns": columns(pool, names, args.columns),
                  "zoo": zoo(pool, names, args.families, args.per_family, args.samples),
                  "towers": towers(pool, args.towers)}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "collapse_trial.json").write_text(json.dumps(report, indent=1) + "\n")
    lines = [f"# Collapse steps on trial ({report['date']}, 2 workers, `default` unchecked)", "",
             "`.venv/bin/python benchmarks/collapse_trial.py`; every configuration on the same seeds.", "",
             "Columns of 10 cm cubes with one left out (k = 8, sigma 5 mm): the largest P(falls) among the cubes "
             "below the gap (`paper` leaves them standing):", "",
             "| scene | paper | " + " | ".join(names) + " |", "|---" * (len(names) + 2) + "|"]
    lines += [f"| {r['scene']} | {r['paper']:.3f} | " + " | ".join(f"{r[n]:.3f}" for n in names) + " |"
              for r in report["columns"]]
    lines += ["", f"Zoo ({args.per_family} scenes per family, k = {args.samples}, default queries): mean / worst "
              "|dP(object falls)| against `paper`, speed-up over it, rollouts whose collapse steps were undone:", "",
              "| family | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    lines += [f"| {r['family']} | " + " | ".join(f"{r[n]['mean']:.3f} / {r[n]['worst']:.3f}, {r[n]['speedup']:.1f}x, "
                                                   f"{r[n]['undone']}" for n in names) + " |" for r in report["zoo"]]
    t = report["towers"]
    lines += ["", "Authors' towers (k = 48, fall): " + (t["skipped"] if "skipped" in t else
              f"{t['towers']} towers, `both` / `neither` time {t['time_ratio']:.3f}, {t['answers_moved']} fall "
              f"fractions moved (largest {t['largest_move']:.4f}), {t['rollouts_undone']} of {t['rollouts']} "
              "rollouts undone")]
    (out / "collapse_trial.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
