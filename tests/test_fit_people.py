"""``ipe fit`` (issue 74): the model's inputs fitted to people's responses. The fit must recover the
inputs of synthetic people made by the model itself, and refuse bad inputs in one line."""

import json
import subprocess
import sys

import numpy as np
import pytest

from ipe_ros.analysis.fitting.crossval import folds
from ipe_ros.analysis.fitting.fit import (PARAMETER_SET_FORMAT, FitSettings, evaluate_grid, fit_evaluations,
                                         parameter_set)
from ipe_ros.analysis.fitting.grid import evaluate
from ipe_ros.analysis.fitting.mapping import ResponseMapping, fit_mapping
from ipe_ros.analysis.fitting.readout import parse_readout
from ipe_ros.analysis.fitting.responses import Responses
from ipe_ros.cli import build_parser
from ipe_ros.cli_inputs import given_request_arguments
from ipe_ros.engine.errors import ConfigError
from ipe_ros.engine.input_sets import load_input_set
from ipe_ros.engine.scene.format import scene_from_dict, scene_to_dict

READOUT = parse_readout('contact_probability["puck:zone"]')
GRID = {"launch_speed_log_sd": (0.0, 0.2, 0.4), "launch_direction_sd_deg": (0.0, 10.0, 20.0)}
TRUTH = {"launch_speed_log_sd": 0.2, "launch_direction_sd_deg": 10.0}
PEOPLE = ResponseMapping(intercept=0.0, slope=1.5, lapse=0.04, samples=64)


def _stimulus(name: str, zone_x: float, zone_y: float) -> dict:
    """A puck launched at 1.5 m/s along +x stops after ~0.38 m (friction 0.6 x 0.5); does it touch a
    flat zone 0.25-0.45 m ahead, 0-0.12 m aside? Its launch's speed decides how far it gets, its
    direction how far aside."""
    return {"format": "ipe_ros.scene/2", "name": name, "gravity_m_s2": [0, 0, -9.81], "horizon_s": 0.6,
            "support": {"type": "floor", "height_m": 0.0, "friction": 0.5, "restitution": 0.0},
            "objects": [{"name": "puck", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.05]},
                         "position_m": [0, 0, 0.025], "orientation_xyzw": [0, 0, 0, 1], "friction": 0.6,
                         "restitution": 0.0, "mass_kg": 0.5, "linear_velocity_m_s": [1.5, 0, 0]},
                        {"name": "zone", "shape": {"type": "box", "extents_m": [0.06, 0.04, 0.01]},
                         "position_m": [zone_x, zone_y, 0.005], "orientation_xyzw": [0, 0, 0, 1], "friction": 0.6,
                         "restitution": 0.0, "static": True}]}


def _scenes():
    return [scene_from_dict(_stimulus(f"s{i}", x, y)) for i, (x, y) in
            enumerate((x, y) for x in (0.3, 0.36, 0.42, 0.48) for y in (0.0, 0.04, 0.08, 0.12))]


@pytest.fixture(scope="module")
def synthetic():
    """The grid evaluated once (k = 32, seed 0), and people's true P(yes): the model at TRUTH with
    other random numbers (k = 64, seed 99) through PEOPLE's mapping."""
    scenes = _scenes()
    evaluations, reference = evaluate_grid(scenes, READOUT, GRID, reference={}, samples=32, seed=0)
    truth = evaluate(scenes, READOUT, tuple(TRUTH.items()), fixed={}, samples=64, seed=99, preset_name="default")
    return scenes, evaluations, reference, PEOPLE.p_yes(truth.p_model)


def _people(scenes, p_yes: np.ndarray, seed: int, responders: int = 90) -> Responses:
    n = np.full(len(scenes), responders)
    yes = np.random.default_rng(seed).binomial(n, p_yes)
    return Responses(tuple(s.name for s in scenes), yes / n, n, None)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_fit_recovers_the_inputs_of_people_made_by_the_model(synthetic, seed):
    scenes, evaluations, reference, p_yes = synthetic
    assert len({tuple(e.p_model) for e in evaluations}) > 5  # the grid's points answer differently
    result = fit_evaluations(evaluations, reference, _people(scenes, p_yes, seed), READOUT,
                             FitSettings.of(GRID, samples=32, seed=seed, folds=3))
    for name, value in TRUTH.items():
        low, high = result.intervals[name]
        assert low <= value <= high, (name, result.intervals, result.parameters)
    # informative: exact launches fit these people worst but for the noisiest, and are not chosen
    assert result.parameters != {"launch_speed_log_sd": 0.0, "launch_direction_sd_deg": 0.0}
    assert result.loglik[0] < np.sort(result.loglik)[-3]
    assert result.cv.r > 0.5  # held out, the fitted model follows these people


def test_the_mapping_is_recovered_from_many_stimuli():
    rng = np.random.default_rng(0)
    p_model = rng.random(400)
    n = np.full(400, 90)
    truth = ResponseMapping(0.4, 1.5, 0.1, samples=16)
    mapping, _ = fit_mapping(p_model, rng.binomial(n, truth.p_yes(p_model)), n, samples=16)
    assert mapping.intercept == pytest.approx(0.4, abs=0.15)
    assert mapping.slope == pytest.approx(1.5, rel=0.15)
    assert mapping.lapse == pytest.approx(0.1, abs=0.03)


def test_folds_are_disjoint_and_cover_every_stimulus():
    parts = folds(23, 5, seed=4)
    assert sorted(np.concatenate(parts).tolist()) == list(range(23))
    assert [len(p) for p in parts] == [5, 5, 5, 4, 4]


@pytest.mark.slow
def test_the_parameter_set_loads_as_the_model_s_inputs(synthetic, tmp_path):
    scenes, evaluations, reference, p_yes = synthetic
    result = fit_evaluations(evaluations, reference, _people(scenes, p_yes, 5), READOUT,
                             FitSettings.of(GRID, {"sigma": 0.01}, samples=32, seed=5, folds=3))
    path = tmp_path / "fit.json"
    content = parameter_set(result, scenes_path="s.json", responses_path="p.csv")
    path.write_text(json.dumps(content))
    assert content["format"] == PARAMETER_SET_FORMAT
    assert content["provenance"]["intervals_95"].keys() == GRID.keys()
    loaded = load_input_set(path)
    assert loaded == {"sigma_m": 0.01, **{k: result.parameters[k] for k in GRID}}
    # a flag typed on the command line wins over the file; the others come from it
    argv = ["predict", "x.json", "--inputs-from", str(path), "--sigma", "0.03"]
    args = build_parser().parse_args(argv)
    args.argv = tuple(argv)
    given = given_request_arguments(args)
    assert given["sigma_m"] == 0.03
    assert given["launch_direction_sd_deg"] == result.parameters["launch_direction_sd_deg"]


def test_a_parameter_set_that_is_no_file_is_refused_without_waiting_on_it(tmp_path):
    """Issue 76 (the next inputs through the same bounds): a FIFO as the node's inputs_from (or
    --inputs-from) is refused at once, not waited on; a device is not read without end."""
    import os

    fifo = tmp_path / "fit.json"
    os.mkfifo(fifo)
    for path, message in ((fifo, f"inputs_from: {fifo} is not a regular file (a folder, a FIFO or a device)"),
                          (tmp_path / "none.json", f"inputs_from: {tmp_path / 'none.json'}: no such file"),
                          ("/dev/zero", "inputs_from: /dev/zero is not a regular file (a folder, a FIFO or a device)")):
        with pytest.raises(ConfigError) as caught:
            load_input_set(path)
        assert str(caught.value) == message


# ---- bad inputs, each refused in one line ---------------------------------------------------------


def _files(tmp_path, rows: list[str]) -> tuple[str, str]:
    scenes = tmp_path / "scenes.json"
    scenes.write_text(json.dumps([scene_to_dict(s) for s in _scenes()[:4]]))
    people = tmp_path / "people.csv"
    people.write_text("stimulus,people_p_yes,responders\n" + "\n".join(rows) + "\n")
    return str(scenes), str(people)


GOOD = ["s0,0.9,90", "s1,0.5,90", "s2,0.2,90", "s3,0.1,90"]


@pytest.mark.parametrize("rows, readout, message", [
    (GOOD[:3] + ["ghost,0.5,90"], 'contact_probability["puck:zone"]',
     "--responses: stimulus 'ghost' has no scene of that name: give the scenes file the responses were collected on"),
    (GOOD[:3] + ["s3,1.2,90"], 'contact_probability["puck:zone"]',
     "--responses: people.csv line 5: people_p_yes must be a share in 0..1, got 1.2"),
    (GOOD[:3] + ["s3,0.5,0"], 'contact_probability["puck:zone"]',
     "--responses: people.csv line 5: responders must be a whole number >= 1, got 0"),
    (GOOD, "far_m", "--readout: 'far_m' is not a probability an answer gives; one of any_fall_probability, "
                    "contact_probability, fall_fraction, object_fall_probability, rest_probability, "
                    "tipped_object_probability, tipped_probability"),
    (GOOD, 'object_fall_probability["ghost"]',
     "--readout: s0's answer has no object_fall_probability[\"ghost\"] (its object_fall_probability has 'puck')"),
])
def test_bad_inputs_are_refused_in_one_line(tmp_path, rows, readout, message):
    scenes, people = _files(tmp_path, rows)
    done = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "fit", scenes, "--responses", people, "--readout",
                           readout, "--grid", "sigma=0,0.01", "--samples", "1", "--folds", "2", "--workers", "0",
                           "-o", str(tmp_path / "fit.json")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.strip().splitlines()[-1] == f"ipe: error: {message}"
    assert not (tmp_path / "fit.json").exists()


def test_a_grid_of_one_value_is_refused(tmp_path):
    scenes, people = _files(tmp_path, GOOD)
    done = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "fit", scenes, "--responses", people, "--readout",
                           'contact_probability["puck:zone"]', "--grid", "sigma=0.01", "--workers", "0"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip() == "ipe: error: --grid: sigma: give two or more different values, got [0.01]"
