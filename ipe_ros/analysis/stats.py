"""Statistics as in the paper's SI "Data Analysis", on top of scipy.

- Correlations over stimuli: Pearson (Exps. 1, 3, 5, S2) and circular (Exps. 2, 4; Jammalamadaka &
  SenGupta 2001, the coefficient of the paper's ref. 2).
- Every coefficient is reported as the median of 10 000 bootstrap resamples of the stimuli, with the
  2.5th and 97.5th percentiles as its 95% interval (``scipy.stats.bootstrap``, percentile method).
- P values come from a direct bootstrap test: the fraction of paired resamples in which the
  difference goes the other way.
- The F ratio is the one-way ANOVA F statistic over stimuli (``scipy.stats.f_oneway``).
- k from response variances: variance_subjects = variance_model / k + omega^2 (SI "Approximating
  Probabilities"), a straight-line fit whose slope is 1/k and whose intercept is omega^2.

Randomness is always an explicit ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy import stats as scipy_stats

#: The paper's resample count.
BOOTSTRAP_RESAMPLES = 10_000


def _as_pair(x, y) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.asarray(x, float), np.asarray(y, float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"x and y: must be 1-D arrays of the same length, got shapes {x.shape} and {y.shape}")
    return x, y


def pearson(x, y, axis: int = -1) -> np.ndarray | float:
    """Pearson's r along ``axis`` (``scipy.stats.pearsonr``, vectorised for the bootstrap); NaN where
    either side is constant."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy_stats.ConstantInputWarning)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = scipy_stats.pearsonr(x, y, axis=axis).statistic
    return float(r) if np.ndim(r) == 0 else np.asarray(r)


def circular_mean(angles_rad, axis: int = -1) -> np.ndarray | float:
    """``scipy.stats.circmean`` in (-pi, pi]."""
    out = scipy_stats.circmean(angles_rad, high=math.pi, low=-math.pi, axis=axis)
    return float(out) if np.ndim(out) == 0 else out


def circular_variance(angles_rad, axis: int = -1) -> np.ndarray | float:
    """``scipy.stats.circvar``: 1 - the mean resultant length (0 when all angles agree, 1 when they cancel)."""
    out = scipy_stats.circvar(angles_rad, high=math.pi, low=-math.pi, axis=axis)
    return float(out) if np.ndim(out) == 0 else out


def circular_correlation(a, b, axis: int = -1) -> np.ndarray | float:
    """Jammalamadaka-SenGupta circular correlation of two angle arrays (radians), in [-1, 1].

    Written here: scipy has no circular correlation (astropy's ``circcorrcoef`` is this formula, not
    worth a dependency for five lines).

    r = sum sin(a - mean a) sin(b - mean b) / sqrt(sum sin^2(a - mean a) sum sin^2(b - mean b)).
    A rotated copy (b = a + c) gives exactly 1, a reflected one (b = c - a) gives -1.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    sa = np.sin(a - np.expand_dims(circular_mean(a, axis=axis), axis))
    sb = np.sin(b - np.expand_dims(circular_mean(b, axis=axis), axis))
    num = (sa * sb).sum(axis=axis)
    den = np.sqrt((sa * sa).sum(axis=axis) * (sb * sb).sum(axis=axis))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return float(r) if np.ndim(r) == 0 else r


def fisher_lee_correlation(a, b, axis: int = -1) -> np.ndarray | float:
    """Fisher-Lee (1983) circular correlation rho_T of two angle arrays (radians), in [-1, 1].

    r = sum_{i<j} sin(a_i - a_j) sin(b_i - b_j) / sqrt(sum sin^2(a_i - a_j) sum sin^2(b_i - b_j)).
    Built from pairwise differences, it needs no mean direction. That matters for fall directions,
    which spread round the whole circle: their circular mean is then ill-defined, and the
    Jammalamadaka-SenGupta r (which subtracts it) jumps between bootstrap resamples.
    """
    a, b = np.moveaxis(np.asarray(a, float), axis, -1), np.moveaxis(np.asarray(b, float), axis, -1)
    da = np.sin(a[..., :, None] - a[..., None, :])
    db = np.sin(b[..., :, None] - b[..., None, :])
    # Each unordered pair appears twice with the same sign of the product: the factor cancels.
    num = (da * db).sum(axis=(-2, -1))
    den = np.sqrt((da * da).sum(axis=(-2, -1)) * (db * db).sum(axis=(-2, -1)))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return float(r) if np.ndim(r) == 0 else r


def angular_difference(a, b) -> np.ndarray:
    """a - b wrapped to [-pi, pi) (radians)."""
    return np.mod(np.asarray(a, float) - np.asarray(b, float) + math.pi, 2 * math.pi) - math.pi


def fraction_within(a, b, tolerance_rad: float, axis: int = -1) -> np.ndarray | float:
    """Fraction of stimuli whose two angles differ by at most ``tolerance_rad`` (the paper's "within
    +-45 degrees" agreement, Fig. 3B)."""
    out = (np.abs(angular_difference(a, b)) <= tolerance_rad).mean(axis=axis)
    return float(out) if np.ndim(out) == 0 else out


@dataclass(frozen=True)
class Estimate:
    """A bootstrapped statistic: the paper's median and 2.5/97.5 percentiles of the resamples.

    point: the statistic on the data as observed. resamples: how many resamples gave a defined
    value (a resample whose values are all equal has no correlation).
    """

    point: float
    median: float
    lo: float
    hi: float
    resamples: int

    def to_dict(self) -> dict[str, float]:
        return {"point": self.point, "median": self.median, "ci95": [self.lo, self.hi], "resamples": self.resamples}

    def __str__(self) -> str:
        return f"{self.median:.2f} [{self.lo:.2f}, {self.hi:.2f}]"


Statistic = Callable[..., np.ndarray]


def _bootstrap_distribution(statistic: Statistic, data: Sequence[np.ndarray], n_resamples: int,
                            rng: np.random.Generator) -> np.ndarray:
    """Paired resamples of the stimuli (all arrays share their index), via scipy.stats.bootstrap."""
    n = len(data[0])
    if n < 3:
        raise ValueError(f"data: need at least 3 stimuli to bootstrap, got {n}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # constant resamples -> NaN, counted below
        warnings.simplefilter("ignore", scipy_stats.DegenerateDataWarning)
        result = scipy_stats.bootstrap(tuple(data), statistic, n_resamples=n_resamples, paired=True,
                                       vectorized=True, method="percentile", rng=rng, batch=1000)
    return np.asarray(result.bootstrap_distribution, float)


def bootstrap(statistic: Statistic, *data, n_resamples: int = BOOTSTRAP_RESAMPLES,
              rng: np.random.Generator) -> Estimate:
    """Median and 95% percentile interval of ``statistic(*data, axis=-1)`` over paired resamples."""
    arrays = [np.asarray(d, float) for d in data]
    dist = _bootstrap_distribution(statistic, arrays, n_resamples, rng)
    finite = dist[np.isfinite(dist)]
    point = float(statistic(*arrays, axis=-1))
    if len(finite) == 0:
        return Estimate(point=point, median=math.nan, lo=math.nan, hi=math.nan, resamples=0)
    lo, med, hi = np.percentile(finite, [2.5, 50, 97.5])
    return Estimate(point=point, median=float(med), lo=float(lo), hi=float(hi), resamples=int(len(finite)))


def bootstrap_pearson(x, y, *, n_resamples: int = BOOTSTRAP_RESAMPLES, rng: np.random.Generator) -> Estimate:
    x, y = _as_pair(x, y)
    return bootstrap(pearson, x, y, n_resamples=n_resamples, rng=rng)


def bootstrap_circular(a, b, *, n_resamples: int = BOOTSTRAP_RESAMPLES, rng: np.random.Generator) -> Estimate:
    a, b = _as_pair(a, b)
    return bootstrap(circular_correlation, a, b, n_resamples=n_resamples, rng=rng)


def bootstrap_fisher_lee(a, b, *, n_resamples: int = BOOTSTRAP_RESAMPLES, rng: np.random.Generator) -> Estimate:
    a, b = _as_pair(a, b)
    return bootstrap(fisher_lee_correlation, a, b, n_resamples=n_resamples, rng=rng)


def bootstrap_within(a, b, tolerance_rad: float, *, n_resamples: int = BOOTSTRAP_RESAMPLES,
                     rng: np.random.Generator) -> Estimate:
    a, b = _as_pair(a, b)
    return bootstrap(lambda x, y, axis=-1: fraction_within(x, y, tolerance_rad, axis=axis), a, b,
                     n_resamples=n_resamples, rng=rng)


@dataclass(frozen=True)
class Comparison:
    """A direct bootstrap test of ``first > second`` (both statistics on the same resamples).

    difference: the bootstrapped first - second. p_value: fraction of resamples with difference <= 0.
    """

    difference: Estimate
    p_value: float

    def to_dict(self) -> dict:
        return {"difference": self.difference.to_dict(), "p_value": self.p_value}


def bootstrap_compare(first: Statistic, second: Statistic, *data, n_resamples: int = BOOTSTRAP_RESAMPLES,
                      rng: np.random.Generator) -> Comparison:
    """Is statistic ``first`` larger than ``second`` on these stimuli? (e.g. r(IPE, people) vs
    r(features, people)); each receives all of ``data``, resampled together."""
    arrays = [np.asarray(d, float) for d in data]

    def difference(*args, axis=-1):
        return first(*args, axis=axis) - second(*args, axis=axis)

    dist = _bootstrap_distribution(difference, arrays, n_resamples, rng)
    finite = dist[np.isfinite(dist)]
    if len(finite) == 0:
        raise ValueError("data: no resample gave a defined difference (constant values?)")
    lo, med, hi = np.percentile(finite, [2.5, 50, 97.5])
    point = float(difference(*arrays, axis=-1))
    est = Estimate(point=point, median=float(med), lo=float(lo), hi=float(hi), resamples=int(len(finite)))
    return Comparison(difference=est, p_value=float(np.mean(finite <= 0)))


def anova_f_ratio(groups: Sequence[np.ndarray]) -> float:
    """One-way ANOVA F over stimuli (each group: one stimulus's per-sample model predictions).

    The SI's "variance of per-stimulus prediction means over the mean of per-stimulus prediction
    variances", with ANOVA's degrees of freedom (for equal group sizes n it is n times that ratio).
    Infinite when every stimulus's samples agree but the stimuli differ.
    """
    groups = [np.asarray(g, float) for g in groups if len(g)]
    if len(groups) < 2:
        raise ValueError("groups: need at least two stimuli with samples")
    within = sum(float(((g - g.mean()) ** 2).sum()) for g in groups)
    if within == 0:
        means = np.array([g.mean() for g in groups])
        return math.inf if np.ptp(means) > 0 else math.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy_stats.DegenerateDataWarning)
        return float(scipy_stats.f_oneway(*groups).statistic)


@dataclass(frozen=True)
class KEstimate:
    """Samples per judgment estimated from response variances (SI "Approximating Probabilities").

    k = 1 / slope and omega = sqrt(intercept) of variance_subjects = variance_model / k + omega^2,
    with bootstrap intervals over stimuli (k's upper end is inf when the slope's lower end is <= 0).
    """

    k: float
    k_ci95: tuple[float, float]
    omega: float
    omega_ci95: tuple[float, float]
    slope: float
    intercept: float
    stimuli: int

    def to_dict(self) -> dict:
        return {"k": self.k, "k_ci95": list(self.k_ci95), "omega": self.omega, "omega_ci95": list(self.omega_ci95),
                "slope": self.slope, "intercept": self.intercept, "stimuli": self.stimuli}


def _fit_line(x, y, axis=-1):
    """Least-squares slope and intercept along ``axis`` (``scipy.stats.linregress`` fits one line at a
    time; the bootstrap fits 10 000 at once)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    dx = x - x.mean(axis=axis, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = (dx * (y - y.mean(axis=axis, keepdims=True))).sum(axis=axis) / (dx * dx).sum(axis=axis)
    intercept = y.mean(axis=axis) - slope * x.mean(axis=axis)
    return slope, intercept


def _k_from_slope(slope: float) -> float:
    return 1.0 / slope if slope > 0 else math.inf


def estimate_k(model_variance, subject_variance, *, n_resamples: int = BOOTSTRAP_RESAMPLES,
               rng: np.random.Generator) -> KEstimate:
    """Fit subject_variance = model_variance / k + omega^2 over stimuli.

    model_variance: per stimulus, the variance of the model's single-sample (k = 1) responses.
    subject_variance: per stimulus, the variance of people's responses (same units, e.g. [0, 1]).
    """
    x, y = _as_pair(model_variance, subject_variance)
    if len(x) < 3 or np.ptp(x) == 0:
        raise ValueError("model_variance: need at least 3 stimuli whose model variances differ")
    slope, intercept = (float(v) for v in _fit_line(x, y))
    slopes = _bootstrap_distribution(lambda a, b, axis=-1: _fit_line(a, b, axis)[0], [x, y], n_resamples, rng)
    intercepts = _bootstrap_distribution(lambda a, b, axis=-1: _fit_line(a, b, axis)[1], [x, y], n_resamples, rng)
    s_lo, s_hi = (float(v) for v in np.nanpercentile(slopes, [2.5, 97.5]))
    i_lo, i_hi = (float(v) for v in np.nanpercentile(intercepts, [2.5, 97.5]))
    return KEstimate(k=_k_from_slope(slope), k_ci95=(_k_from_slope(s_hi), _k_from_slope(s_lo)),
                     omega=math.sqrt(max(intercept, 0.0)),
                     omega_ci95=(math.sqrt(max(i_lo, 0.0)), math.sqrt(max(i_hi, 0.0))),
                     slope=slope, intercept=intercept, stimuli=len(x))
