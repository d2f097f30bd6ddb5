"""Statistics of Monte Carlo answers: 95% intervals of means and fractions, circular statistics.

Pure numpy (scipy's t quantile on demand); shared by the queries, the sequential decisions and the
analyses.
"""

from __future__ import annotations

import math

import numpy as np

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
