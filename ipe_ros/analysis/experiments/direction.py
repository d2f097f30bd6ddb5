"""Exp. 2 (In which direction?): IPE directions, the decisiveness rule and circular correlations."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine import preset
from ..report import Report, pyplot
from ..runs import load_tower_stimuli, run_model
from .common import (DECISIVE, FALL_DIRECTION, HumanComparison, Options, compare_with_people, direction_agreement,
                     ground_truth_model, ipe_model, render_people)

_STATISTIC_LABELS = {
    "circular_r_included": "circular r (Jammalamadaka-SenGupta), kept towers",
    "circular_r_all": "circular r (Jammalamadaka-SenGupta), all towers",
    "fisher_lee_r_included": "circular r (Fisher-Lee), kept towers",
    "within_45_deg_included": "fraction within +-45 degrees, kept towers (paper, IPE vs people: 0.89)",
}


@dataclass(frozen=True)
class DirectionResult:
    towers: tuple[str, ...]
    source: str
    agreement: dict  # direction_agreement's statistics and per-tower directions
    people: HumanComparison | None


def compute(opts: Options, map_fn) -> DirectionResult:
    settings = preset(opts.preset)
    stim = load_tower_stimuli("whichdirection.csv", opts.data_dir, opts.limit(None, 6), seed=opts.seed + 2)
    ipe = run_model("IPE", stim.scenes, ipe_model(opts.k), settings, FALL_DIRECTION, opts.seed, map_fn)
    truth = run_model("ground truth", stim.scenes, ground_truth_model(), settings, FALL_DIRECTION, opts.seed, map_fn)
    agreement = direction_agreement(opts, stim.names, ipe, truth, "exp2")
    people = compare_with_people(opts, stim.names, {"IPE": agreement["ipe_direction_rad"],
                                                    "ground truth": agreement["ground_truth_direction_rad"]},
                                 circular=True)
    return DirectionResult(towers=stim.names, source=stim.source, agreement=agreement, people=people)


def render(result: DirectionResult, opts: Options) -> Report:
    out = result.agreement
    report = Report("direction", "Exp. 2 (In which direction?): IPE directions, decisiveness, circular correlation",
                    opts.parameters(**{"decisiveness threshold": DECISIVE}))
    report.add(f"Stimuli: {len(result.towers)} towers from {result.source}.", "")
    report.results.update(towers=list(result.towers), **out)
    report.add("## Decisiveness exclusion", "",
               f"A tower is kept when at least {DECISIVE:.0%} of the IPE's sampled directions fall in one half "
               f"circle (paper: 47 of 60 kept). Kept here: {out['decisive']} of {len(result.towers)} "
               f"({out['included']} with a ground-truth direction too).", "")
    rows = [[text, str(out[label])] for label, text in _STATISTIC_LABELS.items() if label in out]
    report.add("## IPE against ground-truth directions", "")
    report.table(["statistic", "median [95% CI]"], rows)
    report.add("", "Fall directions spread round the whole circle, so their circular mean is ill-defined and the "
               "Jammalamadaka-SenGupta r (which subtracts it) swings between bootstrap resamples: its interval is "
               "wide and its point value can differ from the median. The Fisher-Lee r uses pairwise differences "
               "and no mean, and the +-45 degree fraction is the paper's Fig. 3B measure.", "")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.8, 4.5))
    ipe_deg, gt_deg = np.degrees(out["ipe_direction_rad"]), np.degrees(out["ground_truth_direction_rad"])
    keep = out["decisiveness"] >= DECISIVE
    ax.scatter(gt_deg[keep], ipe_deg[keep], s=18, label="kept")
    ax.scatter(gt_deg[~keep], ipe_deg[~keep], s=18, marker="x", label="indecisive")
    ax.set_xlabel("ground truth direction (deg)")
    ax.set_ylabel("IPE direction (deg)")
    ax.legend()
    report.figure(fig, opts.out_dir, "directions", "IPE against ground-truth fall directions")
    render_people(report, result.people, opts)
    return report


def run(opts: Options, map_fn) -> Report:
    return render(compute(opts, map_fn), opts)
