"""Exp. S2 (How far?): far predictions, and the F ratio against Will it fall?"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...engine import preset
from .. import stats
from ..features import tower_features
from ..report import Report
from ..runs import load_tower_stimuli, run_model
from .common import (FALL, FALL_FAR, HumanComparison, Options, compare_with_people, ground_truth_model, ipe_model,
                     render_people)


@dataclass(frozen=True)
class FarResult:
    towers: tuple[str, ...]
    source: str
    fall_towers: int
    fall_source: str
    ipe_far_m: np.ndarray
    ground_truth_far_m: np.ndarray
    tower_height_m: np.ndarray
    f_ratio_far: float
    f_ratio_fall: float
    r_ipe_ground_truth: object
    r_ipe_height: object
    people: HumanComparison | None


def compute(opts: Options, map_fn) -> FarResult:
    settings = preset(opts.preset)
    stim = load_tower_stimuli("whichdirection.csv", opts.data_dir, opts.limit(None, 6), seed=opts.seed + 2)
    fall_stim = load_tower_stimuli("willitfall.csv", opts.data_dir, opts.limit(None, 6), seed=opts.seed)
    ipe = run_model("IPE far", stim.scenes, ipe_model(opts.k), settings, FALL_FAR, opts.seed, map_fn)
    truth = run_model("ground truth far", stim.scenes, ground_truth_model(), settings, FALL_FAR, opts.seed, map_fn)
    fall = run_model("IPE fall", fall_stim.scenes, ipe_model(opts.k), settings, FALL, opts.seed, map_fn)
    heights = np.array([tower_features(s)["F_F1_height_m"] for s in stim.scenes])
    far, gt_far = ipe.mean("far"), truth.mean("far")
    return FarResult(
        towers=stim.names, source=stim.source, fall_towers=len(fall_stim.scenes), fall_source=fall_stim.source,
        ipe_far_m=far, ground_truth_far_m=gt_far, tower_height_m=heights,
        f_ratio_far=stats.anova_f_ratio(ipe.per_sample("far")), f_ratio_fall=stats.anova_f_ratio(fall.per_sample("fall")),
        r_ipe_ground_truth=stats.bootstrap_pearson(far, gt_far, n_resamples=opts.resamples, rng=opts.rng("far-gt")),
        r_ipe_height=stats.bootstrap_pearson(far, heights, n_resamples=opts.resamples, rng=opts.rng("far-height")),
        people=compare_with_people(opts, stim.names, {"IPE": far, "ground truth": gt_far, "tower height": heights}))


def render(res: FarResult, opts: Options) -> Report:
    report = Report("far", "Exp. S2 (How far?): far predictions and the F ratio against Will it fall?",
                    opts.parameters())
    report.results.update(towers=list(res.towers), ipe_far_m=res.ipe_far_m, ground_truth_far_m=res.ground_truth_far_m,
                          tower_height_m=res.tower_height_m, f_ratio_far=res.f_ratio_far, f_ratio_fall=res.f_ratio_fall,
                          r_ipe_ground_truth=res.r_ipe_ground_truth, r_ipe_height=res.r_ipe_height)
    report.add(f"Stimuli: {len(res.towers)} towers from {res.source} (How far?), {res.fall_towers} from "
               f"{res.fall_source} (Will it fall?).", "",
               "## How separable are the model's predictions across towers?", "",
               f"One-way ANOVA F over towers of the per-sample predictions (k = {opts.k} per tower): How far? "
               f"F = {res.f_ratio_far:.1f}, Will it fall? F = {res.f_ratio_fall:.1f} (paper: 66.34 vs 172.17). Lower "
               "F means the model is less confident relative to how much towers differ.", "",
               "## Far against ground truth and against a feature", "",
               f"IPE far vs ground-truth far: r = {res.r_ipe_ground_truth}. IPE far vs tower height (Table S2 "
               f"F_F(1)): r = {res.r_ipe_height} (paper: height predicts people better than the model on this "
               "task).", "")
    render_people(report, res.people, opts)
    return report


def run(opts: Options, map_fn) -> Report:
    return render(compute(opts, map_fn), opts)
