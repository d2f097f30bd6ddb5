"""A change to `default` on trial: today's `default` against the same preset with the change, both
self-checked as the preset itself is (inside the validated envelope where the preset is), and
`paper`, interleaved tower by tower on the authors' towers, one run.

    .venv/bin/python benchmarks/preset_trial.py --set collapse.end_travel_fraction=none
                                               [--towers 60] [--samples 48] [--query fall,any_fall,direction,far]
                                               [--out benchmarks/results/preset_trial]

``--set GROUP.FIELD=VALUE`` (or ``FIELD=VALUE`` for a top-level field; ``none`` for None) names the
change; the trial runs under the name `default`, so that the self-check treats it as the preset it
would become (the validated envelope compares the settings with the preset's). Per configuration:
seconds per prediction, speed-up over `paper`, mean / max |ΔFF| and per-sample agreement against
`paper` (benchmarks/accuracy_vs_time.py's ``compare``), the samples refined (rerun at the reference
because they ended unhealthy: > 5% inside another, energy made, or failed) and the verdicts.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import accuracy_vs_time as A  # noqa: E402

from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, SimSettings, WorkerPool, predict  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.checking import envelope  # noqa: E402
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def parse_change(items: list[str]) -> dict:
    """``["collapse.end_travel_fraction=none", "horizon_s=1.5"]`` -> ``changed()``'s keyword arguments."""
    changes: dict = {}
    for item in items:
        name, _, text = item.partition("=")
        if not text:
            raise SystemExit(f"--set {item!r}: expected NAME=VALUE")
        value = None if text.lower() == "none" else json.loads(text)
        group, _, field = name.rpartition(".")
        if group:
            changes.setdefault(group, {})[field] = value
        else:
            changes[field] = value
    return changes


def trial(base: SimSettings, changes: dict) -> SimSettings:
    return base.changed(base.name, **changes)


@contextlib.contextmanager
def as_the_preset(settings: SimSettings | None):
    """``settings`` (a trial of `default`, under its name) as `default` while the block runs, so
    that the validated envelope, which compares the settings with ``config.PRESETS["default"]``,
    treats it as the preset it would become; None: `default` as it is."""
    preset_now = envelope.PRESETS["default"]  # config.PRESETS itself
    envelope.PRESETS["default"] = preset_now if settings is None else settings
    try:
        yield
    finally:
        envelope.PRESETS["default"] = preset_now


def run(scenes, configs: dict[str, SimSettings], model: ModelConfig, query: QuerySpec, pool) -> dict[str, dict]:
    """Every configuration on every tower, taking turns; each inside the envelope as the preset."""
    results = {name: {"wall_s": 0.0, "predictions": [], "rollouts": 0} for name in configs}
    for i, scene in enumerate(scenes):
        for name, settings in configs.items():
            start = time.perf_counter()
            with as_the_preset(None if name == "paper" else settings):
                prediction = predict(scene,
                                     Request(model=model, settings=settings, query=query, seed=i,
                                             check=None if name == "paper" else DEFAULT_CHECK, budget_s=None),
                                     Context(map_fn=pool.map))
            results[name]["wall_s"] += time.perf_counter() - start
            results[name]["predictions"].append(prediction)
            results[name]["rollouts"] += prediction.samples
        print(f"{scene.name}: " + "  ".join(f"{n} {r['wall_s']:.1f}s" for n, r in results.items()), flush=True)
    return results


def summary(result: dict, reference: dict) -> dict:
    row = A.compare(result, reference)
    predictions = result["predictions"]
    row["refined_samples"] = sum(p.refined_samples for p in predictions)
    row["verdicts"] = {v: sum(p.fidelity == v for p in predictions)
                       for v in sorted({p.fidelity for p in predictions})}
    return row


def markdown(report: dict) -> str:
    lines = [f"# `default` with {report['change']} on trial: the authors' {report['towers']} towers, "
             f"k = {report['samples']}",
             "", f"{report['machine']}; {report['date']}; queries {report['queries']}; sigma {A.SIGMA_M} m, "
             "phi 0; `paper` and both configurations taking turns tower by tower (same seeds); "
             f"wall {report['wall_s'] / 60:.0f} min.",
             "", "| configuration | s / prediction | speed-up vs paper | mean \\|ΔFF\\| | max \\|ΔFF\\| | "
             "per-sample agreement | direction error ° | samples refined | verdicts |",
             "|---|---|---|---|---|---|---|---|---|"]
    for name, row in report["rows"].items():
        direction = row["mean_direction_error_deg"]
        lines.append(f"| {name} | {row['wall_s_per_prediction']:.3f} | {row['speedup_vs_paper']:.2f}x | "
                     f"{row['mean_abs_dff']:.4f} | {row['max_abs_dff']:.4f} | "
                     f"{100 * row['per_sample_agreement']:.2f}% | "
                     f"{'-' if direction is None else f'{direction:.2f}'} | {row['refined_samples']} | "
                     + ", ".join(f"{v} {n}" for v, n in row["verdicts"].items()) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--set", action="append", required=True, metavar="NAME=VALUE",
                        help="the change, e.g. collapse.end_travel_fraction=none (repeatable)")
    parser.add_argument("--towers", type=int, default=60)
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--query", default="fall,any_fall,direction,far")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "preset_trial"))
    args = parser.parse_args(argv)
    change = parse_change(args.set)
    scenes, _, source = A.load_towers(args.towers)
    model = ModelConfig(sigma_m=A.SIGMA_M, samples=args.samples)
    query = QuerySpec(queries=frozenset(args.query.split(",")))
    label = ", ".join(args.set)
    configs = {"paper": PRESETS["paper"], "default": PRESETS["default"],
               f"default, {label}": trial(PRESETS["default"], change)}
    start = time.perf_counter()
    with WorkerPool(args.workers) as pool:
        pool.warm()
        results = run(scenes, configs, model, query, pool)
    report = {"change": label, "towers": len(scenes), "source": source, "samples": args.samples,
              "queries": args.query, "machine": f"{os.cpu_count()} CPUs, {args.workers} workers",
              "date": time.strftime("%Y-%m-%d"), "wall_s": time.perf_counter() - start,
              "rows": {name: summary(results[name], results["paper"]) for name in configs if name != "paper"}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "preset_trial.json").write_text(json.dumps(report, indent=1))
    (out / "preset_trial.md").write_text(markdown(report))
    print(markdown(report))


if __name__ == "__main__":
    main()
