"""Statistics on inputs whose answers are known."""

import math

import numpy as np
import pytest

from ipe_ros.engine.sampling.estimate import circular_mean, half_circle_decisiveness, mean_interval, wilson_interval


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(0.0, 48)
    assert lo == 0.0 and hi == pytest.approx(0.0741, abs=1e-3)
    lo, hi = wilson_interval(0.5, 100)
    assert (lo, hi) == pytest.approx((0.4038, 0.5962), abs=1e-3)


def test_wilson_interval_covers_the_truth_about_95_percent():
    # fixed seed; 2000 experiments of k = 48 Bernoulli(0.3) draws; tolerance: coverage in [0.93, 0.97]
    rng = np.random.default_rng(0)
    draws = rng.random((2000, 48)) < 0.3
    covered = [lo <= 0.3 <= hi for lo, hi in (wilson_interval(d.mean(), 48) for d in draws)]
    assert 0.93 <= np.mean(covered) <= 0.97


def test_mean_interval():
    assert mean_interval(np.array([1.0])) == (1.0, 1.0)
    lo, hi = mean_interval(np.array([0.0, 2.0]))
    # Student t with 1 degree of freedom: 12.706, not the normal 1.96
    assert lo == pytest.approx(1 - 12.7062047 * math.sqrt(2) / math.sqrt(2), abs=1e-6) and hi == pytest.approx(2 - lo)


def test_circular_mean_wraps_around():
    assert circular_mean(np.array([math.radians(350), math.radians(10)])) == pytest.approx(0.0, abs=1e-12)
    assert circular_mean(np.array([0.0, math.pi])) is None
    assert circular_mean(np.array([])) is None


def test_half_circle_decisiveness():
    assert half_circle_decisiveness(np.array([0.1, 0.2, 0.3])) == 1.0
    spread = np.linspace(0, 2 * math.pi, 8, endpoint=False)  # 8 evenly spaced: a closed half holds 5
    assert half_circle_decisiveness(spread) == 5 / 8
    assert half_circle_decisiveness(np.array([3.0, -3.0, 3.1])) == 1.0  # all near pi, across the +-pi seam
    assert half_circle_decisiveness(np.array([0.0, 3.0, -3.0])) == 2 / 3
    assert half_circle_decisiveness(np.array([])) is None


def test_the_wilson_interval_is_scipys_for_counts():
    from scipy.stats import binomtest

    from ipe_ros.engine.sampling.estimate import wilson_interval

    for n in (1, 5, 48):
        for count in range(n + 1):
            ours = wilson_interval(count / n, n)
            theirs = binomtest(count, n).proportion_ci(confidence_level=0.95, method="wilson")
            assert ours == pytest.approx((theirs.low, theirs.high), abs=1e-6), (count, n)
