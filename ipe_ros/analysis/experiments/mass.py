"""Exps. 3 and 4 (mass): mu over the SI's grid on the state pairs, and the mass-insensitive model (mu = 1)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine import preset
from .. import stats
from ..report import Report
from ..runs import PAPER_MUS, load_tower_stimuli, run_model
from .common import (FALL, FALL_DIRECTION, Options, direction_agreement, first_pairs, ground_truth_model, ipe_model,
                     state_pairs)

#: (key, stimulus file, query, title) of the two experiments.
EXPERIMENTS = (("exp3", "willitfall-mass.csv", "fall", "Exp. 3 (Will it fall?)"),
               ("exp4", "whichdirection-mass.csv", "direction", "Exp. 4 (In which direction?)"))


@dataclass(frozen=True)
class MuRow:
    """One mu of one experiment: agreement with ground truth, and the state pairs' differences."""

    mu: float
    r_with_ground_truth: object       # bootstrap Pearson (fall) or J-S circular r on decisive towers (direction)
    pair_difference_r: float
    mean_abs_pair_difference: float
    max_abs_pair_difference: float
    fisher_lee_r: object = None        # direction only
    within_45_deg: object = None       # direction only
    decisive_kept: int | None = None   # direction only


@dataclass(frozen=True)
class MassExperiment:
    key: str
    title: str
    query: str
    path: str
    stimuli: tuple[str, ...]
    pairs: int
    rows: tuple[MuRow, ...]


@dataclass(frozen=True)
class MassResult:
    mus: tuple[float, ...]
    experiments: tuple[MassExperiment, ...]
    absent: tuple[tuple[str, str], ...]  # (title, path) of the experiments whose stimuli are missing


def compute(opts: Options, map_fn) -> MassResult:
    settings = preset(opts.preset)
    mus = (1.0, 10.0) if opts.quick else PAPER_MUS
    pair_limit = None if opts.stimuli is None else max(3, opts.stimuli // 2)
    pair_limit = 3 if opts.quick and pair_limit is None else pair_limit
    experiments, absent = [], []
    for key, filename, query, title in EXPERIMENTS:
        path = opts.data_dir / filename
        if not path.exists():
            absent.append((title, str(path)))
            continue
        stim = first_pairs(load_tower_stimuli(filename, opts.data_dir, None, ratio="10"), pair_limit)
        pairs = state_pairs(stim.names)
        spec = FALL if query == "fall" else FALL_DIRECTION
        truth = run_model(f"{key} ground truth", stim.scenes, ground_truth_model(), settings, spec, opts.seed, map_fn)
        gt = truth.mean(query)
        gt_diff = np.array([gt[a] - gt[b] for a, b in pairs])
        rows = []
        for mu in mus:
            run = run_model(f"{key} mu={mu:g}", stim.scenes, ipe_model(opts.k, mu=mu), settings, spec, opts.seed,
                            map_fn)
            values = run.mean(query)
            diff = np.array([values[a] - values[b] for a, b in pairs])
            if query == "direction":
                diff = np.angle(np.exp(1j * diff))  # wrapped to (-pi, pi]
            sizes = dict(mean_abs_pair_difference=float(np.nanmean(np.abs(diff))),
                         max_abs_pair_difference=float(np.nanmax(np.abs(diff))))
            if query == "direction":
                out = direction_agreement(opts, stim.names, run, truth, f"{key}-{mu}")
                both = np.isfinite(diff) & np.isfinite(gt_diff)
                rows.append(MuRow(mu=mu, r_with_ground_truth=out.get("circular_r_included"),
                                  pair_difference_r=stats.circular_correlation(
                                      diff[both], np.angle(np.exp(1j * gt_diff))[both]),
                                  fisher_lee_r=out.get("fisher_lee_r_included"),
                                  within_45_deg=out.get("within_45_deg_included"), decisive_kept=out["included"],
                                  **sizes))
            else:
                rows.append(MuRow(mu=mu, r_with_ground_truth=stats.bootstrap_pearson(
                    values, gt, n_resamples=opts.resamples, rng=opts.rng(f"{key}-{mu}")),
                    pair_difference_r=stats.pearson(diff, gt_diff), **sizes))
        experiments.append(MassExperiment(key=key, title=title, query=query, path=str(path), stimuli=stim.names,
                                          pairs=len(pairs), rows=tuple(rows)))
    return MassResult(mus=tuple(mus), experiments=tuple(experiments), absent=tuple(absent))


def _show(value) -> str:
    return str(value) if value is not None else "-"


def render(res: MassResult, opts: Options) -> Report:
    report = Report("mass", "Exps. 3 and 4 (mass): mu over the SI's grid, state pairs, mass-insensitive model",
                    opts.parameters(mu=list(res.mus)))
    absent = dict(res.absent)
    done = {e.title: e for e in res.experiments}
    for _key, _filename, query, title in EXPERIMENTS:
        if title in absent:
            report.add(f"## {title}", "", f"Skipped: {absent[title]} is absent (the state pairs are the authors' "
                                          "stimuli).", "")
            continue
        exp = done[title]
        per_mu, rows = {}, []
        for row in exp.rows:
            entry = {"mean_abs_pair_difference": row.mean_abs_pair_difference,
                     "max_abs_pair_difference": row.max_abs_pair_difference}
            if query == "direction":
                entry.update(fisher_lee_r_with_ground_truth=row.fisher_lee_r, within_45_deg=row.within_45_deg)
                rows.append([f"{row.mu:g}", *(_show(v) for v in (row.r_with_ground_truth, row.fisher_lee_r,
                                                                  row.within_45_deg)),
                             float(row.pair_difference_r), row.mean_abs_pair_difference,
                             f"{row.decisive_kept}/{len(exp.stimuli)}"])
            else:
                rows.append([f"{row.mu:g}", str(row.r_with_ground_truth), float(row.pair_difference_r),
                             row.mean_abs_pair_difference])
            entry.update(r_with_ground_truth=row.r_with_ground_truth, pair_difference_r=row.pair_difference_r)
            per_mu[f"{row.mu:g}"] = entry
        report.results[exp.key] = {"stimuli": list(exp.stimuli), "pairs": exp.pairs, "by_mu": per_mu}
        unit = "rad" if query == "direction" else "fall fraction"
        report.add(f"## {title}: {len(exp.stimuli)} stimuli ({exp.pairs} state pairs at ratio 10) from {exp.path}", "",
                   "Reference: the ground-truth model with the stimuli's own masses (ratio 10). 'pair r' correlates "
                   "the IPE's within-pair differences with ground truth's. mu = 1 is the mass-insensitive model: "
                   "its pair members share geometry and seeds, so their difference is exactly 0.", "")
        if query == "direction":
            header = ["mu", "circular r with ground truth (J-S)", "Fisher-Lee r", "within +-45 degrees",
                      "pair r (J-S)", f"mean absolute pair difference ({unit})", "decisive kept"]
        else:
            header = ["mu", "r with ground truth", "pair r", f"mean absolute pair difference ({unit})"]
        report.table(header, rows)
    return report


def run(opts: Options, map_fn) -> Report:
    return render(compute(opts, map_fn), opts)
