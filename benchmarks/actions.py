"""What the robot questions cost (issue 17's targets), measured on this machine in one run.

    .venv/bin/python benchmarks/actions.py [--workers 2] [--out benchmarks/results/actions]

- the support graph of a 10-block paper tower at k = 16 per variant (target <= 2 s);
- "safe to remove?" for one object at k = 48 (target <= 0.8 s);
- best place on a 20 x 20 cm region, 16 candidates, k = 16 (target <= 3 s);
- cost of one removal question vs the number of unrelated towers in the scene (1-8): objects an
  action cannot reach are left out of its rollouts, so it should cost about one tower;
- cost of a support graph vs tower height (5-40 cubes) at k = 8.

Towers: the authors' stable 10-block towers from ../shared/data/battaglia2013/willitfall.csv (the
first one their ground truth keeps standing; generated paper-style towers without the data).
Each figure is the median of ``--repeats`` runs with a warm worker pool. DDS is not involved.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from ipe_ros.engine import Box, Floor, ModelConfig, Scene, WorkerPool, preset  # noqa: E402
from ipe_ros.engine import actions as A  # noqa: E402
from ipe_ros.engine.config import DEFAULT_SIGMA_M  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
I = (0.0, 0.0, 0.0, 1.0)


def stable_tower() -> Scene:
    from ipe_ros.analysis.paper_data import EXP1_DATASET, authors_outcomes, shared_data_dir
    from ipe_ros.engine.scene_io import scenes_from_tower_csv

    csv = shared_data_dir() / "willitfall.csv"
    if csv.exists():
        outcomes = authors_outcomes(EXP1_DATASET, shared_data_dir())
        for scene in scenes_from_tower_csv(csv):
            if outcomes.get(scene.name) is not None and outcomes[scene.name].stable:
                return scene
    from ipe_ros.engine.generators import generate_towers

    return generate_towers(2013, 1)[0]


def column(n: int, size: float = 0.1) -> Scene:
    boxes = tuple(Box(name=f"c{i}", extents_m=(size,) * 3, position_m=(0.0, 0.0, size * (i + 0.5)), orientation_xyzw=I,
                      friction=0.6, restitution=0.0, mass_kg=1.0) for i in range(n))
    return Scene(name=f"column_{n}", objects=boxes, support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


def shelf(tower: Scene, copies: int, spacing_m: float = 6.0) -> Scene:
    objects = []
    for c in range(copies):
        for b in tower.objects:
            x, y, z = b.position_m
            objects.append(dataclasses.replace(b, name=f"t{c}_{b.name}", position_m=(x + c * spacing_m, y, z)))
    return dataclasses.replace(tower, name=f"shelf_{copies}", objects=tuple(objects))


def timed(fn, repeats: int) -> float:
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - start)
    return statistics.median(walls)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default=str(REPO / "benchmarks/results/actions"))
    parser.add_argument("--heights", default="5,10,20,40")
    parser.add_argument("--shelves", default="1,2,4,8")
    args = parser.parse_args()
    settings = preset("default")
    tower = stable_tower()
    top = max(tower.dynamic_objects, key=lambda b: b.position_m[2]).name
    rows = []
    with WorkerPool(args.workers) as pool:
        pool.warm()
        kw = dict(map_fn=pool.map)

        def model(k):
            return ModelConfig(sigma_m=DEFAULT_SIGMA_M, samples=k)

        graph = A.support_graph(tower, model(16), settings, **kw)
        rows.append({"question": f"support graph, {tower.name} (10 blocks), k = 16 per variant", "target_s": 2.0,
                     "seconds": timed(lambda: A.support_graph(tower, model(16), settings, **kw), args.repeats),
                     "note": f"{len(graph.edges)} edges, safe now: {', '.join(n for n, _, _ in graph.safe) or 'none'}"})
        rows.append({"question": f"safe to remove the top block ({top}), k = 48", "target_s": 0.8,
                     "seconds": timed(lambda: A.remove(tower, [top], model(48), settings, **kw), args.repeats),
                     "note": "as is + one removal (simulated: the top presses on what holds it up)"})
        block = Box(name="new", extents_m=(0.2, 0.2, 0.2), position_m=(0.0, 0.0, 0.0), orientation_xyzw=I,
                    friction=0.6, restitution=0.0, mass_kg=1.0)
        centre = max(tower.dynamic_objects, key=lambda b: b.position_m[2]).position_m
        region = A.Region((centre[0] - 0.1, centre[0] + 0.1), (centre[1] - 0.1, centre[1] + 0.1))
        rows.append({"question": "best place on the tower's top, 20 x 20 cm, 16 candidates, k = 16", "target_s": 3.0,
                     "seconds": timed(lambda: A.best_place(tower, block, region, model(16), settings, candidates=16,
                                                           **kw), args.repeats), "note": ""})
        shelves = []
        for copies in map(int, args.shelves.split(",")):
            scene = shelf(tower, copies)
            shelves.append({"towers": copies, "seconds": timed(
                lambda: A.ask(scene, [A.Remove((f"t0_{tower.dynamic_objects[0].name}",))], model(16), settings, **kw),
                args.repeats)})
        heights = []
        for n in map(int, args.heights.split(",")):
            scene = column(n)
            heights.append({"blocks": n, "seconds": timed(
                lambda: A.support_graph(scene, ModelConfig(sigma_m=0.005, samples=8), settings, **kw), 1)})
    report = {"date": time.strftime("%Y-%m-%d"), "workers": args.workers, "tower": tower.name, "targets": rows,
              "unrelated_towers": shelves, "support_graph_vs_height": heights}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "actions.json").write_text(json.dumps(report, indent=1) + "\n")
    lines = [f"# Robot questions: cost ({report['date']}, {args.workers} workers, `default`)", "",
             "`.venv/bin/python benchmarks/actions.py`; medians of 3 runs with a warm pool.", "",
             "| question | s | target s | |", "|---|---|---|---|"]
    lines += [f"| {r['question']} | {r['seconds']:.2f} | {r['target_s']:g} | {r['note']} |" for r in rows]
    lines += ["", "One removal (k = 16) in a scene of N separate 10-block towers 6 m apart:", "",
              "| towers | s |", "|---|---|"] + [f"| {r['towers']} | {r['seconds']:.2f} |" for r in shelves]
    lines += ["", "Support graph of a column of N 10 cm cubes (k = 8 per variant, one run):", "",
              "| blocks | s |", "|---|---|"] + [f"| {r['blocks']} | {r['seconds']:.2f} |" for r in heights]
    (out / "actions.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
