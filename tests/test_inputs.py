"""The table of inputs (engine.inputs) agrees with the CLI's options and the node's parameters, and
errors name inputs as each user spells them."""

from __future__ import annotations

import pytest

from ipe_ros.cli import build_parser
from ipe_ros.engine import ConfigError, ModelConfig
from ipe_ros.engine.inputs import INPUTS, as_spelled, spelled


def _options(command: str, question: str | None = None) -> set[str]:
    sub = build_parser()._subparsers._group_actions[0].choices[command]  # noqa: SLF001 - argparse has no API
    if question is not None:
        sub = sub._subparsers._group_actions[0].choices[question]  # noqa: SLF001
    return {o for action in sub._actions for o in action.option_strings}  # noqa: SLF001


def test_every_flag_is_an_option_and_every_parameter_a_node_parameter():
    from ipe_ros.ros.params import PARAMETERS

    flags = _options("predict") | _options("ask", "remove")
    parameters = {p.name for p in PARAMETERS}
    assert [i.flag for i in INPUTS if i.flag is not None and i.flag not in flags] == []
    assert [i.parameter for i in INPUTS if i.parameter is not None and i.parameter not in parameters] == []
    assert len({i.field for i in INPUTS}) == len(INPUTS)


def test_an_engine_error_reads_as_each_user_spelled_the_input():
    with pytest.raises(ConfigError) as caught:
        ModelConfig(sigma_m=99.0)
    assert caught.value.field == "sigma_m"
    assert str(as_spelled(caught.value, "cli")) == "--sigma: must be at most 10 m (check the units), got 99.0"
    assert str(as_spelled(caught.value, "ros")) == "sigma: must be at most 10 m (check the units), got 99.0"
    assert spelled("force_direction_rad", "ros") == "force_direction_deg"
    assert spelled("objects[2].mass_kg", "cli") == "objects[2].mass_kg"  # not an input of the table
    assert spelled("max_objects", "cli") == "max_objects"  # no CLI spelling


def test_a_scene_is_checked_once_however_often_a_request_validates_it(monkeypatch):
    from ipe_ros.engine import QuerySpec, preset, predict
    from ipe_ros.engine.scene import validation as scene_module
    from ipe_ros.engine.sampling.sampler import check_request
    from tests.helpers import block, floor_scene

    calls = []
    real = scene_module._validate
    monkeypatch.setattr(scene_module, "_validate", lambda s, m: calls.append(s.name) or real(s, m))
    scene = floor_scene(block("b", 0.0, 0.0, 0.1), name="checked_once")
    model, settings, query = ModelConfig(sigma_m=0.0, samples=1), preset("default"), QuerySpec()
    check_request(scene, query, model=model, settings=settings, budget_s=10.0)  # where the CLI costs it
    predict(scene, model, settings, query, check=None)  # and where it is predicted
    assert calls == ["checked_once"]
    broken = floor_scene(block("b", 0.0, 0.0, -1.0), name="broken")
    for _ in range(2):  # an invalid scene is never remembered as valid
        with pytest.raises(Exception, match="below the support surface"):
            check_request(broken, query)
    assert calls.count("broken") == 2


def test_the_ground_truth_refuses_a_perception_that_draws_the_scene():
    """The ground truth is the scene exactly as given: with perception from images it would silently
    be k samples of their posterior instead."""
    from ipe_ros.engine.request import build_request

    assert build_request(ground_truth=True).model.object_noise is False
    for perception in ("vision", "depth"):
        with pytest.raises(ConfigError) as caught:
            build_request(ground_truth=True, perception=perception)
        problem = (f"takes the scene exactly as given, but perception {perception} draws it from a posterior; "
                   "ask the ground truth with perception gaussian")
        assert str(as_spelled(caught.value, "cli")) == f"--ground-truth: {problem}"
        assert str(as_spelled(caught.value, "ros")) == f"ground_truth: {problem}"


@pytest.mark.parametrize("changes, reason", [
    ({"queries": ["fall", "contact"]}, "contact_pairs: the contact query needs pairs to watch: give A:B (B may be "
                                       "support), or drop contact from the queries"),
    ({"contact_pairs": "A:A"}, "contact_pairs: A:A: an object always touches itself; name two"),
    ({"contact_pairs": "support:support"}, "contact_pairs: support:support: an object always touches itself; name two"),
])
def test_node_settings_no_scene_could_answer_are_refused_when_set_naming_the_parameter(changes, reason):
    """Accepted, they made every later scene fail, with errors naming the CLI's --contact."""
    from ipe_ros.engine import ConfigError
    from ipe_ros.ros.params import PARAMETERS, config_from_values

    values = {spec.name: spec.default for spec in PARAMETERS} | changes
    with pytest.raises(ConfigError) as info:
        config_from_values(values)
    assert str(info.value) == reason
