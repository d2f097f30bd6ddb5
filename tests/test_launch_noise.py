"""Uncertain launches (issue 74, item 2): the speed and direction of what moves at t = 0 drawn per
sample, off by default (answers as before), each object's draws on a stream of its own."""

import math
import subprocess
import sys

import numpy as np
import pytest

from ipe_ros.engine import predict
from ipe_ros.engine import Request
from ipe_ros.engine.errors import ConfigError
from ipe_ros.engine.request import build_request
from ipe_ros.engine.sampling.perturb import draw_sample, is_deterministic
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.scene.format import scene_from_dict
from ipe_ros.engine.scene.launches import LaunchSpread, draw_launch

SPEED_M_S = 2.0


def _box(name: str, y: float, velocity=(SPEED_M_S, 0.0, 0.0)) -> dict:
    return {"name": name, "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.05]}, "position_m": [0.0, y, 0.025],
            "orientation_xyzw": [0, 0, 0, 1], "friction": 0.5, "restitution": 0.0, "mass_kg": 1.0,
            "linear_velocity_m_s": list(velocity), "angular_velocity_rad_s": [0.0, 0.0, 1.0]}


def _scene(*boxes: dict):
    return scene_from_dict({"format": "ipe_ros.scene/2", "name": "slide", "gravity_m_s2": [0, 0, -9.81],
                            "support": {"type": "floor", "height_m": 0.0, "friction": 1.0, "restitution": 0.0},
                            "objects": list(boxes or [_box("box", 0.0)])})


def _model(**inputs):
    return build_request(**{"samples": 64, "sigma_m": 0.0, "queries": ("far",), "self_check": False, **inputs}).model


def test_off_by_default_the_scene_is_drawn_as_given_and_stays_deterministic():
    scene = _scene()
    model = _model()
    assert model.launch_spread is None
    drawn, inputs = draw_sample(scene, model, np.random.SeedSequence(1).spawn(1)[0])
    assert drawn is scene and inputs.properties == ()
    assert is_deterministic(scene, model)
    assert not is_deterministic(scene, _model(launch_direction_sd_deg=5.0))
    # nothing moves at t = 0: nothing to draw, still one rollout
    still = _scene(_box("box", 0.0, velocity=(0.0, 0.0, 0.0)) | {"angular_velocity_rad_s": [0, 0, 0]})
    assert is_deterministic(still, _model(launch_direction_sd_deg=5.0))


def test_the_ground_truth_takes_launches_as_given():
    request = build_request(ground_truth=True, launch_speed_log_sd=0.3, launch_direction_sd_deg=10.0)
    assert request.model.launch_spread is None


def test_a_launch_is_turned_and_scaled_as_one_push_and_other_draws_are_unchanged():
    scene = _scene()
    seed = np.random.SeedSequence(7).spawn(3)[2]
    plain_scene, plain = draw_sample(scene, _model(sigma_m=0.01), seed)
    drawn_scene, drawn = draw_sample(scene, _model(sigma_m=0.01, launch_speed_log_sd=0.2,
                                                   launch_direction_sd_deg=20.0), seed)
    np.testing.assert_array_equal(drawn.positions_m, plain.positions_m)  # the main stream untouched
    factor, turn = draw_launch("box", LaunchSpread(0.2, math.radians(20.0)), seed)
    assert dict(drawn.properties) == {"box.launch_speed_factor": factor, "box.launch_turn_rad": turn}
    body = drawn_scene.objects[0]
    assert body.linear_velocity_m_s == pytest.approx((factor * SPEED_M_S * math.cos(turn),
                                                      factor * SPEED_M_S * math.sin(turn), 0.0))
    assert body.angular_velocity_rad_s == pytest.approx((0.0, 0.0, factor))  # a spin about z turns into itself


def test_each_object_s_launch_depends_on_its_seed_and_name_only():
    seed = np.random.SeedSequence(3).spawn(5)[4]
    model = _model(launch_direction_sd_deg=15.0)
    alone, _ = draw_sample(_scene(_box("a", 0.0)), model, seed)
    pair, _ = draw_sample(_scene(_box("b", 0.5), _box("a", 0.0)), model, seed)
    assert pair.objects[1].linear_velocity_m_s == alone.objects[0].linear_velocity_m_s
    assert pair.objects[0].linear_velocity_m_s != alone.objects[0].linear_velocity_m_s


def test_the_slides_spread_as_the_launches_do():
    """A box launched at 2 m/s slides straight on to v^2 / (2 mu g): its heading's SD is the direction
    SD, its distance's log SD twice the speed's (64 samples: SDs within 25%, about 3 standard errors)."""
    scene = _scene(_box("box", 0.0) | {"angular_velocity_rad_s": [0, 0, 0]})
    request = build_request(samples=64, sigma_m=0.0, queries=("final_pose",), self_check=False,
                            launch_speed_log_sd=0.1, launch_direction_sd_deg=10.0, seed=5)
    prediction = predict(scene,
                         Request(model=request.model, settings=request.settings, query=request.query,
                                 seed=request.seed, check=None, budget_s=None))
    moved = np.array([o.rollouts[0].final_positions_m[0, :2] - o.initial_positions_m[0, :2]
                      for o in prediction.outcomes if o.ok])
    assert len(moved) == 64
    heading_sd = np.std(np.arctan2(moved[:, 1], moved[:, 0]), ddof=1)
    assert heading_sd == pytest.approx(math.radians(10.0), rel=0.25)
    assert np.std(np.log(np.linalg.norm(moved, axis=1)), ddof=1) == pytest.approx(2 * 0.1, rel=0.25)
    assert request.model.launch_spread == LaunchSpread(0.1, math.radians(10.0))


@pytest.mark.parametrize("fields, flag, message", [
    ({"launch_speed_log_sd": -0.1}, "--launch-speed-log-sd", "must be a number in [0, 1.5] (0: exact), got -0.1"),
    ({"launch_direction_sd_deg": math.inf}, "--launch-direction-sd", "must be degrees in [0, 180] (0: exact), got inf"),
])
def test_bad_spreads_are_refused_naming_the_option(fields, flag, message):
    from ipe_ros.engine.inputs import as_spelled

    with pytest.raises(ConfigError) as caught:
        build_request(**fields)
    assert str(as_spelled(caught.value, "cli")) == f"{flag}: {message}"


def test_the_command_line_refuses_a_direction_sd_out_of_range_in_one_line():
    done = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "predict", str(example_scene_path()),
                           "--launch-direction-sd", "200"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "ipe: error: --launch-direction-sd: must be degrees in [0, 180] (0: exact), got 200.0"]
