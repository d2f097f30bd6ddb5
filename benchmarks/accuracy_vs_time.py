"""What accuracy costs in time: simulation settings against the converged `paper` reference, one run.

    .venv/bin/python benchmarks/accuracy_vs_time.py [--towers N] [--samples 48] [--workers 2]
                                                    [--phi 0,2] [--out benchmarks/results]

Towers: the 60 of ../shared/data/battaglia2013/willitfall.csv (IPE_SHARED_DATA overrides), or
generated paper-style towers when that file is absent. sigma = 0.2 block short sides (0.04 m), each
phi value in turn. Every configuration uses the same seeds as the reference, hence the same noisy
initial scenes, so differences are the simulator's alone.

Per configuration: wall time per prediction, rollouts per second, speed-up over `paper` timed in the
same run (the configurations take turns tower by tower, so the machine's drift hits each alike), mean and max |delta fall_fraction|, per-sample agreement (did anything fall in sample i?),
per-box agreement, the direction error for towers that fall (reference fall fraction >= 0.1), the mean
simulated time per rollout, and ground-truth agreement (sigma = phi = 0) with the authors' outcomes.
Also: k from 1 to 96 (the first k samples of a k = 96 run of the default, against the paper reference)
and the worker count. Writes accuracy_vs_time.md / .json (and .png when matplotlib is available).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

from ipe_ros.engine import PRESETS, ModelConfig, QuerySpec, SimSettings, WorkerPool, predict  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK, SelfCheck  # noqa: E402
from ipe_ros.engine.scene.generators import generate_towers  # noqa: E402
from ipe_ros.engine.scene.files import scenes_from_tower_csv  # noqa: E402
from ipe_ros.analysis.paper_data import EXP1_DATASET, authors_outcomes, shared_data_dir  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = shared_data_dir()
SIGMA_M = 0.04
UNCHECKED = "-unchecked"
ALWAYS_VERIFY = "-always-verify"  # checked as outside the validated envelope (checking/envelope.py)


def _check_for(name: str):
    """The self-check a configuration runs with: none, every answer verified, or the default's."""
    if name.endswith(UNCHECKED):
        return None
    return SelfCheck(always_verify=True) if name.endswith(ALWAYS_VERIFY) else DEFAULT_CHECK


def candidates() -> list[SimSettings]:
    """The settings swept; the `paper` preset is the reference and is always first."""
    paper = PRESETS["paper"]
    # The size cap (0.03 sqrt(size / g), 1/233 s for 0.2 m blocks) would silently turn every step
    # coarser than that back into 1/233 s: the swept settings lift it so each runs the step it names.
    base = paper.changed('', max_step_fraction_of_time_scale=0.1,
                         solver={"iterations": 100, "residual_threshold": 1e-05, "warm_start_factor": 1.0})
    # "-unchecked": the same settings without the self-check (engine.checking.fidelity), to show what it costs
    out = [paper, PRESETS["default"], PRESETS["default"].changed("default" + UNCHECKED),
           PRESETS["default"].changed("default" + ALWAYS_VERIFY)]
    for name in sorted(PRESETS):
        if name not in ("paper", "default"):
            out.append(PRESETS[name])
    fine, default = PRESETS["fine"], PRESETS["default"]
    out += [
        # what each of the default's changes from `fine` does on its own, and variations of them
        fine.changed('fine+collapse4', collapse={"step_factor": 4}),
        fine.changed('fine+1/180s', time_step_s=1 / 180, max_step_fraction_of_time_scale=0.04),
        fine.changed('fine+rest0.15', early_stop={"duration_s": 0.15, "min_time_s": 0.2}),
        fine.changed('fine+rest0.4', early_stop={"speed_sizes_per_s": 0.4, "angular_rad_s": 0.4}),
        # the default before "at rest" was read as 0.4 sizes/s and 0.4 rad/s
        default.changed('default-rest0.05', early_stop={"speed_sizes_per_s": 0.05, "angular_rad_s": 0.05}),
        # without settling (the first 0.1 s in half steps)
        fine.changed('fine-no-settle', settling={"substeps": 1}),
        default.changed('default-no-settle', settling={"substeps": 1}),
        default.changed('default-no-collapse', collapse={"step_factor": 1}),
        default.changed('default-collapse2', collapse={"step_factor": 2}),
        default.changed('default-collapse6', collapse={"step_factor": 6}),
        default.changed('default-travel0.25', max_travel_fraction=0.25),
        default.changed('default-drop0.25', collapse={"drop_fraction": 0.25}),
        # the solver iterations once the collapse has begun (the default's 50; None: the solver's 100;
        # the mass-ratio rule still adds more)
        default.changed('default-collapse100it', collapse={"solver_iterations": None}),
        default.changed('default-collapse30it', collapse={"solver_iterations": 30}),
        default.changed('default-res5e-6', solver={"residual_threshold": 5e-06}),
        # fewer iterations until the collapse, the full 100 in it
        default.changed('default-50it+collapse100it', solver={"iterations": 50}, collapse={"solver_iterations": 100}),
        default.changed('default-40it+collapse100it', solver={"iterations": 40}, collapse={"solver_iterations": 100}),
        default.changed('default-no-early', early_stop={"enabled": False}),
        default.changed('default-res1e-5', solver={"residual_threshold": 1e-05}),
        default.changed('default-res1e-6', solver={"residual_threshold": 1e-06}),
        default.changed('default-50it', solver={"iterations": 50}),
        default.changed('default-30it', solver={"iterations": 30}),
        default.changed('default-ws0.85', solver={"warm_start_factor": 0.85}),
        default.changed('default-multibody', solver={"maximal_coordinates": False}),
        default.changed('default-1/120s', time_step_s=1 / 120),
        default.changed('default-1/120s-uncapped', time_step_s=1 / 120, max_step_fraction_of_time_scale=0.1),
        default.changed('default-1/180s-uncapped', time_step_s=1 / 180, max_step_fraction_of_time_scale=0.1),
        default.changed('default-1.5s-horizon', horizon_s=1.5),
        default.changed('default-1s-horizon', horizon_s=1.0),
        PRESETS['paper'].changed('1ms/20it+early', solver={"iterations": 20}, early_stop={"enabled": True}),
        base.changed('1/240s/100it/ws1', time_step_s=1 / 240),
        base.changed('1/240s/100it/ws1+early', time_step_s=1 / 240, early_stop={"enabled": True}),
        base.changed('1/240s/50it/ws1+early', time_step_s=1 / 240, solver={"iterations": 50},
                     early_stop={"enabled": True}),
        base.changed('1/240s/100it/ws0.85', time_step_s=1 / 240, solver={"warm_start_factor": 0.85}),
        paper.changed('1ms/50it/maximal', solver={"maximal_coordinates": True}),
        base.changed('1/240s/100it/maximal', time_step_s=1 / 240, solver={"maximal_coordinates": True}),
        base.changed('1/240s/100it/maximal+early', time_step_s=1 / 240, solver={"maximal_coordinates": True},
                     early_stop={"enabled": True}),
        base.changed('1/120s/100it/maximal+early', time_step_s=1 / 120, solver={"maximal_coordinates": True},
                     early_stop={"enabled": True}),
        base.changed('1/240s/50it/maximal+early', time_step_s=1 / 240,
                     solver={"maximal_coordinates": True, "iterations": 50}, early_stop={"enabled": True}),
        base.changed('1/240s/100it/maximal/ws0.85+early', time_step_s=1 / 240,
                     solver={"maximal_coordinates": True, "warm_start_factor": 0.85}, early_stop={"enabled": True}),
        base.changed('1/180s/100it/maximal+early', time_step_s=1 / 180, solver={"maximal_coordinates": True},
                     early_stop={"enabled": True}),
        base.changed('1/240s/100it/maximal+early0.1', time_step_s=1 / 240, solver={"maximal_coordinates": True},
                     early_stop={"enabled": True, "duration_s": 0.1, "min_time_s": 0.2}),
        base.changed('1/120s/100it/ws1+early', time_step_s=1 / 120, early_stop={"enabled": True}),
        base.changed('1/240s/100it/ws1/1s', time_step_s=1 / 240, horizon_s=1.0),
    ]
    return out


def load_towers(count: int | None):
    csv = SHARED / "willitfall.csv"
    if csv.exists():
        scenes = scenes_from_tower_csv(csv)
        # name -> did the authors' ground-truth simulation make the tower fall
        truth = {name: not outcome.stable for name, outcome in authors_outcomes(EXP1_DATASET, SHARED).items()}
        source = str(csv)
    else:
        scenes, truth, source = generate_towers(2013, count or 20), {}, "generated towers (seed 2013)"
    return (scenes[:count] if count else scenes), truth, source


def run_config(scenes, settings: SimSettings, model: ModelConfig, query: QuerySpec, pool: WorkerPool) -> dict:
    return run_configs(scenes, [settings], model, query, pool)[0]


def run_configs(scenes, configs: list[SimSettings], model: ModelConfig, query: QuerySpec,
                pool: WorkerPool) -> list[dict]:
    """Every configuration on every tower, interleaved tower by tower: this shared 2-core machine
    drifts by 10-25% over minutes, and a ratio of times taken in different minutes (paper's 10 min,
    then default's 1) carries that drift; interleaved, each tower's predictions see the same machine."""
    walls = [0.0] * len(configs)
    predictions: list[list] = [[] for _ in configs]
    for i, scene in enumerate(scenes):
        for c, settings in enumerate(configs):
            start = time.perf_counter()
            predictions[c].append(predict(scene,
                                          Request(model=model, settings=settings, query=query, seed=i,
                                                  check=_check_for(settings.name), budget_s=None),
                                          Context(map_fn=pool.map)))
            walls[c] += time.perf_counter() - start
    return [{"wall_s": wall, "predictions": preds, "rollouts": sum(p.samples for p in preds)}
            for wall, preds in zip(walls, predictions)]


def circular_error_deg(a: float | None, b: float | None) -> float | None:
    if a is None or b is None:
        return None
    return abs(math.degrees((a - b + math.pi) % (2 * math.pi) - math.pi))


def answer(p) -> float:
    """The prediction's headline number: fall fraction, or P(anything falls) when only that was asked."""
    return p.fall_fraction if p.fall_fraction is not None else p.any_fall_probability


def _anything_fell(rollout) -> bool:
    return bool(rollout.fallen.any()) if rollout.fallen is not None else bool(rollout.value("any_fell"))


def compare(result: dict, reference: dict) -> dict:
    ff = np.array([answer(p) for p in result["predictions"]])
    ref_ff = np.array([answer(p) for p in reference["predictions"]])
    sample_agree, box_agree, simulated, dir_err = [], [], [], []
    for p, r in zip(result["predictions"], reference["predictions"]):
        for o, ro in zip(p.outcomes, r.outcomes):
            if not (o.ok and ro.ok):
                continue
            sample_agree.append(_anything_fell(o.rollouts[0]) == _anything_fell(ro.rollouts[0]))
            fell, ref_fell = o.rollouts[0].fallen, ro.rollouts[0].fallen
            if fell is not None and ref_fell is not None:
                box_agree.extend(fell == ref_fell)
            simulated.append(o.rollouts[0].simulated_s)
        if r.fall_fraction is not None and r.fall_fraction >= 0.1 and r.direction_rad is not None:
            err = circular_error_deg(p.direction_rad, r.direction_rad)
            if err is not None:
                dir_err.append(err)
    n = len(result["predictions"])
    return {
        "wall_s_per_prediction": result["wall_s"] / n,
        "median_latency_s": float(np.median([p.wall_s for p in result["predictions"]])),
        "rollouts_per_s": result["rollouts"] / result["wall_s"],
        "speedup_vs_paper": reference["wall_s"] / result["wall_s"],
        "mean_abs_dff": float(np.mean(np.abs(ff - ref_ff))),
        "max_abs_dff": float(np.max(np.abs(ff - ref_ff))),
        "per_sample_agreement": float(np.mean(sample_agree)),
        "per_box_agreement": float(np.mean(box_agree)) if box_agree else None,
        "mean_direction_error_deg": float(np.mean(dir_err)) if dir_err else None,
        "mean_simulated_s": float(np.mean(simulated)),
        "failed_samples": int(sum(p.failed_samples for p in result["predictions"])),
    }


def ground_truth_agreement(scenes, settings: SimSettings, truth: dict[str, bool], pool: WorkerPool) -> float | None:
    if not truth:
        return None
    hits = []
    predictions = pool.map(_ground_truth, [(s, settings) for s in scenes])
    for scene, fell in zip(scenes, predictions):
        base = scene.name.split("@")[0]
        if base in truth:
            hits.append(fell == truth[base])
    return float(np.mean(hits)) if hits else None


def _ground_truth(item) -> bool:
    scene, settings = item
    # the ground truth: the scene exactly as given (no noise of the model's, none of any body's own)
    p = predict(scene,
                Request(model=ModelConfig(object_noise=False), settings=settings,
                        query=QuerySpec(queries=frozenset({"fall"})), seed=0, budget_s=None))
    return p.fall_fraction > 0


K_VALUES = (1, 3, 6, 12, 24, 48, 96)


def k_sweep(scenes, reference: dict, model: ModelConfig, query: QuerySpec, pool: WorkerPool) -> list[dict]:
    """The default preset with k samples against the paper reference with the configured k."""
    rows = []
    ref_ff = np.array([answer(p) for p in reference["predictions"]])
    for k in K_VALUES:
        result = run_config(scenes, PRESETS["default"], model.changed(samples=k), query, pool)
        ff = np.array([answer(p) for p in result["predictions"]])
        rows.append({"k": k, "wall_s_per_prediction": result["wall_s"] / len(scenes),
                     "speedup_vs_paper": reference["wall_s"] / result["wall_s"],
                     "mean_abs_dff": float(np.mean(np.abs(ff - ref_ff))),
                     "max_abs_dff": float(np.max(np.abs(ff - ref_ff)))})
        print(f"k={k:<3} {rows[-1]['wall_s_per_prediction']:6.2f} s  |dFF| {rows[-1]['mean_abs_dff']:.3f}", flush=True)
    return rows


def worker_sweep(scenes, model: ModelConfig, query: QuerySpec, max_workers: int) -> list[dict]:
    rows = []
    for workers in sorted({1, max_workers}):
        with WorkerPool(workers) as pool:
            pool.warm()
            result = run_config(scenes, PRESETS["default"], model, query, pool)
        rows.append({"workers": workers, "wall_s_per_prediction": result["wall_s"] / len(scenes),
                     "rollouts_per_s": result["rollouts"] / result["wall_s"]})
        print(f"workers={workers} {rows[-1]['wall_s_per_prediction']:.2f} s per prediction", flush=True)
    return rows


def _fmt(value, spec=".3f") -> str:
    return "-" if value is None else format(value, spec)


def markdown(report: dict) -> str:
    lines = [f"{report['towers']} towers from {report['source']}; k = {report['samples']}, sigma = "
             f"{report['sigma_m']} m, queries {','.join(report['queries'])}, {report['workers']} workers; "
             "reference: `paper` with the same seeds. With only `any_fall` asked, ΔFF is the difference in "
             "P(anything falls).", "",
             "| phi m/s² | settings | s / prediction | median s | rollouts/s | speed-up | mean \|ΔFF\| | max \|ΔFF\| | "
             "per-sample agreement | per-box agreement | direction error ° | simulated s | ground truth vs authors |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in report["rows"]:
        lines.append(f"| {r['phi_m_s2']:g} | {r['config']} | {r['wall_s_per_prediction']:.2f} | "
                     f"{_fmt(r.get('median_latency_s'), '.2f')} | {r['rollouts_per_s']:.0f} | "
                     f"{r['speedup_vs_paper']:.1f}x | {r['mean_abs_dff']:.3f} | {r['max_abs_dff']:.3f} | "
                     f"{r['per_sample_agreement']:.3f} | {_fmt(r['per_box_agreement'], '.3f')} | "
                     f"{_fmt(r['mean_direction_error_deg'], '.1f')} | {r['mean_simulated_s']:.2f} | "
                     f"{_fmt(r['ground_truth_agreement'], '.3f')} |")
    if report.get("k_sweep"):
        lines += ["", "k sweep (`default` preset, phi = 0, against the `paper` reference):", "",
                  "| k | s / prediction | speed-up vs paper | mean \|ΔFF\| | max \|ΔFF\| |", "|---|---|---|---|---|"]
        lines += [f"| {r['k']} | {r['wall_s_per_prediction']:.2f} | {r['speedup_vs_paper']:.1f}x | "
                  f"{r['mean_abs_dff']:.3f} | {r['max_abs_dff']:.3f} |" for r in report["k_sweep"]]
    if report.get("worker_sweep"):
        lines += ["", "| workers | s / prediction (default, phi = 0) | rollouts/s |", "|---|---|---|"]
        lines += [f"| {r['workers']} | {r['wall_s_per_prediction']:.2f} | {r['rollouts_per_s']:.0f} |"
                  for r in report["worker_sweep"]]
    return "\n".join(lines) + "\n"


def plot(report: dict, path: Path) -> bool:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for phi in sorted({r["phi_m_s2"] for r in report["rows"]}):
        rows = [r for r in report["rows"] if r["phi_m_s2"] == phi]
        ax = axes[0]
        ax.scatter([r["wall_s_per_prediction"] for r in rows], [r["mean_abs_dff"] for r in rows],
                   label=f"phi = {phi:g} m/s²")
        for r in rows:
            ax.annotate(r["config"], (r["wall_s_per_prediction"], r["mean_abs_dff"]), fontsize=6)
    axes[0].set_xscale("log")
    axes[0].axhline(0.02, color="grey", lw=0.5, ls="--")
    axes[0].set_xlabel("wall time per prediction, s (log)")
    axes[0].set_ylabel("mean |Δ fall fraction| vs paper")
    axes[0].set_title("settings (k fixed)")
    axes[0].legend(fontsize=7)
    if report.get("k_sweep"):
        ks = report["k_sweep"]
        axes[1].plot([r["wall_s_per_prediction"] for r in ks], [r["mean_abs_dff"] for r in ks], "o-")
        for r in ks:
            axes[1].annotate(f"k={r['k']}", (r["wall_s_per_prediction"], r["mean_abs_dff"]), fontsize=7)
        axes[1].set_xscale("log")
        axes[1].set_xlabel("wall time per prediction, s (log)")
        axes[1].set_ylabel("mean |Δ fall fraction| vs paper (k = %d)" % report["samples"])
        axes[1].set_title("default preset, samples k")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--towers", type=int, default=None, help="first N towers (default: all 60)")
    parser.add_argument("--samples", type=int, default=48)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--phi", default="0,2", help="push magnitudes in m/s^2, each a separate sweep")
    parser.add_argument("--query", default="fall,direction",
                        help="queries asked (early termination stops sooner when only 'fall' is asked)")
    parser.add_argument("--only", default=None, help="comma-separated configuration names (paper is always run)")
    parser.add_argument("--no-k-sweep", action="store_true")
    parser.add_argument("--out", default=str(REPO / "benchmarks" / "results"))
    args = parser.parse_args()
    scenes, truth, source = load_towers(args.towers)
    query = QuerySpec(queries=frozenset(args.query.split(",")))
    configs = candidates()
    if args.only:
        keep = set(args.only.split(",")) | {"paper"}
        configs = [c for c in configs if c.name in keep]
    report = {"source": source, "towers": len(scenes), "samples": args.samples, "workers": args.workers,
              "queries": sorted(query.queries), "sigma_m": SIGMA_M, "rows": [],
              "machine": f"{os.cpu_count()} CPUs", "date": time.strftime("%Y-%m-%d")}
    print(f"{len(scenes)} towers from {source}; k = {args.samples}, sigma = {SIGMA_M} m, {args.workers} workers\n")
    with WorkerPool(args.workers) as pool:
        pool.warm()
        for phi in (float(v) for v in args.phi.split(",")):
            model = ModelConfig(sigma_m=SIGMA_M, phi_m_s2=(phi,), samples=args.samples)
            results = run_configs(scenes, configs, model, query, pool)
            reference = results[0]
            for settings, result in zip(configs, results):
                row = {"phi_m_s2": phi, "config": settings.name, **compare(result, reference),
                       "ground_truth_agreement": ground_truth_agreement(scenes, settings, truth, pool) if phi == 0 else None,
                       "settings": {k: v for k, v in dataclasses.asdict(settings).items() if k != "name"}}
                report["rows"].append(row)
                print(f"phi={phi:g} {settings.name:<26} {row['wall_s_per_prediction']:7.2f} s  x{row['speedup_vs_paper']:5.2f}  "
                      f"|dFF| {row['mean_abs_dff']:.3f}/{row['max_abs_dff']:.3f}  agree {row['per_sample_agreement']:.3f}  "
                      f"sim {row['mean_simulated_s']:.2f} s  GT {row['ground_truth_agreement']}", flush=True)
            if phi == 0 and not args.no_k_sweep:
                report["k_sweep"] = k_sweep(scenes, reference, model, query, pool)
    if not args.no_k_sweep:
        report["worker_sweep"] = worker_sweep(scenes[:10], ModelConfig(sigma_m=SIGMA_M, samples=args.samples), query,
                                              args.workers)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "accuracy_vs_time.json").write_text(json.dumps(report, indent=1, default=float))
    (out / "accuracy_vs_time.md").write_text(markdown(report))
    made_plot = plot(report, out / "accuracy_vs_time.png")
    print(f"\nwrote {out}/accuracy_vs_time.json, .md" + (", .png" if made_plot else " (no matplotlib: no plot)"))


if __name__ == "__main__":
    main()
