"""What event questions cost: the contact watch against the same rollouts without it, and a
contact question asked alone (its rollouts end once every pair has touched) against asking where
things end up.

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python benchmarks/queries.py --per-family 4 --samples 8

Per zoo family with an event to ask about (a projectile reaching a stack, a domino chain reaching its
last slab, a mover reaching the block at a ramp's foot, a dropped object reaching the one below), the
same noisy scenes and seeds, 2 workers, one run (the pool warmed first, the three runs of a scene
in turns), the self-check off (the physics alone):
- ``final_pose`` vs ``final_pose + contact``: what watching the pair after every step costs on the
  same rollouts (both run to rest);
- ``contact`` alone vs ``final_pose``: what ending at the event saves;
- whether ``contact`` alone and ``contact + final_pose`` answer the contact question identically.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, predict, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.scene.zoo import scene_zoo, zoo_sigma_m  # noqa: E402

#: the pair asked of each family's scenes
PAIRS = {
    "launch": lambda s: ("projectile", "block0"),
    "dominoes": lambda s: (s.dynamic_objects[-2].name, s.dynamic_objects[-1].name),
    "ramp": lambda s: ("mover", "block0"),
    "drop": lambda s: ("dropped", next(b.name for b in s.objects if b.name != "dropped")),  # a stack or a container
}


def main() -> int:
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST", "set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--per-family", type=int, default=4)
    parser.add_argument("--samples", type=int, default=8)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", default="benchmarks/results/queries")
    args = parser.parse_args()
    settings = preset("default")
    rows = []
    with WorkerPool(2) as pool:
        warm = scene_zoo(args.seed, 1, ("drop",))[0]  # workers started and imports done before any timing
        predict(warm,
                Request(model=ModelConfig(sigma_m=zoo_sigma_m(warm), samples=4), settings=settings, query=QuerySpec(),
                        check=None, budget_s=None),
                Context(map_fn=pool.map))
        for family, pair_of in PAIRS.items():
            times = {"final_pose": 0.0, "final_pose+contact": 0.0, "contact": 0.0}
            same = simulated_alone = simulated_rest = 0
            asked = 0
            for scene in scene_zoo(args.seed, args.per_family, (family,)):
                pair = pair_of(scene)
                model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.samples)
                answers = {}
                runs = [("final_pose", {"final_pose"}), ("final_pose+contact", {"final_pose", "contact"}),
                        ("contact", {"contact"})]
                for name, queries in runs[asked % 3:] + runs[:asked % 3]:  # the order turns scene by scene
                    spec = QuerySpec(queries=frozenset(queries), contact_pairs=(pair,) if "contact" in queries else ())
                    start = time.perf_counter()
                    answers[name] = predict(scene,
                                            Request(model=model, settings=settings, query=spec, seed=1, check=None,
                                                    budget_s=None),
                                            Context(map_fn=pool.map))
                    times[name] += time.perf_counter() - start
                same += answers["contact"].contact_probability == answers["final_pose+contact"].contact_probability
                simulated_alone += sum(r.simulated_s for o in answers["contact"].outcomes for r in o.rollouts)
                simulated_rest += sum(r.simulated_s for o in answers["final_pose"].outcomes for r in o.rollouts)
                asked += 1
            rows.append({"family": family, "scenes": asked, **{f"{k}_s": v for k, v in times.items()},
                         "watch_overhead": times["final_pose+contact"] / times["final_pose"] - 1,
                         "alone_vs_rest": times["contact"] / times["final_pose"],
                         "simulated_alone_vs_rest": simulated_alone / simulated_rest,
                         "same_contact_answer": f"{same}/{asked}"})
            print(json.dumps(rows[-1]), flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "queries.json").write_text(json.dumps(rows, indent=1))
    lines = ["| family | scenes | final_pose s | + contact s | watch overhead | contact alone s | alone / to rest "
             "(wall) | alone / to rest (simulated) | same contact answer |", "|---" * 9 + "|"]
    for r in rows:
        lines.append(f"| {r['family']} | {r['scenes']} | {r['final_pose_s']:.2f} | {r['final_pose+contact_s']:.2f} | "
                     f"{r['watch_overhead']:+.1%} | {r['contact_s']:.2f} | {r['alone_vs_rest']:.2f} | "
                     f"{r['simulated_alone_vs_rest']:.2f} | {r['same_contact_answer']} |")
    (out / "queries.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
