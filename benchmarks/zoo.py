"""What accuracy costs in time, per family of the scene zoo, with the chaos yardstick beside it.

    .venv/bin/python benchmarks/zoo.py [--per-family 6] [--samples 16] [--seed 2026] [--workers 2]
                                       [--families launch,dominoes] [--only default,default-unchecked]
                                       [--sample-seed 0]
                                       [--trial islands=true] [--out benchmarks/results/zoo]

Every zoo family (ipe_ros.engine.scene.zoo) under `paper` (the converged reference), `paper-half-step`
(the yardstick: `paper` at 0.5 ms on the same noisy scenes; how much a family's outcomes depend on
the integrator at all) and the candidates (by default `default`, which checks itself, and
`default-unchecked`, the same physics without the checks). Each scene's sigma is 5% of its smallest
dynamic body; every configuration gets the same seeds, hence the same noisy scenes. Queries: the
node's default (fall, any_fall, direction, far), so rollouts run as a user's do, and what a family
asks besides (``zoo.EXTRA_QUERIES``: `household` asks whether its objects tip over, and its tipping
counts in the bars as falling does).

Per family and configuration: seconds per prediction and speed-up over `paper` (configurations take
turns scene by scene, so the machine's drift hits each alike), mean and max |dP(object falls)| (and
|dP(object tips)| where asked) and
|dP(anything falls)| against `paper`, per-sample agreement on "did anything fall?", the worst end
penetration and the rollouts ending > 5% inside another, the worst energy gain (% of the scene's
scale), the share of samples the self-check refined or escalated, the share of rollouts whose
collapse steps made energy and were undone (config.CollapseSettings), and each answer's fidelity.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import zlib
from collections import Counter
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from accuracy_vs_time import _anything_fell  # noqa: E402 - the towers' "did anything fall?"
from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, WorkerPool, predict  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.config import DEFAULT_QUERIES  # noqa: E402
from ipe_ros.engine.simulation.health import energy_scale_j  # noqa: E402
from ipe_ros.engine.scene.zoo import EXTRA_QUERIES, FAMILIES, family_of, family_queries, scene_zoo, zoo_sigma_m  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
QUERY = QuerySpec(queries=DEFAULT_QUERIES)
PAPER = PRESETS["paper"]


def object_differences(p, r) -> list[float]:
    """|dP| per object between two predictions: falling, and tipping where both asked it."""
    diffs = [abs(p.object_fall_probability[n] - r.object_fall_probability[n]) for n in r.object_fall_probability]
    if p.tipped_object_probability and r.tipped_object_probability:
        diffs += [abs(p.tipped_object_probability[n] - r.tipped_object_probability[n])
                  for n in r.tipped_object_probability]
    return diffs


#: configurations that run as `default` would with a change on trial (``--trial``)
TRIAL = "trial"


def sample_seed(scene, offset: int = 0) -> int:
    """A scene's prediction seed, from its name (family, scene seed, index) alone: a run of some
    families draws the same samples of a scene as a run of all of them."""
    return zlib.crc32(f"{scene.name}/{offset}".encode())


def configurations(trial: dict | None = None) -> dict[str, tuple]:
    """name -> (settings, self_check). `paper` first: it is the reference. ``trial``: ``changed()``'s
    arguments for `default` with a change on trial, run as "trial" and "trial-unchecked" (under the
    preset's name: the self-check treats it as the preset it would become)."""
    from ipe_ros.engine.checking.fidelity import SelfCheck

    default = PRESETS["default"]
    out = {
        "paper": (PAPER, None),
        "paper-half-step": (PAPER.changed("paper-half-step", time_step_s=PAPER.time_step_s / 2), None),
        "default": (default, SelfCheck()),
        "default-unchecked": (default, None),
    }
    if trial:
        changed = default.changed(default.name, **trial)
        out |= {TRIAL: (changed, SelfCheck()), f"{TRIAL}-unchecked": (changed, None)}
    return out


def compare_family(rows: list[dict], reference: list[dict]) -> dict:
    """One configuration's predictions of one family against the reference's."""
    d_obj, d_any, agree, pen, over5, gain = [], [], [], [], 0, []
    worst_scene = 0.0
    for row, ref in zip(rows, reference):
        p, r = row["prediction"], ref["prediction"]
        if not (p.samples and r.samples):
            continue
        diffs = object_differences(p, r)
        d_obj.append(float(np.mean(diffs)))
        worst_scene = max(worst_scene, max(diffs), abs(p.any_fall_probability - r.any_fall_probability))
        d_any.append(abs(p.any_fall_probability - r.any_fall_probability))
        for o, ro in zip(p.outcomes, r.outcomes):
            if o.ok and ro.ok:
                agree.append(_anything_fell(o.rollouts[0]) == _anything_fell(ro.rollouts[0]))
        ends = [rr.penetration_fraction for o in p.outcomes if o.ok for rr in o.rollouts]
        pen.append(max(ends))
        over5 += sum(e > 0.05 for e in ends)
        gain.append(100 * p.max_energy_gain_j / row["energy_scale_j"])
    wall = sum(r["wall_s"] for r in rows)
    samples = sum(r["prediction"].samples for r in rows)
    refined = sum(r["prediction"].refined_samples for r in rows)
    rollouts = sum(len(o.rollouts) for r in rows for o in r["prediction"].outcomes if o.ok)
    undone = sum(r["prediction"].collapse_undone_rollouts for r in rows)
    return {
        "scenes": len(rows), "wall_s_per_prediction": wall / len(rows),
        "speedup_vs_paper": sum(r["wall_s"] for r in reference) / wall,
        "mean_abs_dp_object": float(np.mean(d_obj)), "max_abs_dp_scene": worst_scene,
        "mean_abs_dp_any": float(np.mean(d_any)),
        "per_sample_agreement": float(np.mean(agree)) if agree else None,
        "max_end_penetration_fraction": float(max(pen)), "rollouts_over_5_percent": int(over5),
        "max_energy_gain_percent": float(max(gain)),
        "refined_share": refined / max(1, samples),
        "collapse_undone_share": undone / max(1, rollouts),
        "fidelity": dict(Counter(str(r["prediction"].fidelity) for r in rows)),
        "failed_samples": int(sum(r["prediction"].failed_samples for r in rows)),
    }


def scene_rows(scenes: list, results: dict[str, list[dict]]) -> list[dict]:
    """Per scene and configuration: its fidelity, the worst |dP| of an object (or of "anything falls")
    against `paper`, and its seconds: which scenes a check escalated, and whether it had to."""
    rows = []
    for i, scene in enumerate(scenes):
        ref = results["paper"][i]["prediction"]
        row = {"scene": scene.name}
        for name, runs in results.items():
            p = runs[i]["prediction"]
            worst = max([*object_differences(p, ref), abs(p.any_fall_probability - ref.any_fall_probability)]) \
                if p.samples and ref.samples else None
            row[name] = {"fidelity": str(p.fidelity), "worst_abs_dp": worst, "wall_s": runs[i]["wall_s"],
                         **{key: (p.self_check or {}).get(key) for key in ("verified_samples", "disagreeing_samples")}}
        rows.append(row)
    return rows


def verdict(family_rows: dict[str, dict], name: str = "default") -> dict:
    """The issue's bar for one family: ``name``'s mean |dP| <= max(0.03, 1.5x the yardstick's), no
    scene off by more than the yardstick's worst + 0.1, no rollout ending > 5% inside another, no
    energy gain above 1% of the scale."""
    yard, ours = family_rows["paper-half-step"], family_rows[name]
    return {
        "mean_ok": ours["mean_abs_dp_object"] <= max(0.03, 1.5 * yard["mean_abs_dp_object"]),
        "worst_ok": ours["max_abs_dp_scene"] <= yard["max_abs_dp_scene"] + 0.1,
        "penetration_ok": ours["rollouts_over_5_percent"] == 0,
        "energy_ok": ours["max_energy_gain_percent"] <= 1.0,
    }


def markdown(report: dict) -> str:
    lines = [f"# The scene zoo: {report['per_family']} scenes per family (seed {report['seed']}), k = "
             f"{report['samples']}, queries {', '.join(sorted(QUERY.queries))} (and "
             + "; ".join(f"{f}: {', '.join(sorted(q))}" for f, q in EXTRA_QUERIES.items()) + ")", "",
             f"{report['machine']}; {report['date']}; sigma = 5% of each scene's smallest dynamic body; every "
             "configuration on the same noisy scenes (same seeds), taking turns scene by scene; "
             f"wall time {report['wall_s'] / 60:.0f} min.", "",
             "| family | configuration | s / prediction | speed-up | mean \\|ΔP(object)\\| | worst scene \\|ΔP\\| | "
             "mean \\|ΔP(any)\\| | per-sample agreement | worst end penetration | rollouts > 5% | worst energy gain | "
             "refined | collapse steps undone | fidelity |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for family, rows in report["families"].items():
        for name, row in rows.items():
            fid = ", ".join(f"{k} {v}" for k, v in sorted(row["fidelity"].items()) if k != "None") or "-"
            agree = "-" if row["per_sample_agreement"] is None else f"{row['per_sample_agreement']:.1%}"
            lines.append(f"| {family} | {name} | {row['wall_s_per_prediction']:.2f} | {row['speedup_vs_paper']:.1f}x | "
                         f"{row['mean_abs_dp_object']:.3f} | {row['max_abs_dp_scene']:.3f} | "
                         f"{row['mean_abs_dp_any']:.3f} | {agree} | {row['max_end_penetration_fraction']:.1%} | "
                         f"{row['rollouts_over_5_percent']} | {row['max_energy_gain_percent']:.2f}% | "
                         f"{row['refined_share']:.1%} | {row['collapse_undone_share']:.1%} | {fid} |")
    lines += ["", "Against the bar (mean \\|ΔP\\| <= max(0.03, 1.5x yardstick); worst scene <= yardstick's worst + "
              "0.1; no rollout ending > 5% inside another; energy gain <= 1% of the scale):", "",
              "| family | mean | worst scene | penetration | energy |", "|---|---|---|---|---|"]
    def row(label: str, v: dict) -> str:
        return f"| {label} | " + " | ".join("ok" if v[k] else "MISSED"
                                             for k in ("mean_ok", "worst_ok", "penetration_ok", "energy_ok")) + " |"

    trial = report.get("trial_verdicts", {})
    for family, v in report.get("verdicts", {}).items():
        lines.append(row(family, v))
        if family in trial:
            lines.append(row(f"{family} (trial: {report['trial']})", trial[family]))
    if "overall" in report:
        lines += ["", "Overall speed-up over `paper` (all scenes' time together): " +
                  ", ".join(f"`{k}` {v:.1f}x" for k, v in report["overall"].items())]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--per-family", type=int, default=6)
    parser.add_argument("--samples", type=int, default=16)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--sample-seed", type=int, default=0,
                        help="draws other noisy samples of the same scenes (the self-check's luck, seed by seed)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--only", default=None, help="configurations besides paper (comma-separated)")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "zoo"))
    parser.add_argument("--trial", action="append", default=[], metavar="NAME=VALUE",
                        help="also run `default` with this change (e.g. islands=true; repeatable), as \"trial\"")
    args = parser.parse_args(argv)
    from preset_trial import as_the_preset, parse_change

    configs = configurations(parse_change(args.trial) if args.trial else None)
    if args.only:
        wanted = ["paper"] + [n for n in args.only.split(",") if n != "paper"]
        unknown = [n for n in wanted if n not in configs]
        if unknown:
            sys.exit(f"--only: unknown configuration {unknown[0]!r}; choose from {', '.join(configs)}")
        configs = {n: configs[n] for n in wanted}
    scenes = scene_zoo(args.seed, args.per_family, tuple(args.families.split(",")))
    results: dict[str, list[dict]] = {name: [] for name in configs}
    start = time.perf_counter()
    with WorkerPool(args.workers) as pool:
        pool.warm()
        for scene in scenes:
            model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=args.samples)
            line = []
            for name, (settings, check) in configs.items():
                t0 = time.perf_counter()
                with as_the_preset(settings if name.startswith(TRIAL) else None):
                    prediction = predict(scene,
                                         Request(model=model, settings=settings,
                                                 query=QuerySpec(queries=family_queries(family_of(scene))),
                                                 seed=sample_seed(scene, args.sample_seed), check=check,
                                                 budget_s=None),
                                         Context(map_fn=pool.map))
                wall = time.perf_counter() - t0
                results[name].append({"family": family_of(scene), "prediction": prediction, "wall_s": wall,
                                      "energy_scale_j": energy_scale_j(scene)})
                line.append(f"{name} {wall:.2f}s any={prediction.any_fall_probability}")
            print(f"{scene.name}: " + " | ".join(line), flush=True)
    report = {"per_family": args.per_family, "seed": args.seed, "sample_seed": args.sample_seed,
              "samples": args.samples, "machine": f"{os.cpu_count()} CPUs, {args.workers} workers",
              "date": time.strftime("%Y-%m-%d"), "wall_s": time.perf_counter() - start, "families": {}, "verdicts": {},
              "trial": ", ".join(args.trial) or None, "scenes": scene_rows(scenes, results)}
    for family in dict.fromkeys(family_of(s) for s in scenes):
        ref = [r for r in results["paper"] if r["family"] == family]
        report["families"][family] = {name: compare_family([r for r in rows if r["family"] == family], ref)
                                      for name, rows in results.items()}
        if {"default", "paper-half-step"} <= set(configs):
            report["verdicts"][family] = verdict(report["families"][family])
        if {TRIAL, "paper-half-step"} <= set(configs):
            report.setdefault("trial_verdicts", {})[family] = verdict(report["families"][family], TRIAL)
    paper_wall = sum(r["wall_s"] for r in results["paper"])
    report["overall"] = {name: paper_wall / sum(r["wall_s"] for r in rows) for name, rows in results.items()}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "zoo.json").write_text(json.dumps(report, indent=1))
    (out / "zoo.md").write_text(markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
