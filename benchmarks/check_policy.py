"""What the self-check costs and catches, policy by policy, replayed offline on the same samples.

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python benchmarks/check_policy.py --towers 12 --zoo 2 --samples 48

Every sample of every scene is simulated once at the fast settings (`default`, unchecked) and once at
the reference (`paper`'s physics, ending at rest by the strict reading), same seeds, 2 workers; then
``self_check.checking`` is replayed for each policy with a ``run`` that hands back the stored
reference outcomes, so each policy's verdicts, reference samples and answers are exactly what
``predict`` would have produced, at no new simulation. Per policy and scene set: reference samples
per prediction, the estimated speed-up against `paper` (fast time + reference samples x their
measured mean time, perfect balance over the workers), escalations, and the checked answer's
mean / worst |dP(object falls)| (and |dP(object tips)| where a zoo family asks it, as zoo.py does:
household) against the full reference answer. Authors' towers need ``../shared``; without it
generated towers are used. ``--families`` replays some zoo families only.

With ``--draws N --draw-samples k`` each policy is replayed on N random draws of k of a scene's
samples, each a prediction of its own: simulate more samples than a prediction uses (``--zoo-samples
64``) and the replay says how often a policy catches a bias, where one draw says only whether it did
that once. A draw *needs* escalating where its unchecked answer is ``NEEDS_ESCALATION_DP`` or more
from the reference's on the same samples; *missed* counts those the policy did not escalate.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, load_scenes, parse_queries, preset  # noqa: E402
from ipe_ros.engine.config import DEFAULT_QUERIES  # noqa: E402
from ipe_ros.engine.checking.fidelity import (DEFAULT_CHECK, SelfCheck, coverage_ahead, look_ahead_split,  # noqa: E402
                                     reference_settings, verification_count)
from ipe_ros.engine.scene.generators import generate_towers  # noqa: E402
from ipe_ros.engine.sampling.montecarlo import MonteCarlo, drive  # noqa: E402
from ipe_ros.engine.sampling.rollout import lost, run_sample  # noqa: E402
from ipe_ros.engine.predict import make_tasks  # noqa: E402
from ipe_ros.engine.checking.self_check import checking  # noqa: E402
from ipe_ros.engine.scene.zoo import FAMILIES, family_of, family_queries, scene_zoo, zoo_sigma_m  # noqa: E402

POLICIES = {
    "current": DEFAULT_CHECK,
    "no coverage": dataclasses.replace(DEFAULT_CHECK, cover_samples=0),
    "cover 2": dataclasses.replace(DEFAULT_CHECK, cover_samples=2),
    "confirm 1 per round": dataclasses.replace(DEFAULT_CHECK, confirm_samples=1),
    "one confirmation round": dataclasses.replace(DEFAULT_CHECK, confirm_rounds=1),
    "no confirmation": dataclasses.replace(DEFAULT_CHECK, confirm_rounds=0),
    "verify 2": dataclasses.replace(DEFAULT_CHECK, verify_samples=2),
    "bias tolerance 0.05": dataclasses.replace(DEFAULT_CHECK, bias_tolerance=0.05),
    "bias tolerance 0.15": dataclasses.replace(DEFAULT_CHECK, bias_tolerance=0.15),
    # the rule before issue 52's stratified estimate of the bias: counts of same-way differences
    "counts": dataclasses.replace(DEFAULT_CHECK, bias_tolerance=None, escalate_min_samples=3, confirm_rounds=2),
    "unchecked": SelfCheck(enabled=False),
    # how the bias rule counts differences, and what an undecided bias does once the rounds are spent
    # (issue 75's replay: strike 2027/4 was verified 0.375 off); "current" counts on the side and escalates
    "net, verify (before)": dataclasses.replace(DEFAULT_CHECK, same_way="net", when_undecided="verify"),
    "net, escalate": dataclasses.replace(DEFAULT_CHECK, same_way="net", when_undecided="escalate"),
    "side, verify": dataclasses.replace(DEFAULT_CHECK, when_undecided="verify"),
    "side, confirm": dataclasses.replace(DEFAULT_CHECK, when_undecided="confirm"),
}


def _policy_names(text: str) -> list[str]:
    """``--policies``: names split at commas, a name's own comma (\"net, verify (before)\") kept."""
    names, pending = [], ""
    for piece in text.split(","):
        pending = f"{pending},{piece}" if pending else piece
        if pending.strip() in POLICIES:
            names.append(pending.strip())
            pending = ""
    if pending or not names:
        raise argparse.ArgumentTypeError(f"unknown policy {pending.strip()!r}; choose from {', '.join(map(repr, POLICIES))}")
    return names


def _family_names(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(","))
    unknown = [n for n in names if n not in FAMILIES]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown family {unknown[0]!r}; choose from {', '.join(FAMILIES)}")
    return names


def _scenes(args) -> list[tuple[str, object, ModelConfig]]:
    path = Path(os.environ.get("IPE_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared/data/battaglia2013"))
    towers_csv = path / "stability_all_towers.csv"
    towers = load_scenes(towers_csv)[::5][:args.towers] if towers_csv.exists() else generate_towers(2013, args.towers)
    out = [("towers", t, ModelConfig(sigma_m=0.04, samples=args.samples)) for t in towers]
    for family in args.families or FAMILIES:
        for scene in scene_zoo(args.zoo_seed, args.zoo, (family,)):
            out.append((f"zoo/{family}", scene, ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.zoo_samples)))
    return out


def object_p(outcomes) -> np.ndarray:
    """Per object: the share of the good samples' rollouts in which it fell, and in which it tipped
    over where that was asked (the zoo's household: ``zoo.EXTRA_QUERIES``)."""
    ok = [o for o in outcomes if o.ok]

    def flags(r):
        tipped = r.get("tipped")
        return np.asarray(r.fallen, float) if tipped is None else np.concatenate([r.fallen, np.asarray(tipped, float)])

    return np.mean([np.mean([flags(r) for r in o.rollouts], axis=0) for o in ok], axis=0)


def main() -> int:
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST", "set ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=12)
    parser.add_argument("--zoo", type=int, default=2, help="scenes per zoo family")
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--zoo-seed", type=int, default=2026, help="the zoo's scenes (2027: the held-out seed)")
    parser.add_argument("--zoo-samples", type=int, default=16, help="samples per zoo scene (the zoo's own k: 16)")
    parser.add_argument("--draws", type=int, default=1,
                        help="replay each policy on this many random draws of --draw-samples of a scene's samples "
                             "(1: the samples as simulated): how often the check catches a bias, not on one draw")
    parser.add_argument("--draw-samples", type=int, default=None, help="samples per draw (default: all)")
    parser.add_argument("--query", type=parse_queries, default=DEFAULT_QUERIES,
                        help="the queries asked (default: the node's and the CLI's, fall,any_fall,direction,far), "
                             "and what a zoo family asks besides, as zoo.py asks it (household: tipped)")
    parser.add_argument("--families", type=_family_names, default=None,
                        help="only these zoo families (comma-separated; default: all)")
    parser.add_argument("--end-substeps", type=int, default=None,
                        help="the fast physics with collapse.end_substeps set to this (default: `default`'s own)")
    parser.add_argument("--cache", type=Path, default=None,
                        help="a pickle of the simulated samples: read when it exists (no simulation), else written, "
                             "so that policies can be replayed again on the same samples")
    parser.add_argument("--reference-from", type=Path, default=None,
                        help="take the reference samples from this cache (same scenes, seeds and queries) instead "
                             "of simulating them again")
    parser.add_argument("--policies", type=_policy_names, default=None,
                        help="replay only these policies (comma-separated names, some with a comma of their own, "
                             "e.g. 'current,net, verify (before)'; default: all)")
    parser.add_argument("--out", default="benchmarks/results/check_policy")
    args = parser.parse_args()
    fast_settings, reference = preset("default"), reference_settings()
    if args.end_substeps is not None:
        fast_settings = fast_settings.changed(f"default-end{args.end_substeps}",
                                              collapse={"end_substeps": args.end_substeps})
    query = QuerySpec(queries=args.query)
    if args.cache is not None and args.cache.exists():
        stored = pickle.loads(args.cache.read_bytes())
    else:
        stored = _simulate(args, fast_settings, reference, query)
        if args.cache is not None:
            args.cache.write_bytes(pickle.dumps(stored))
    rows, scenes = _replay(stored, reference, args.draws, args.draw_samples,
                           None if args.policies is None else {n: POLICIES[n] for n in args.policies})
    tasks = stored[0][2]
    title = (f"# Self-check policies replayed on the same samples ({time.strftime('%Y-%m-%d')}): fast "
             f"`{tasks[0].settings.name}` (collapse.end_substeps {tasks[0].settings.collapse.end_substeps}), "
             f"queries {', '.join(sorted(tasks[0].query.queries))}, against `{reference.name}`\n\n")
    _write(rows, Path(args.out), title)
    (Path(args.out) / "check_policy_scenes.json").write_text(json.dumps(_per_scene(scenes), indent=1))
    return 0


def _simulate(args, fast_settings, reference, query) -> list:
    """Every sample of every scene at the fast settings and at the reference, same seeds."""
    stored = []
    earlier = pickle.loads(args.reference_from.read_bytes()) if args.reference_from else None
    with WorkerPool(2) as pool:
        run_tasks = MonteCarlo(run_sample, lost, pool.map).run
        scenes = _scenes(args)
        group, scene, model = scenes[0]  # workers started and imports done before any timing
        run_tasks(make_tasks(scene, dataclasses.replace(model, samples=2), fast_settings, query, seed=0))
        for n, (group, scene, model) in enumerate(scenes):
            asked = query if group == "towers" else QuerySpec(queries=query.queries | family_queries(family_of(scene)))
            tasks = make_tasks(scene, model, fast_settings, asked, seed=11)
            start = time.perf_counter()
            fast = run_tasks(tasks)
            fast_s = time.perf_counter() - start
            if earlier is not None:
                if earlier[n][1] != scene.name or len(earlier[n][4]) != len(tasks):
                    raise SystemExit(f"--reference-from holds other scenes ({earlier[n][1]} for {scene.name})")
                ref, ref_s = earlier[n][4], earlier[n][6]
            else:
                start = time.perf_counter()
                ref = run_tasks([t.at(reference) for t in tasks])
                ref_s = time.perf_counter() - start
            stored.append((group, scene.name, tasks, fast, ref, fast_s, ref_s))
            print(f"{group} {scene.name}: fast {fast_s:.2f} s, reference {ref_s:.2f} s", flush=True)
    return stored


#: a draw whose unchecked answer is this far from the reference's on the same samples (worst object
#: or "anything falls") needs escalating: beyond the zoo's worst-scene bars of every family
NEEDS_ESCALATION_DP = 0.25


def _draws(n_samples: int, draws: int, size: int | None) -> list[np.ndarray]:
    """The samples each replay uses: all of them, or ``draws`` random draws of ``size`` (fixed seed)."""
    if draws <= 1 and (size is None or size >= n_samples):
        return [np.arange(n_samples)]
    rng = np.random.default_rng(5)
    return [np.sort(rng.choice(n_samples, min(size or n_samples, n_samples), replace=False)) for _ in range(draws)]


def _worst_dp(answer, ref) -> float:
    p = object_p(answer) - object_p(ref)
    fell = [np.mean([r.fallen.any() for r in o.rollouts]) for o in answer if o.ok]
    ref_fell = [np.mean([r.fallen.any() for r in o.rollouts]) for o in ref if o.ok]
    return float(max(np.max(np.abs(p)), abs(np.mean(fell) - np.mean(ref_fell))))


def _replay(stored: list, reference, draws: int = 1, draw_samples: int | None = None,
            policies: dict | None = None) -> list[dict]:
    """Each policy's self-check on the stored samples (on each draw of them), the reference outcomes
    handed back as reruns."""
    rows, scenes = [], []
    for name, check in (POLICIES if policies is None else policies).items():
        per_group: dict[str, dict] = {}
        for group, scene_name, all_tasks, all_fast, all_ref, fast_s, ref_s in stored:
            for picked in _draws(len(all_tasks), draws, draw_samples):
                # a draw is a prediction of its own: its samples renumbered 0..k-1, as predict numbers them
                tasks = [dataclasses.replace(all_tasks[i], index=j) for j, i in enumerate(picked)]
                fast, ref = [all_fast[i] for i in picked], [all_ref[i] for i in picked]
                used: list[int] = []

                def run(batch, ref=ref, used=used):
                    used.extend(t.index for t in batch)
                    return [ref[t.index] for t in batch]

                # as predict runs it: the verification, and the coverage sample picked ahead of the last samples
                verified = {i: ref[i] for i in range(verification_count(check, len(tasks)))}
                split = look_ahead_split(check, len(tasks))
                if split < len(tasks):
                    verified.update({i: ref[i] for i in coverage_ahead(fast[:split], verified, check, len(tasks))})
                used.extend(verified)
                answer, report = drive(checking(tasks, list(fast), verified, check, reference, "default"), run)
                dp = np.abs(object_p(answer) - object_p(ref))
                needed = _worst_dp(fast, ref) >= NEEDS_ESCALATION_DP
                g = per_group.setdefault(group, {"scenes": 0, "reference_samples": 0, "fast_s": 0.0, "ref_s": 0.0,
                                                 "paper_s": 0.0, "escalated": 0, "dp": [], "worst": 0.0,
                                                 "needed": 0, "missed": 0, "because": {}})
                per_sample_fast, per_sample_ref = fast_s / len(all_tasks), ref_s / len(all_tasks)
                g["scenes"] += 1
                g["reference_samples"] += len(set(used))
                g["fast_s"] += per_sample_fast * len(tasks)
                g["ref_s"] += per_sample_ref * len(set(used))
                g["paper_s"] += per_sample_ref * len(tasks)  # the reference at every sample: what `paper` costs, about
                g["escalated"] += report.verdict == "escalated"
                g["needed"] += needed
                g["missed"] += needed and report.verdict != "escalated"
                if report.verdict == "escalated":  # why, and whether the draw needed it
                    for reason in report.escalated_because:
                        tally = g["because"].setdefault(reason, [0, 0])
                        tally[0] += 1
                        tally[1] += bool(needed)
                g["dp"].append(float(dp.mean()))
                g["worst"] = max(g["worst"], float(dp.max()))
                scenes.append({"policy": name, "scene": scene_name, "verdict": report.verdict, "reference_samples": len(set(used)),
                               "worst_abs_dp": float(dp.max()), "needed": bool(needed)})
        for group, g in per_group.items():
            rows.append({"policy": name, "group": group, "scenes": g["scenes"],
                         "reference_samples_per_prediction": g["reference_samples"] / g["scenes"],
                         "speedup_vs_reference": g["paper_s"] / (g["fast_s"] + g["ref_s"]),
                         "escalated": g["escalated"], "needed": g["needed"], "missed": g["missed"],
                         "escalated_because": {r: {"escalated": n, "needed": k} for r, (n, k) in g["because"].items()},
                         "mean_abs_dp": float(np.mean(g["dp"])), "worst_abs_dp": g["worst"]})
    return rows, scenes


def _per_scene(scenes: list[dict]) -> list[dict]:
    """Per policy and scene: its draws' verdicts, reruns and worst |dP| (one row per draw is too many
    to keep for 30 draws of 66 scenes under 9 policies)."""
    out: dict[tuple[str, str], dict] = {}
    for s in scenes:
        row = out.setdefault((s["policy"], s["scene"]), {"policy": s["policy"], "scene": s["scene"], "draws": 0,
                                                         "verdicts": {}, "reference_samples": 0, "needed": 0,
                                                         "missed": 0, "worst_abs_dp": 0.0})
        row["draws"] += 1
        row["verdicts"][s["verdict"]] = row["verdicts"].get(s["verdict"], 0) + 1
        row["reference_samples"] += s["reference_samples"]
        row["needed"] += s["needed"]
        row["missed"] += s["needed"] and s["verdict"] != "escalated"
        row["worst_abs_dp"] = max(row["worst_abs_dp"], s["worst_abs_dp"])
    return list(out.values())


def _write(rows: list[dict], out: Path, title: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "check_policy.json").write_text(json.dumps(rows, indent=1))
    lines = ["| policy | set | predictions | reference samples / prediction | speed-up vs reference | escalated | "
             "needed escalating | missed | mean \\|dP\\| | worst \\|dP\\| | escalated because (of them needed) |",
             "|---" * 11 + "|"]
    for r in sorted(rows, key=lambda r: (r["group"] != "towers", r["group"])):
        because = ", ".join(f"{reason} {t['escalated']} ({t['needed']})"
                            for reason, t in sorted(r.get("escalated_because", {}).items())) or "-"
        lines.append(f"| {r['policy']} | {r['group']} | {r['scenes']} | {r['reference_samples_per_prediction']:.2f} | "
                     f"{r['speedup_vs_reference']:.1f}x | {r['escalated']} | {r['needed']} | {r['missed']} | "
                     f"{r['mean_abs_dp']:.3f} | "
                     f"{r['worst_abs_dp']:.3f} | {because} |")
    (out / "check_policy.md").write_text(title + "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
