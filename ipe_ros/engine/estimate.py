"""Aggregation over samples (paper Eq. S5): means, 95% intervals, circular statistics, decisiveness.

Samples are the independent units: when several push magnitudes are simulated per sample, their
results are averaged within the sample first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .rollout import SampleOutcome
from .scene import Scene

Z95 = 1.959963984540054


def wilson_interval(p_hat: float, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval for a mean of n independent values in [0, 1].

    For a fraction (not only a 0/1 outcome) the Bernoulli variance p(1-p) bounds the true variance,
    so the interval is conservative; unlike mean +- 1.96 sd/sqrt(n) it does not collapse to a point
    when every sample agrees (48 samples that all stay up still leave P(fall) up to ~0.07).
    Written here because ``scipy.stats.binomtest(...).proportion_ci(method="wilson")`` takes an
    integer count, and a fall fraction is a mean of fractions; for counts the two agree (tested).
    """
    if n <= 0:
        return (0.0, 1.0)
    denom = 1 + z * z / n
    centre = (p_hat + z * z / (2 * n)) / denom
    half = z * math.sqrt(max(p_hat * (1 - p_hat) / n + z * z / (4 * n * n), 0.0)) / denom
    # at p_hat = 0 or 1 the matching bound is exact; avoid returning 1e-17 for it
    lo = 0.0 if p_hat <= 0 else max(0.0, centre - half)
    hi = 1.0 if p_hat >= 1 else min(1.0, centre + half)
    return (lo, hi)


def mean_interval(values: np.ndarray) -> tuple[float, float]:
    """Student-t 95% interval of a mean (degenerate for fewer than 2 values): at k = 8-16 the normal
    z = 1.96 would be 5-15% too narrow."""
    from scipy.special import stdtrit  # the t quantile; scipy is already needed for hull meshes

    m = float(np.mean(values))
    if len(values) < 2:
        return (m, m)
    half = float(stdtrit(len(values) - 1, 0.975)) * float(np.std(values, ddof=1)) / math.sqrt(len(values))
    return (m - half, m + half)


def circular_mean(angles_rad: np.ndarray) -> float | None:
    """``scipy.stats.circmean`` in (-pi, pi], or None for no angles or a zero resultant (opposite
    falls cancel: "no direction", where circmean would return an arbitrary angle)."""
    # scipy.stats' formulas, step for step (its import costs ~0.5-1 s of every CLI call and node start)
    angles = np.asarray(angles_rad, dtype=float)
    if len(angles) == 0:
        return None
    sin, cos = np.sin(angles), np.cos(angles)
    resultant = min((np.mean(sin) ** 2.0 + np.mean(cos) ** 2.0) ** 0.5, 1.0)  # circvar = 1 - this
    if 1.0 - (1.0 - resultant) < 1e-12:
        return None
    return float((np.arctan2(np.sum(sin), np.sum(cos)) * 1.0 + math.pi) % (2 * math.pi) - math.pi)


def half_circle_decisiveness(angles_rad: np.ndarray) -> float | None:
    """Largest fraction of the angles inside any closed half circle (paper: exclude towers below 0.8).

    The best half circle can always be rotated until its start touches one of the angles, so it
    suffices to try each angle as the start.
    """
    n = len(angles_rad)
    if n == 0:
        return None
    a = np.mod(np.asarray(angles_rad, float), 2 * math.pi)
    diff = np.mod(a[None, :] - a[:, None], 2 * math.pi)  # diff[i, j]: j measured from i
    inside = diff <= math.pi + 1e-12
    return float(inside.sum(axis=1).max() / n)


def sample_fall_fraction(outcome: SampleOutcome) -> float:
    """One sample's fraction of fallen boxes, averaged over its push magnitudes (samples are the units)."""
    return float(np.mean([r.fallen.mean() for r in outcome.rollouts]))


def sample_any_fall(outcome: SampleOutcome) -> float:
    """One sample's "did anything fall?" (1 or 0), averaged over its push magnitudes."""
    return float(np.mean([float(r.any_fell) for r in outcome.rollouts]))


def sample_far_m(outcome: SampleOutcome) -> float:
    """One sample's far distance, averaged over its push magnitudes."""
    return float(np.mean([r.far_m for r in outcome.rollouts]))


@dataclass(frozen=True)
class Prediction:
    """The IPE's answer for one scene. Fields are None when their query was not asked.

    fall_fraction: expected fraction of dynamic boxes that fall (Exps. 1, 3).
    fall_fraction_ci95: its 95% interval (Wilson; a point for the deterministic ground truth).
    object_fall_probability: per box, the fraction of rollouts in which it fell.
    any_fall_probability: probability that at least one box falls (the yes/no question), with its
        95% Wilson interval ``any_fall_probability_ci95``.
    direction_rad: circular mean of the per-rollout fall directions (Exps. 2, 4), None if nothing fell.
    direction_decisiveness: largest fraction of those directions inside one half circle.
    far_m: expected largest horizontal distance of a fallen box from the tower base (Exp. S2).
    fell_off_fraction_by_group: per group, expected fraction of its boxes that end below the table top.
    bump_ratio: expected share of ``bump_group`` among boxes that fell off (Exp. 5), over rollouts
        where any fell off.
    stopped_by: what ended sampling: "samples" (all k), "ci_width" / "deadline" (anytime sampling),
        or "budget" (the compute budget ran out: ``samples`` says how many were used; the samples cut
        off are ``budget_skipped_samples``, neither used nor counted as failed).
    """

    scene: str
    samples: int
    samples_requested: int
    failed_samples: int
    failure_reasons: tuple[str, ...]
    deterministic: bool
    fall_fraction: float | None = None
    fall_fraction_ci95: tuple[float, float] | None = None
    object_fall_probability: dict[str, float] | None = None
    any_fall_probability: float | None = None
    any_fall_probability_ci95: tuple[float, float] | None = None
    direction_rad: float | None = None
    direction_decisiveness: float | None = None
    direction_rollouts: int | None = None
    far_m: float | None = None
    far_m_ci95: tuple[float, float] | None = None
    fell_off_fraction_by_group: dict[str, float] | None = None
    bump_group: str | None = None
    bump_ratio: float | None = None
    bump_rollouts: int | None = None
    wall_s: float = 0.0
    stopped_by: str = "samples"  # "samples" (all k drawn), "ci_width", "deadline" (anytime sampling), "budget"
    budget_skipped_samples: int = 0
    max_penetration_fraction: float | None = None
    max_energy_gain_j: float | None = None
    #: the self-check's verdict (engine.fidelity.VERDICTS): "verified", "escalated", "contradicted",
    #: "unverified" or "reference"; ``refined_samples``: rollouts rerun at the reference because they
    #: ended unhealthy; ``self_check``: what ran at which settings (FidelityReport.to_dict()).
    fidelity: str | None = None
    refined_samples: int = 0
    self_check: dict[str, Any] | None = None
    request: dict[str, Any] = field(default_factory=dict)
    outcomes: tuple[SampleOutcome, ...] = field(default=(), repr=False, compare=False)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready fields (everything but the raw outcomes)."""
        out = {name: getattr(self, name) for name in self.__dataclass_fields__ if name != "outcomes"}
        for key in ("fall_fraction_ci95", "any_fall_probability_ci95", "far_m_ci95", "failure_reasons"):
            if out[key] is not None:
                out[key] = list(out[key])
        return out


def aggregate(scene: Scene, outcomes: Sequence[SampleOutcome], *, queries: frozenset[str],
              bump_group: str, deterministic: bool, samples_requested: int, wall_s: float,
              request: dict[str, Any]) -> Prediction:
    """Combine per-sample outcomes into a :class:`Prediction` (failed samples are counted, not used)."""
    ok = [o for o in outcomes if o.ok]
    skipped = [o for o in outcomes if o.budget_stopped]
    failed = [o for o in outcomes if not o.ok and not o.budget_stopped]
    reasons = tuple(dict.fromkeys(o.error or "unknown" for o in failed))[:5]
    base = dict(scene=scene.name, samples=len(ok), samples_requested=samples_requested,
                failed_samples=len(failed), failure_reasons=reasons, deterministic=deterministic,
                wall_s=wall_s, request=request, outcomes=tuple(outcomes), budget_skipped_samples=len(skipped))
    if skipped:
        base["stopped_by"] = "budget"
    if not ok:
        return Prediction(**base)
    names = [b.name for b in scene.dynamic_objects]
    groups = [b.group for b in scene.dynamic_objects]
    values: dict[str, Any] = {}
    rollouts = [r for o in ok for r in o.rollouts]
    values["max_penetration_fraction"] = float(max(r.penetration_fraction for r in rollouts))
    values["max_energy_gain_j"] = float(max(r.energy_gain_j for r in rollouts))

    if "fall" in queries:
        per_sample = np.array([sample_fall_fraction(o) for o in ok])
        fall = float(per_sample.mean())
        values["fall_fraction"] = fall
        values["fall_fraction_ci95"] = (fall, fall) if deterministic else wilson_interval(fall, len(ok))
        per_object = np.mean([r.fallen for r in rollouts], axis=0)
        values["object_fall_probability"] = {n: float(p) for n, p in zip(names, per_object)}
    if "any_fall" in queries:
        anything = float(np.mean([sample_any_fall(o) for o in ok]))
        values["any_fall_probability"] = anything
        values["any_fall_probability_ci95"] = (anything, anything) if deterministic else wilson_interval(anything, len(ok))
    if "direction" in queries:
        angles = np.array([r.direction_rad for r in rollouts if r.direction_rad is not None])
        values["direction_rad"] = circular_mean(angles)
        values["direction_decisiveness"] = half_circle_decisiveness(angles)
        values["direction_rollouts"] = int(len(angles))
    if "far" in queries:
        per_sample = np.array([sample_far_m(o) for o in ok])
        values["far_m"] = float(per_sample.mean())
        values["far_m_ci95"] = (values["far_m"],) * 2 if deterministic else mean_interval(per_sample)
    if "bump" in queries:
        fell_off = np.array([r.fell_off for r in rollouts if r.fell_off is not None])
        if len(fell_off):
            by_group = {}
            for group in dict.fromkeys(groups):
                members = np.array([g == group for g in groups])
                by_group[group] = float(fell_off[:, members].mean())
            values["fell_off_fraction_by_group"] = by_group
            ratios = [r.bump_ratio for r in rollouts if r.bump_ratio is not None]
            values["bump_ratio"] = float(np.mean(ratios)) if ratios else None
            values["bump_rollouts"] = len(ratios)
            values["bump_group"] = bump_group
    return Prediction(**base, **values)
