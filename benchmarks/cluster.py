"""Rollouts per second through Dask against the local worker pool, on this machine, same worker count.

    .venv/bin/python benchmarks/cluster.py [--towers 10] [--samples 48] [--out benchmarks/results/cluster]

A LocalCluster on loopback (processes, one thread each) stands in for a cluster: what it measures is
the scheduler's overhead per task and how batching hides it, and how rollouts/s scale from 1 to 2
workers, from which the time of the paper's full-size analyses on N cores is projected.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from datetime import date
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from ipe_ros.analysis.paper_data import shared_data_dir  # noqa: E402
from ipe_ros.analysis.runs import load_tower_stimuli  # noqa: E402
from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, predict, predict_many, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.compute.cluster import DaskMap, local_cluster  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
QUERY = QuerySpec(queries=frozenset({"fall"}))
#: Rollouts of the paper's full-size analyses that issue 20 asks for: fall's 11 x 11 sigma x phi grid
#: at k = 48 on 60 towers, and bump's 60 tables and the 48 walled ones' wall-less twins x 16 x 16
#: bumps at k = 12 (each bump one rollout; they cost more than the towers' rollouts measured here).
FULL_SIZE_ROLLOUTS = {"fall grid (121 cells x 60 towers x 48)": 121 * 60 * 48,
                      "bump ((60 + 48) tables x 256 bumps x 12)": 108 * 256 * 12}


def rollouts_per_s(scenes, k: int, map_fn, together: bool = False) -> float:
    """Rollouts/s of k-sample predictions: one map per prediction (what the node does), or every
    prediction's samples in one map (``predict_many``, what ``ipe experiment`` does)."""
    model = ModelConfig(sigma_m=0.04, samples=k)
    start = time.perf_counter()
    if together:
        predict_many([(scene, model, i) for i, scene in enumerate(scenes)], preset("default"), QUERY, map_fn)
    else:
        for i, scene in enumerate(scenes):
            predict(scene, Request(model=model, settings=preset("default"), query=QUERY, seed=i, budget_s=None),
                    Context(map_fn=map_fn))
    return len(scenes) * k / (time.perf_counter() - start)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=10)
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--batches", default="1,4,12")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "cluster"))
    args = parser.parse_args()
    scenes = load_tower_stimuli("willitfall.csv", shared_data_dir(), args.towers).scenes
    rows = []
    for workers in (1, 2):
        with WorkerPool(workers) as pool:
            rollouts_per_s(scenes[:1], args.samples, pool.map)  # warm the workers
            for together in (False, True):
                rows.append({"backend": "local pool", "workers": workers, "batch": None, "together": together,
                             "rollouts_per_s": rollouts_per_s(scenes, args.samples, pool.map, together)})
        with local_cluster(workers) as client:
            for batch in (int(b) for b in args.batches.split(",")):
                dask_map = DaskMap(client, batch_size=batch)
                rollouts_per_s(scenes[:1], args.samples, dask_map.map)
                for together in (False, True):
                    rows.append({"backend": "dask", "workers": workers, "batch": batch, "together": together,
                                 "rollouts_per_s": rollouts_per_s(scenes, args.samples, dask_map.map, together)})
    # the full-size analyses run as ipe experiment does: many predictions per map
    best = {w: max(r["rollouts_per_s"] for r in rows if r["backend"] == "dask" and r["workers"] == w and r["together"])
            for w in (1, 2)}
    scaling = best[2] / best[1]
    per_core = best[1]
    projection = {name: {"rollouts": n, "hours_here": n / best[2] / 3600,
                         "hours_on_64_cores": n / (per_core * 64 * min(1.0, scaling / 2)) / 3600}
                  for name, n in FULL_SIZE_ROLLOUTS.items()}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"date": date.today().isoformat(), "towers": len(scenes), "samples": args.samples, "rows": rows,
              "scaling_1_to_2_workers": scaling, "projection": projection}
    (out / "cluster.json").write_text(json.dumps(result, indent=1))
    lines = [f"# Dask against the local pool ({result['date']})", "",
             f"{len(scenes)} towers, k = {args.samples}, `default`, the fall query, this 2-core machine; a LocalCluster "
             "on loopback (processes, one thread each).", "",
             "*per prediction*: one map per k-sample prediction (the node); *together*: all the towers' samples in "
             "one map (`predict_many`, as `ipe experiment` runs).", "",
             "| backend | workers | Dask batch | rollouts/s, per prediction | rollouts/s, together |", "|---|---|---|---|---|"]
    for first in range(0, len(rows), 2):
        one, together = rows[first], rows[first + 1]
        lines.append(f"| {one['backend']} | {one['workers']} | {one['batch'] or '-'} | {one['rollouts_per_s']:.1f} | "
                     f"{together['rollouts_per_s']:.1f} |")
    lines += ["", f"Scaling from 1 to 2 Dask workers: {scaling:.2f}x. Projected wall time of the paper's full-size "
              "analyses (rollouts / best Dask rate with many predictions per map; on 64 cores, the 1-worker rate x 64 x the measured parallel "
              "efficiency):", "", "| analysis | rollouts | hours here | hours on 64 cores |", "|---|---|---|---|"]
    lines += [f"| {name} | {p['rollouts']} | {p['hours_here']:.1f} | {p['hours_on_64_cores']:.2f} |"
              for name, p in projection.items()]
    (out / "cluster.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
