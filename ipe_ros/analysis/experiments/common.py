"""What every report shares: its options, the paper's model settings, and the comparisons used by several."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...engine import ModelConfig, QuerySpec
from .. import paper_data, stats
from ..human import HumanResponses
from ..report import Report
from ..runs import PAPER_PHI, PAPER_SIGMA, PHI_M_S2_PER_PAPER_UNIT, ModelRun, Stimuli, phi_m_s2, sigma_m

FALL = QuerySpec(queries=frozenset({"fall"}))
FALL_DIRECTION = QuerySpec(queries=frozenset({"fall", "direction"}))
FALL_FAR = QuerySpec(queries=frozenset({"fall", "far"}))
BUMP = QuerySpec(queries=frozenset({"bump"}))
#: The paper's decisiveness rule for Exps. 2 and 4: keep a tower when at least this share of the
#: IPE's sampled directions lies in one half circle.
DECISIVE = 0.8


@dataclass(frozen=True)
class Options:
    """quick: CI-sized. samples: k of the main model (paper: 48 for towers, 12 for Exp. 5).
    stimuli: use the first N stimuli of each set. resamples: bootstrap resamples (paper: 10 000).
    grid_samples: k of each cell of the sigma x phi grid (default: ``samples``; 121 cells x 60 towers
    at k = 48 take hours)."""

    out_dir: Path
    data_dir: Path
    quick: bool = False
    seed: int = 0
    samples: int | None = None
    stimuli: int | None = None
    preset: str = "default"
    resamples: int = stats.BOOTSTRAP_RESAMPLES
    grid_samples: int | None = None
    human: HumanResponses | None = None
    human_path: str | None = None
    vision_resolution: int | None = None  # the vision report's image size (None: 256, quick 64)

    @property
    def k(self) -> int:
        return self.samples or (6 if self.quick else 48)

    def limit(self, full: int | None, quick: int) -> int | None:
        if self.stimuli is not None:
            return self.stimuli
        return quick if self.quick else full

    def rng(self, purpose: str) -> np.random.Generator:
        """One generator per analysis step, from the seed and the step's name (order-independent)."""
        return np.random.default_rng([self.seed, *purpose.encode()])

    def parameters(self, **extra) -> dict:
        """What a report states it was run with (its "Parameters" line and JSON field)."""
        out = {"seed": self.seed, "preset": self.preset, "k": self.k, "quick": self.quick,
               "bootstrap resamples": self.resamples, "sigma (paper, block short sides)": PAPER_SIGMA,
               "phi (paper)": PAPER_PHI, "phi m/s^2 per paper unit": PHI_M_S2_PER_PAPER_UNIT}
        if self.human_path:
            out["human responses"] = self.human_path
        out.update(extra)
        return out


def ipe_model(k: int, phi_paper: float = PAPER_PHI, sigma_sides: float = PAPER_SIGMA,
              mu: float | None = None) -> ModelConfig:
    """The IPE with the paper's fitted sigma and phi (in the paper's units) unless told otherwise."""
    return ModelConfig(sigma_m=sigma_m(sigma_sides), phi_m_s2=(phi_m_s2(phi_paper),), samples=k, mu=mu)


def ground_truth_model(mu: float | None = None) -> ModelConfig:
    """sigma = phi = 0 and no body's own noise: the stimulus exactly as given, one rollout."""
    return ModelConfig(mu=mu, object_noise=False)


def authors_stable(data_dir: Path, dataset: str) -> dict[str, bool]:
    return {name: outcome.stable for name, outcome in paper_data.authors_outcomes(dataset, data_dir).items()}


# ------------------------------------------------------------------------------------------------
# comparisons several reports make

@dataclass(frozen=True)
class HumanComparison:
    """Model-people correlations for each model variant over the stimuli people answered."""

    stimuli: int
    correlations: dict  # variant -> bootstrap estimate
    used: dict          # variant -> stimuli with a defined model value
    circular: bool


def compare_with_people(opts: Options, names: tuple[str, ...], model: dict[str, np.ndarray],
                        circular: bool = False) -> HumanComparison | None:
    """Bootstrap correlations with the human responses (None without them); ``stimuli`` < 3: none computed."""
    human = opts.human
    if human is None:
        return None
    answered = [i for i, n in enumerate(names) if n in human.mean]
    if len(answered) < 3:
        return HumanComparison(stimuli=len(answered), correlations={}, used={}, circular=circular)
    people = np.array([human.mean[names[i]] for i in answered])
    correlate = stats.bootstrap_circular if circular else stats.bootstrap_pearson
    correlations, used = {}, {}
    for label, values in model.items():
        v = values[answered]
        keep = np.isfinite(v)
        correlations[label] = correlate(v[keep], people[keep], n_resamples=opts.resamples,
                                        rng=opts.rng(f"human-{label}"))
        used[label] = int(keep.sum())
    return HumanComparison(stimuli=len(answered), correlations=correlations, used=used, circular=circular)


def render_people(report: Report, comparison: HumanComparison | None, opts: Options) -> None:
    if comparison is None:
        return
    if comparison.stimuli < 3:
        report.add(f"Human responses: only {comparison.stimuli} of this report's stimuli appear in "
                   f"{opts.human_path}; no correlation computed.", "")
        return
    report.results["human"] = {"stimuli": comparison.stimuli, "correlations": comparison.correlations}
    report.add("### Against the human responses", "")
    report.table(["model", "stimuli", "circular r" if comparison.circular else "r (median [95% CI])"],
                 [[label, comparison.used[label], str(est)] for label, est in comparison.correlations.items()])


def circular_agreement(a: np.ndarray, b: np.ndarray, opts: Options, rng_keys: tuple[str, str, str]) -> dict:
    """Agreement of two direction sets: J-S circular r, and its stable companions (fall directions
    spread round the circle, where the J-S r is erratic): Fisher-Lee r and the +-45 degree fraction."""
    keys = iter(rng_keys)
    return {"circular_r": stats.bootstrap_circular(a, b, n_resamples=opts.resamples, rng=opts.rng(next(keys))),
            "fisher_lee_r": stats.bootstrap_fisher_lee(a, b, n_resamples=opts.resamples, rng=opts.rng(next(keys))),
            "within_45_deg": stats.bootstrap_within(a, b, math.pi / 4, n_resamples=opts.resamples,
                                                    rng=opts.rng(next(keys)))}


def direction_agreement(opts: Options, names, ipe: ModelRun, truth: ModelRun, key: str) -> dict:
    """IPE against ground-truth directions on the decisive towers (and J-S r on all with a direction)."""
    ipe_dir, gt_dir = ipe.mean("direction"), truth.mean("direction")
    decisiveness = np.array([np.nan if p.direction_decisiveness is None else p.direction_decisiveness
                             for p in ipe.predictions])
    defined = np.isfinite(ipe_dir) & np.isfinite(gt_dir)
    included = defined & (decisiveness >= DECISIVE)
    out = {"stimuli": len(names), "decisive": int(np.sum(decisiveness >= DECISIVE)), "included": int(included.sum()),
           "ground_truth_direction_defined": int(np.isfinite(gt_dir).sum()),
           "ipe_direction_rad": ipe_dir, "ground_truth_direction_rad": gt_dir, "decisiveness": decisiveness}
    if included.sum() >= 3:
        agreement = circular_agreement(ipe_dir[included], gt_dir[included], opts,
                                       (key + "-in", key + "-fl", key + "-45"))
        out.update({f"{name}_included": est for name, est in agreement.items()})
    if defined.sum() >= 3:
        out["circular_r_all"] = stats.bootstrap_circular(ipe_dir[defined], gt_dir[defined],
                                                         n_resamples=opts.resamples, rng=opts.rng(key + "-all"))
    return out


# ------------------------------------------------------------------------------------------------
# state pairs (Exps. 3 and 4)

def state_pairs(names: tuple[str, ...]) -> list[tuple[int, int]]:
    """Indices of the two members of each heavy/light state pair (same geometry, other masses)."""
    by_geometry: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        by_geometry.setdefault(name.split("@", 1)[0].rsplit("_", 1)[0], []).append(i)
    return [(v[0], v[1]) for v in by_geometry.values() if len(v) == 2]


def first_pairs(stim: Stimuli, pairs: int | None) -> Stimuli:
    """The stimuli of the first ``pairs`` state pairs (all when None)."""
    if pairs is None:
        return stim
    keep = sorted(i for pair in state_pairs(stim.names)[:pairs] for i in pair)
    return dataclasses.replace(stim, scenes=tuple(stim.scenes[i] for i in keep))
