"""`ipe experiment NAME --quick`: every report runs end to end and says what the paper's analyses say.

These are the CI-sized forms; the full forms (paper sizes) run outside CI from the same command.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from ipe_ros.analysis.experiments import EXPERIMENTS

from .conftest import SHARED_DATA

#: the paper's analyses, small
pytestmark = pytest.mark.slow


def run_cli(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "ipe_ros.cli", "experiment", *args], capture_output=True,
                          text=True, timeout=timeout)


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    out = tmp_path_factory.mktemp("experiments")
    result = run_cli("all", "--quick", "--workers", "2", "--out", str(out), "--resamples", "2000")
    assert result.returncode == 0, result.stderr[-3000:]
    return out, {name: json.loads((out / f"{name}.json").read_text()) for name in EXPERIMENTS}


def test_every_report_writes_json_markdown_and_its_figures(reports):
    out, data = reports
    for name, report in data.items():
        assert report["experiment"] == name
        assert report["parameters"]["seed"] == 0 and report["parameters"]["quick"] is True
        text = (out / f"{name}.md").read_text()
        assert text.startswith("# ") and "Parameters: seed = 0" in text
        for figure in report["figures"]:
            assert (out / figure).stat().st_size > 1000
    assert {"fall_sigma_phi_grid.png", "bump_disks.png", "samples_by_k.png"} <= {
        f for r in data.values() for f in r["figures"]}


def test_fall_report_compares_ipe_and_ground_truth(reports):
    fall = reports[1]["fall"]["results"]
    ipe, truth = np.array(fall["ipe_fall_fraction"]), np.array(fall["ground_truth_fall_fraction"])
    assert ipe.shape == truth.shape and np.all((ipe >= 0) & (ipe <= 1))
    grid = np.array(fall["grid"]["r_with_fitted_ipe"], dtype=float)
    assert grid.shape == (len(fall["grid"]["phi_paper"]), len(fall["grid"]["sigma_sides"]))
    assert np.nanmax(grid) > 0.5  # settings near the fitted one agree with it
    assert fall["failed_samples"] == 0


def test_direction_report_applies_the_decisiveness_rule(reports):
    d = reports[1]["direction"]["results"]
    decisiveness = np.array(d["decisiveness"], dtype=float)
    assert d["decisive"] == int(np.sum(decisiveness >= 0.8)) and d["included"] <= d["decisive"]
    assert np.all((decisiveness >= 0.5) & (decisiveness <= 1.0))  # a half circle holds at least half
    if d["included"] >= 3:
        within = d["within_45_deg_included"]
        assert 0.0 <= within["ci95"][0] <= within["median"] <= within["ci95"][1] <= 1.0
        assert -1.0 <= d["fisher_lee_r_included"]["median"] <= 1.0


def test_mass_insensitive_model_cannot_tell_state_pairs_apart(reports):
    if not (SHARED_DATA / "willitfall-mass.csv").exists():
        pytest.skip(f"{SHARED_DATA} is absent: the state pairs are the authors' stimuli")
    mass = reports[1]["mass"]["results"]
    assert mass["exp3"]["by_mu"]["1"]["max_abs_pair_difference"] == 0.0
    assert mass["exp3"]["by_mu"]["10"]["mean_abs_pair_difference"] > 0.0


def test_far_report_gives_both_f_ratios(reports):
    far = reports[1]["far"]["results"]
    assert far["f_ratio_far"] > 0 and far["f_ratio_fall"] > 0
    assert len(far["ipe_far_m"]) == len(far["tower_height_m"])


def test_bump_report_knocks_more_blocks_off_with_a_harder_bump(reports):
    bump = reports[1]["bump"]["results"]
    assert bump["blocks_fell_off_at_highest_phi"] > bump["blocks_fell_off_at_lowest_phi"]
    ratio = np.array(bump["grid_ratio"], dtype=float)
    finite = ratio[np.isfinite(ratio)]
    assert finite.size and np.all((finite >= 0) & (finite <= 1))


def test_bump_grid_does_not_depend_on_how_tables_are_grouped_into_maps(monkeypatch, tmp_path):
    # Tables share maps (several scenes' samples in one predict_many); each cell must still get its own
    # table's and direction's samples, whichever grouping the map size allows.
    from ipe_ros.analysis import runs
    from ipe_ros.analysis.experiments import bump
    from ipe_ros.analysis.experiments.common import Options
    from ipe_ros.engine.scene.generators import generate_tables

    scenes = generate_tables(seed=3, configurations=2, tables=("T0", "T1"))[:3]
    directions, phis = np.array([0.0, np.pi]), (22.0, 76.0)
    opts = Options(out_dir=tmp_path, data_dir=tmp_path)
    grids = []
    for per_map in (2 * 2, 3 * 2 * 2):  # one table per map, then all three in one
        monkeypatch.setattr(runs, "SAMPLES_PER_MAP", per_map)
        grids.append(bump.bump_grid(scenes, directions, phis, 2, opts, None, "test"))
    one_by_one, together = grids
    for field in ("ratio", "fell_off", "ratio_sum", "ratio_count"):
        np.testing.assert_array_equal(getattr(one_by_one, field), getattr(together, field), err_msg=field)
    alone = bump.bump_grid(scenes[2:], directions[1:], phis, 2, opts, None, "test")  # the last cell on its own
    np.testing.assert_array_equal(alone.fell_off[0, 0], together.fell_off[2, 1])
    assert not np.array_equal(together.fell_off[0], together.fell_off[2])  # different scenes, different cells


def test_samples_report_has_a_curve_per_experiment_and_recovers_k(reports):
    samples = reports[1]["samples"]["results"]
    assert "Exp. 1" in samples["correlation_by_k"] and len(samples["correlation_by_k"]["Exp. 1"]) == 10
    k = samples["k_estimate_synthetic"]["Exp. 1"]
    assert k["k_ci95"][0] <= 4 <= (k["k_ci95"][1] or float("inf"))  # JSON null is an infinite upper end


def test_features_report_fits_ridge_to_the_ipe(reports):
    features = reports[1]["features"]["results"]
    assert set(features["exp1"]["single_feature_r"]) == {"F_F1_height_m", "F_F2_com_height_m",
                                                         "F_F3_critical_angle_rad", "F_F4_min_subtower_angle_rad"}
    assert -1 <= features["exp1"]["ridge_held_out_r"]["median"] <= 1
    if (SHARED_DATA / "willitfall-mass.csv").exists():  # mass-sensitive features under assumed mu
        assert set(features["exp3"]["by_mu"]) == {"1", "10"}


def test_vision_report_compares_the_vision_posterior_with_sigma(reports):
    vision = reports[1]["vision"]["results"]
    for label in ("Exp. 1 (will it fall?)", "Exp. 2 (direction, circular)"):
        part = vision[label]
        spread = np.array(part["vision_spread_m"], dtype=float)
        assert spread.shape[0] == len(part["towers"]) and np.all(spread > 0) and np.all(spread < 1.0)
        assert all(0 < a < 1 for a in part["acceptance"])
    # a wider blur leaves the blocks less constrained: the spread grows with it
    assert np.all(np.diff(np.array(vision["blur_spread_m"], dtype=float)) > 0)
    assert vision["blur_px"][0] <= vision["matching_blur_px"] <= vision["blur_px"][-1]


def test_a_human_table_gets_correlated_with_the_model(tmp_path, reports):
    """People who answer with the IPE's own prediction plus noise correlate with it."""
    fall = reports[1]["fall"]["results"]
    rng = np.random.default_rng(0)
    lines = ["stimulus,response"]
    for name, p in zip(fall["towers"], fall["ipe_fall_fraction"]):
        for _ in range(5):
            lines.append(f"{name},{min(1.0, max(0.0, p + 0.05 * rng.normal())):.4f}")
    human = tmp_path / "people.csv"
    human.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    result = run_cli("fall", "--quick", "--workers", "2", "--out", str(out), "--resamples", "1000",
                     "--human", str(human), "--human-scale", "unit")
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads((out / "fall.json").read_text())
    assert report["results"]["human"]["correlations"]["IPE"]["point"] > 0.9
    assert "Against the human responses" in (out / "fall.md").read_text()


@pytest.mark.parametrize("args, message", [
    (["fall", "--human", "x.csv"], "ipe: error: --human-scale: give --human FILE and --human-scale SCALE together"),
    (["fall", "--samples", "0"], "ipe: error: --samples: must be >= 1, got 0"),
    (["fall", "--human", "missing.csv", "--human-scale", "unit"], "ipe: error: --human: no such file 'missing.csv'"),
])
def test_bad_experiment_arguments_end_with_one_line(args, message):
    result = run_cli(*args, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip() == message
