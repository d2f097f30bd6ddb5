"""Feature-based alternatives to the IPE (Table S2) and cross-validated ridge regression: four analyses.

- tower_features_vs_fall: Exp. 1 towers, tower features -> the IPE's fall fraction (or people's answers);
- mass_features_vs_fall: Exp. 3 state pairs, features computed under an assumed mu -> the IPE at mu = 10;
- direction_features: Exp. 2 towers, direction features -> the IPE's fall direction (single features);
- table_features_vs_bump: Exp. 5 tables, F_B features -> the IPE's uncued bump ratio.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...engine import ModelConfig, preset
from ...engine.scene.generators import generate_tables
from .. import stats
from ..features import (DIRECTION_FEATURES, TABLE_FEATURES, TOWER_FEATURES, feature_matrix, table_features,
                        tower_features)
from ..report import Report
from ..ridge import cross_validated_ridge
from ..runs import PAPER_BUMP_PHIS, PAPER_MUS, PAPER_SIGMA, load_tower_stimuli, phi_m_s2, run_model, sigma_m
from .common import (BUMP, DECISIVE, FALL, FALL_DIRECTION, Options, circular_agreement, first_pairs, ipe_model)

#: Ridge regression needs at least this many stimuli (nested cross-validation).
RIDGE_MIN_STIMULI = 10


@dataclass(frozen=True)
class TowerFeatures:
    towers: tuple[str, ...]
    source: str
    target_label: str
    features: list
    single_feature_r: dict
    ridge_alpha: float
    ridge_coefficients: np.ndarray
    ridge_held_out_r: object
    ipe_minus_features: object | None  # bootstrap comparison with people, when they answered enough


def tower_features_vs_fall(opts: Options, map_fn) -> TowerFeatures:
    stim = load_tower_stimuli("willitfall.csv", opts.data_dir, opts.limit(None, 12), seed=opts.seed)
    ipe = run_model("IPE fall", stim.scenes, ipe_model(opts.k), preset(opts.preset), FALL, opts.seed, map_fn)
    rows = [tower_features(s) for s in stim.scenes]
    x = feature_matrix(rows, TOWER_FEATURES)
    target = ipe.mean("fall")
    target_label = "IPE fall fraction"
    answered = None
    if opts.human is not None:
        answered = [i for i, n in enumerate(stim.names) if n in opts.human.mean]
        if len(answered) >= RIDGE_MIN_STIMULI:
            x, target = x[answered], np.array([opts.human.mean[stim.names[i]] for i in answered])
            target_label = "people's mean response"
    fit = cross_validated_ridge(x, target, rng=opts.rng("ridge-exp1"), outer_folds=min(5, len(target) // 2))
    held_out_r = stats.bootstrap_pearson(fit.held_out, target, n_resamples=opts.resamples, rng=opts.rng("ridge-r"))
    comparison = None
    if target_label == "people's mean response":
        ipe_values = ipe.mean("fall")[answered]
        comparison = stats.bootstrap_compare(lambda a, b, c, axis=-1: stats.pearson(a, c, axis=axis),
                                             lambda a, b, c, axis=-1: stats.pearson(b, c, axis=axis),
                                             ipe_values, fit.held_out, target, n_resamples=opts.resamples,
                                             rng=opts.rng("cmp"))
    return TowerFeatures(towers=stim.names, source=stim.source, target_label=target_label, features=rows,
                         single_feature_r={name: stats.pearson(x[:, j], target) for j, name in enumerate(TOWER_FEATURES)},
                         ridge_alpha=fit.alpha, ridge_coefficients=fit.coefficients, ridge_held_out_r=held_out_r,
                         ipe_minus_features=comparison)


@dataclass(frozen=True)
class MassFeatures:
    stimuli: tuple[str, ...]
    by_mu: dict  # assumed mu -> ridge held-out r, best single feature and its r


def mass_features_vs_fall(opts: Options, map_fn) -> MassFeatures | None:
    """The paper's best fit was mu = 6; mu = 1 is the mass-insensitive feature set. None without the stimuli."""
    if not (opts.data_dir / "willitfall-mass.csv").exists():
        return None
    pairs = 3 if opts.quick else (None if opts.stimuli is None else max(3, opts.stimuli // 2))
    stim = first_pairs(load_tower_stimuli("willitfall-mass.csv", opts.data_dir, None, ratio="10"), pairs)
    ipe_fall = run_model("IPE fall (mass, mu = 10)", stim.scenes, ipe_model(opts.k, mu=10.0), preset(opts.preset),
                         FALL, opts.seed, map_fn).mean("fall")
    by_mu = {}
    for mu in ((1.0, 10.0) if opts.quick else PAPER_MUS):
        x = feature_matrix([tower_features(s, mu=mu) for s in stim.scenes], TOWER_FEATURES)
        if len(ipe_fall) >= RIDGE_MIN_STIMULI:
            fit = cross_validated_ridge(x, ipe_fall, rng=opts.rng(f"ridge-exp3-{mu}"),
                                        outer_folds=min(5, len(ipe_fall) // 2))
            held_out_r = float(stats.pearson(fit.held_out, ipe_fall))
        else:
            held_out_r = math.nan
        best = max(TOWER_FEATURES,
                   key=lambda n: abs(np.nan_to_num(stats.pearson(x[:, TOWER_FEATURES.index(n)], ipe_fall))))
        by_mu[f"{mu:g}"] = {"ridge_held_out_r": held_out_r, "best_single_feature": best,
                            "best_single_r": stats.pearson(x[:, TOWER_FEATURES.index(best)], ipe_fall)}
    return MassFeatures(stimuli=stim.names, by_mu=by_mu)


@dataclass(frozen=True)
class DirectionFeatures:
    towers: tuple[str, ...]
    decisive: int
    circular_r: dict
    fisher_lee_r: dict
    within_45_deg: dict


def direction_features(opts: Options, map_fn) -> DirectionFeatures:
    """Circular: single features only, as in the paper."""
    stim = load_tower_stimuli("whichdirection.csv", opts.data_dir, opts.limit(None, 12), seed=opts.seed + 2)
    ipe = run_model("IPE direction", stim.scenes, ipe_model(opts.k), preset(opts.preset), FALL_DIRECTION, opts.seed,
                    map_fn)
    rows = [tower_features(s) for s in stim.scenes]
    direction = ipe.mean("direction")
    decisive = np.array([(p.direction_decisiveness or 0) >= DECISIVE for p in ipe.predictions]) & np.isfinite(direction)
    by_statistic: dict[str, dict] = {"circular_r": {}, "fisher_lee_r": {}, "within_45_deg": {}}
    for name in DIRECTION_FEATURES:
        values = np.array([r[name] for r in rows])
        if decisive.sum() >= 3:
            agreement = circular_agreement(values[decisive], direction[decisive], opts,
                                           (name, name + "-fl", name + "-45"))
            for statistic, estimate in agreement.items():
                by_statistic[statistic][name] = estimate
    return DirectionFeatures(towers=stim.names, decisive=int(decisive.sum()), **by_statistic)


@dataclass(frozen=True)
class TableFeatures:
    scenes: tuple[str, ...]
    features: list
    ipe_bump_ratio: np.ndarray
    single_feature_r: dict
    ridge_alpha: float | None
    ridge_held_out_r: object | None  # None: too few scenes with a defined bump ratio
    defined: int


def table_features_vs_bump(opts: Options, map_fn) -> TableFeatures:
    """Uncued bump: a random direction, every magnitude."""
    phis = (22.0, 76.0) if opts.quick else PAPER_BUMP_PHIS
    tables = generate_tables(opts.seed, configurations=2 if opts.quick else 12,
                             tables=("T0", "T3") if opts.quick else ("T0", "T1", "T2", "T3", "T4"))
    model = ModelConfig(sigma_m=sigma_m(PAPER_SIGMA), phi_m_s2=tuple(phi_m_s2(p) for p in phis),
                        samples=opts.samples or (3 if opts.quick else 12))
    bump = run_model("IPE bump (uncued)", tables, model, preset(opts.preset), BUMP, opts.seed, map_fn).mean("bump")
    rows = [table_features(s) for s in tables]
    x = feature_matrix(rows, TABLE_FEATURES)
    keep = np.isfinite(bump)
    alpha = held_out_r = None
    if keep.sum() >= RIDGE_MIN_STIMULI:
        fit = cross_validated_ridge(x[keep], bump[keep], rng=opts.rng("ridge-exp5"),
                                    outer_folds=min(5, int(keep.sum()) // 2))
        alpha = fit.alpha
        held_out_r = stats.bootstrap_pearson(fit.held_out, bump[keep], n_resamples=opts.resamples,
                                             rng=opts.rng("b-r"))
    return TableFeatures(scenes=tuple(s.name for s in tables), features=rows, ipe_bump_ratio=bump,
                         single_feature_r={n: stats.pearson(x[keep, j], bump[keep]) for j, n in enumerate(TABLE_FEATURES)},
                         ridge_alpha=alpha, ridge_held_out_r=held_out_r, defined=int(keep.sum()))


@dataclass(frozen=True)
class FeaturesResult:
    towers: TowerFeatures
    mass: MassFeatures | None
    directions: DirectionFeatures
    tables: TableFeatures


def compute(opts: Options, map_fn) -> FeaturesResult:
    return FeaturesResult(towers=tower_features_vs_fall(opts, map_fn), mass=mass_features_vs_fall(opts, map_fn),
                          directions=direction_features(opts, map_fn), tables=table_features_vs_bump(opts, map_fn))


def render(res: FeaturesResult, opts: Options) -> Report:
    report = Report("features", "Feature-based alternatives (Table S2) and cross-validated ridge regression",
                    opts.parameters(target="human responses" if opts.human else "the IPE's own predictions"))
    towers = res.towers
    report.results["exp1"] = {"towers": list(towers.towers), "target": towers.target_label, "features": towers.features,
                              "single_feature_r": towers.single_feature_r, "ridge_alpha": towers.ridge_alpha,
                              "ridge_coefficients": dict(zip(TOWER_FEATURES, towers.ridge_coefficients)),
                              "ridge_held_out_r": towers.ridge_held_out_r}
    report.add(f"## Exp. 1 towers ({len(towers.towers)} from {towers.source}): features -> {towers.target_label}", "",
               f"Cross-validated ridge (nested 5-fold, penalty chosen inside each training fold; alpha on all data "
               f"{towers.ridge_alpha:g}): held-out r = {towers.ridge_held_out_r}.", "")
    report.table(["feature", "r with target", "ridge coefficient (standardised)"],
                 [[n, float(towers.single_feature_r[n]), float(c)]
                  for n, c in zip(TOWER_FEATURES, towers.ridge_coefficients)])
    if towers.ipe_minus_features is not None:
        comparison = towers.ipe_minus_features
        report.results["exp1"]["ipe_vs_features"] = comparison
        report.add(f"IPE minus features, r with people: {comparison.difference} (bootstrap P = "
                   f"{comparison.p_value:.4f}).", "")

    if res.mass is not None:
        report.results["exp3"] = {"stimuli": list(res.mass.stimuli), "by_mu": res.mass.by_mu}
        report.add(f"## Exp. 3 state pairs ({len(res.mass.stimuli)} stimuli at ratio 10): features under an assumed "
                   "mu -> IPE fall fraction (mu = 10)", "",
                   "mu = 1 gives mass-insensitive features (the same for both members of a pair). Ridge needs at "
                   f"least {RIDGE_MIN_STIMULI} stimuli.", "")
        report.table(["assumed mu", "ridge held-out r", "best single feature", "its r"],
                     [[mu, row["ridge_held_out_r"], row["best_single_feature"], float(row["best_single_r"])]
                      for mu, row in res.mass.by_mu.items()])

    directions = res.directions
    report.results["exp2"] = {"towers": list(directions.towers), "decisive": directions.decisive,
                              "circular_r": directions.circular_r, "fisher_lee_r": directions.fisher_lee_r,
                              "within_45_deg": directions.within_45_deg}
    report.add(f"## Exp. 2 towers ({len(directions.towers)}, {directions.decisive} decisive): direction features -> "
               "IPE direction", "")
    report.table(["feature", "circular r, Jammalamadaka-SenGupta (median [95% CI])", "circular r, Fisher-Lee",
                  "fraction within +-45 degrees"],
                 [[n, str(v), str(directions.fisher_lee_r[n]), str(directions.within_45_deg[n])]
                  for n, v in directions.circular_r.items()])

    tables = res.tables
    report.results["exp5"] = {"scenes": list(tables.scenes), "features": tables.features,
                              "ipe_bump_ratio": tables.ipe_bump_ratio, "single_feature_r": tables.single_feature_r}
    lines = [f"## Exp. 5 tables ({len(tables.scenes)} generated scenes): F_B features -> IPE uncued bump ratio", ""]
    if tables.ridge_held_out_r is not None:
        report.results["exp5"].update(ridge_alpha=tables.ridge_alpha, ridge_held_out_r=tables.ridge_held_out_r)
        lines.append(f"Cross-validated ridge over the {len(TABLE_FEATURES)} features: held-out r = "
                     f"{tables.ridge_held_out_r}.")
    else:
        lines.append(f"Ridge skipped: {tables.defined} scenes with a defined bump ratio (needs {RIDGE_MIN_STIMULI}).")
    report.add(*lines, "")
    report.table(["feature", "r with the IPE"], [[n, float(v)] for n, v in tables.single_feature_r.items()])
    return report


def run(opts: Options, map_fn) -> Report:
    return render(compute(opts, map_fn), opts)
