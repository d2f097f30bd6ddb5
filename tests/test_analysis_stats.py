"""The analysis statistics, features and ridge regression on synthetic data whose answer is known.

Statistical checks use fixed seeds and state their tolerances.
"""

import math

import numpy as np
import pytest
from scipy import stats as scipy_stats

from ipe_ros.analysis import stats
from ipe_ros.analysis.features import critical_angle, subtowers, table_features, tower_features
from ipe_ros.analysis.human import load_human_responses
from ipe_ros.analysis.ridge import cross_validated_ridge
from ipe_ros.engine import Box, Floor, Scene
from ipe_ros.engine.scene.generators import make_table

IDENTITY = (0.0, 0.0, 0.0, 1.0)


# ---------------------------------------------------------------- correlations


def test_circular_correlation_of_a_rotated_copy_is_one_and_of_a_reflection_minus_one():
    rng = np.random.default_rng(0)
    a = rng.vonmises(0.5, 2.0, size=200)
    for shift in (0.0, 1.0, math.pi, -2.5):
        assert stats.circular_correlation(a, a + shift) == pytest.approx(1.0, abs=1e-12)
    assert stats.circular_correlation(a, 0.3 - a) == pytest.approx(-1.0, abs=1e-12)
    # wrapping does not matter: the same angles written in [0, 2 pi) or (-pi, pi]
    assert stats.circular_correlation(np.mod(a, 2 * math.pi), a + 4 * math.pi) == pytest.approx(1.0, abs=1e-12)


def test_circular_correlation_of_independent_angles_is_near_zero():
    rng = np.random.default_rng(1)
    a, b = rng.uniform(-math.pi, math.pi, (2, 4000))
    assert abs(stats.circular_correlation(a, b)) < 0.05  # sd ~ 1/sqrt(4000) = 0.016


def test_fisher_lee_correlation_matches_its_pairwise_definition_and_is_rotation_invariant():
    rng = np.random.default_rng(11)
    a = rng.uniform(-math.pi, math.pi, 12)
    b = a + rng.vonmises(0.0, 3.0, 12)
    num = sum(math.sin(a[i] - a[j]) * math.sin(b[i] - b[j]) for i in range(12) for j in range(i + 1, 12))
    saa = sum(math.sin(a[i] - a[j]) ** 2 for i in range(12) for j in range(i + 1, 12))
    sbb = sum(math.sin(b[i] - b[j]) ** 2 for i in range(12) for j in range(i + 1, 12))
    assert stats.fisher_lee_correlation(a, b) == pytest.approx(num / math.sqrt(saa * sbb), abs=1e-12)
    for shift in (0.0, 1.0, -2.5):
        assert stats.fisher_lee_correlation(a, a + shift) == pytest.approx(1.0, abs=1e-12)
    assert stats.fisher_lee_correlation(a, 0.3 - a) == pytest.approx(-1.0, abs=1e-12)
    x, y = rng.uniform(-math.pi, math.pi, (2, 1500))
    assert abs(stats.fisher_lee_correlation(x, y)) < 0.06  # sd ~ 1/sqrt(1500) = 0.026


def test_fisher_lee_interval_stays_narrow_where_directions_spread_round_the_circle():
    """Uniform directions plus von Mises noise (kappa 4), 50 stimuli, seed 5: the J-S interval reaches
    below 0 because the circular mean it subtracts is ill-defined; the Fisher-Lee one stays above 0.4."""
    rng = np.random.default_rng(5)
    a = rng.uniform(-math.pi, math.pi, 50)
    b = a + rng.vonmises(0.0, 4.0, 50)
    js = stats.bootstrap_circular(a, b, n_resamples=2000, rng=np.random.default_rng(1))
    fl = stats.bootstrap_fisher_lee(a, b, n_resamples=2000, rng=np.random.default_rng(1))
    assert js.lo < 0 < 0.4 < fl.lo
    assert fl.hi - fl.lo < 0.4


def test_fraction_within_counts_wrapped_angular_differences():
    a = np.array([0.0, 3.1, -3.1, 1.0])
    b = np.array([0.7, -3.1, 3.1, 2.0])  # differences 0.7, 0.083 (across +-pi), 0.083, 1.0
    assert stats.fraction_within(a, b, math.pi / 4) == pytest.approx(0.75)
    assert stats.angular_difference(3.1, -3.1) == pytest.approx(6.2 - 2 * math.pi)


def test_pearson_matches_scipy_and_is_nan_for_constant_input():
    rng = np.random.default_rng(2)
    x, y = rng.normal(size=(2, 50))
    assert stats.pearson(x, y) == pytest.approx(scipy_stats.pearsonr(x, y).statistic, abs=1e-12)
    assert math.isnan(stats.pearson(np.ones(5), np.arange(5)))


def test_bootstrap_interval_covers_the_true_correlation_about_95_percent_of_the_time():
    """200 data sets of 40 stimuli with rho = 0.6; percentile intervals from 1000 resamples each.
    The percentile interval of r under-covers slightly at n = 40; accept 88-99% (binomial sd 1.5%)."""
    rng = np.random.default_rng(3)
    rho, n, datasets = 0.6, 40, 200
    cov = [[1, rho], [rho, 1]]
    covered = 0
    for _ in range(datasets):
        x, y = rng.multivariate_normal([0, 0], cov, size=n).T
        est = stats.bootstrap_pearson(x, y, n_resamples=1000, rng=rng)
        covered += est.lo <= rho <= est.hi
        assert est.lo <= est.median <= est.hi and est.resamples == 1000
    assert 0.88 <= covered / datasets <= 0.99


def test_bootstrap_rejects_too_few_stimuli():
    with pytest.raises(ValueError, match="need at least 3 stimuli"):
        stats.bootstrap_pearson([0.1, 0.2], [0.3, 0.1], rng=np.random.default_rng(0))


def test_bootstrap_test_prefers_the_better_predictor():
    rng = np.random.default_rng(4)
    truth = rng.normal(size=60)
    good = truth + 0.3 * rng.normal(size=60)
    poor = truth + 2.0 * rng.normal(size=60)

    def r_first(a, b, t, axis=-1):
        return stats.pearson(a, t, axis=axis)

    def r_second(a, b, t, axis=-1):
        return stats.pearson(b, t, axis=axis)

    better = stats.bootstrap_compare(r_first, r_second, good, poor, truth, n_resamples=2000, rng=rng)
    worse = stats.bootstrap_compare(r_second, r_first, good, poor, truth, n_resamples=2000, rng=rng)
    assert better.p_value < 0.01 and better.difference.lo > 0
    assert worse.p_value > 0.99


def test_anova_f_ratio_is_scipys_and_the_sis_ratio_times_group_size():
    rng = np.random.default_rng(5)
    groups = [rng.normal(loc=m, scale=1.0, size=48) for m in rng.normal(size=30)]
    f = stats.anova_f_ratio(groups)
    assert f == pytest.approx(scipy_stats.f_oneway(*groups).statistic, rel=1e-12)
    means = np.array([g.mean() for g in groups])
    variances = np.array([g.var(ddof=1) for g in groups])
    assert f == pytest.approx(48 * means.var(ddof=1) / variances.mean(), rel=1e-12)
    assert stats.anova_f_ratio([np.zeros(4), np.ones(4)]) == math.inf


@pytest.mark.parametrize("k_true", [1, 4, 7])
def test_k_is_recovered_from_response_variances(k_true):
    """People who average k Bernoulli samples and add N(0, 0.1): 60 stimuli, 1000 responses each.
    Tolerance: k within 25%, omega^2 (the intercept) within 0.005."""
    rng = np.random.default_rng(10 + k_true)
    p = rng.uniform(0.05, 0.95, 60)
    omega = 0.1
    model_var = p * (1 - p)  # the variance of one sample's outcome
    responses = rng.binomial(k_true, p[:, None], size=(60, 1000)) / k_true + omega * rng.normal(size=(60, 1000))
    est = stats.estimate_k(model_var, responses.var(axis=1, ddof=1), n_resamples=2000, rng=rng)
    assert est.k == pytest.approx(k_true, rel=0.25)
    assert est.intercept == pytest.approx(omega ** 2, abs=0.005)
    assert est.k_ci95[0] <= est.k <= est.k_ci95[1]


# ---------------------------------------------------------------- features


def _box(name, ext, pos, group="light"):
    return Box(name=name, extents_m=ext, position_m=pos, orientation_xyzw=IDENTITY, mass_kg=None,
               density_kg_m3=170.0, friction=0.9, restitution=0.0, group=group)


def _tower(*boxes):
    return Scene(name="hand_built", objects=tuple(boxes), support=Floor(friction=1.0, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.8))


def test_critical_angle_of_an_upright_block_is_atan_half_width_over_com_height():
    scene = _tower(_box("b", (0.2, 0.2, 0.6), (0.0, 0.0, 0.3)))
    f = tower_features(scene)
    assert f["F_F1_height_m"] == pytest.approx(0.6)
    assert f["F_F2_com_height_m"] == pytest.approx(0.3)
    assert f["F_F3_critical_angle_rad"] == pytest.approx(math.atan2(0.1, 0.3), abs=1e-9)


def test_critical_angle_of_an_offset_stack_points_towards_the_overhang():
    # a lying block, and an equal block on it shifted 0.05 m along +x: COM x = 0.025, z = 0.2
    scene = _tower(_box("bottom", (0.2, 0.6, 0.2), (0.0, 0.0, 0.1)), _box("top", (0.2, 0.6, 0.2), (0.05, 0.0, 0.3)))
    f = tower_features(scene)
    assert f["F_F3_critical_angle_rad"] == pytest.approx(math.atan2(0.1 - 0.025, 0.2), abs=1e-9)
    assert f["F_D1_critical_direction_rad"] == pytest.approx(0.0, abs=1e-9)


def test_critical_angle_is_negative_when_the_centre_of_mass_overhangs_the_base():
    # a 0.2 m cube under a 0.6 m bar centred at x = 0.25: COM x = 0.1875 (outside x <= 0.1), z = 0.25
    scene = _tower(_box("cube", (0.2, 0.2, 0.2), (0.0, 0.0, 0.1)), _box("bar", (0.6, 0.2, 0.2), (0.25, 0.0, 0.3)))
    f = tower_features(scene)
    assert f["F_F3_critical_angle_rad"] == pytest.approx(math.atan2(-0.0875, 0.25), abs=1e-9)
    assert f["F_D1_critical_direction_rad"] == pytest.approx(0.0, abs=1e-9)


def test_subtowers_are_the_groups_that_touch_and_the_minimum_angle_is_the_worst_one():
    safe = _box("safe", (0.2, 0.2, 0.2), (-1.0, 0.0, 0.1))
    tall_bottom = _box("tall0", (0.2, 0.2, 0.2), (1.0, 0.0, 0.1))
    tall_top = _box("tall1", (0.2, 0.2, 0.2), (1.08, 0.0, 0.3))  # overhangs +x by 0.08 m
    scene = _tower(safe, tall_bottom, tall_top)
    groups = sorted(sorted(b.name for b in g) for g in subtowers(scene))
    assert groups == [["safe"], ["tall0", "tall1"]]
    f = tower_features(scene)
    # the tall pair: COM x = 1.04, z = 0.2, nearest edge x = 1.1 -> atan(0.06 / 0.2), towards +x
    assert f["F_F4_min_subtower_angle_rad"] == pytest.approx(math.atan2(0.06, 0.2), abs=1e-9)
    assert f["F_D2_subtower_direction_rad"] == pytest.approx(0.0, abs=1e-9)
    assert f["F_F4_min_subtower_angle_rad"] < math.atan2(0.1, 0.1)  # the lone cube's angle is 45 degrees


def test_critical_angle_of_a_point_base_is_negative():
    angle = critical_angle(np.array([[0.0, 0.0]]), np.array([0.1, 0.0, 0.5]), 0.0)
    assert angle.angle_rad < 0 and angle.direction_rad == pytest.approx(0.0)


def test_table_features_compare_red_blocks_with_all_blocks():
    table = make_table("T1")  # walls along +x and -x
    red = _box("r", (0.2, 0.2, 0.2), (0.0, 0.0, 0.1), group="red")
    yellow = _box("y", (0.2, 0.2, 0.2), (0.0, 0.65, 0.1), group="yellow")  # near the open +y edge
    scene = Scene(name="t", objects=(red, yellow), support=table, gravity_m_s2=(0.0, 0.0, -9.8))
    f = table_features(scene, group="red")
    assert f["F_B2"] == pytest.approx(0.0 / 0.325)  # red at the centre, mean xy distance of all 0.325
    assert f["F_B3"] == pytest.approx(1.0)  # same heights
    assert f["F_B5"] == pytest.approx(0.8 / ((0.8 + 0.15) / 2))  # xy distance to the nearest edge
    with pytest.raises(ValueError, match="no box in group 'blue'"):
        table_features(scene, group="blue")


# ---------------------------------------------------------------- ridge


def test_ridge_recovers_a_linear_target_and_not_noise():
    rng = np.random.default_rng(6)
    x = rng.normal(size=(60, 4))
    y = x @ np.array([1.0, -2.0, 0.5, 0.0]) + 0.1 * rng.normal(size=60)
    fit = cross_validated_ridge(x, y, rng=rng)
    assert stats.pearson(fit.held_out, y) > 0.97
    noise = rng.normal(size=60)
    assert stats.pearson(cross_validated_ridge(x, noise, rng=rng).held_out, noise) < 0.4
    with pytest.raises(ValueError, match="need at least 10 stimuli"):
        cross_validated_ridge(x[:6], y[:6], rng=rng)


# ---------------------------------------------------------------- human table


def test_human_table_is_rescaled_and_summarised(tmp_path):
    path = tmp_path / "people.csv"
    path.write_text("subject,stimulus,response\n1,a,1\n2,a,7\n1,b,4\n2,b,4\n")
    human = load_human_responses(path, "1-7")
    assert human.mean == {"a": 0.5, "b": 0.5}
    assert human.variance["a"] == pytest.approx(0.5) and human.variance["b"] == 0.0
    degrees = tmp_path / "dirs.csv"
    degrees.write_text("stimulus,response\na,350\na,10\n")
    assert load_human_responses(degrees, "degrees").mean["a"] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("text, scale, message", [
    ("stimulus,answer\na,1\n", "1-7", "lacks the column(s) response"),
    ("stimulus,response\na,9\n", "1-7", "line 2: response 9 is outside the 1-7 scale"),
    ("stimulus,response\na,x\n", "unit", "line 2: response 'x' is not a number"),
])
def test_bad_human_tables_name_the_problem(tmp_path, text, scale, message):
    path = tmp_path / "people.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_human_responses(path, scale)


def test_report_tables_escape_pipes_and_print_missing_numbers_as_dashes():
    from ipe_ros.analysis.report import Report
    report = Report("t", "title", {"seed": 0})
    report.table(["mean |d|", "r"], [["a|b", float("nan")], ["c", 0.5]])
    rows = [line for line in report.lines if line.startswith("|")]
    assert rows[0] == "| mean \\|d\\| | r |"
    assert rows[2:] == ["| a\\|b | - |", "| c | 0.500 |"]
