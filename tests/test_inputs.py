"""The table of inputs (engine.inputs) agrees with the CLI's options and the node's parameters, and
errors name inputs as each user spells them."""

from __future__ import annotations

import pytest

from ipe_ros.cli import build_parser
from ipe_ros.engine import ConfigError, ModelConfig
from ipe_ros.engine.inputs import INPUTS, Input, as_spelled, node_default, spelled


def _option(parser, flag: str):
    return next(a for a in parser._actions if flag in a.option_strings)  # noqa: SLF001 - argparse has no API


def test_every_option_and_node_parameter_is_made_from_its_row():
    from ipe_ros.ros.params import all_parameters

    predict = build_parser()._subparsers._group_actions[0].choices["predict"]  # noqa: SLF001
    ask = build_parser()._subparsers._group_actions[0].choices["ask"]  # noqa: SLF001
    remove = ask._subparsers._group_actions[0].choices["remove"]  # noqa: SLF001
    declared = {p.name: p for p in all_parameters()}
    for row in INPUTS:
        if row.flag is not None:
            parser = remove if row.field == "fell_off" else predict
            action = _option(parser, row.flag)
            assert action.dest == row.field
            assert action.default == (None if row.requires or row.kind == "pairs" else row.default), row.field
        if row.parameter is not None:
            assert [declared[row.parameter].default] == [node_default(row)], row.field  # NaN is itself
    assert len({i.field for i in INPUTS}) == len(INPUTS)


def test_a_new_row_is_an_option_and_a_node_parameter_with_its_range():
    """A new input is one row: the generators make the CLI's option and the node's descriptor from it."""
    import argparse

    from ipe_ros.cli_inputs import add_input_options
    from ipe_ros.engine import inputs
    from ipe_ros.ros.params import ParamSpec

    row = Input("tries", "int", 3, "count", "how often to try", "--tries", "tries", range=(1, 9), in_request=False)
    parser = argparse.ArgumentParser()
    original = inputs._BY_FIELD.copy()
    inputs._BY_FIELD["tries"] = row
    try:
        add_input_options(parser, ("tries",))
    finally:
        inputs._BY_FIELD.clear()
        inputs._BY_FIELD.update(original)
    assert parser.parse_args([]).tries == 3 and parser.parse_args(["--tries", "5"]).tries == 5
    assert "how often to try (default 3)" in parser.format_help().replace("\n", " ").replace("  ", " ")
    descriptor = ParamSpec.of(row).descriptor()
    assert (descriptor.name, descriptor.integer_range[0].from_value, descriptor.integer_range[0].to_value) == \
        ("tries", 1, 9)


def test_the_cli_and_the_node_build_the_same_request_from_the_same_intent():
    """Each door's spelling of "not set" (an option left out; 0 or NaN on the node), several phi values
    and contact pairs reach the engine as one request."""
    import dataclasses

    from ipe_ros.cli_inputs import given_request_arguments
    from ipe_ros.engine.request import build_request
    from ipe_ros.ros.params import all_parameters, config_from_values

    defaults = {spec.name: spec.default for spec in all_parameters()}
    parse = build_parser().parse_args
    cases = [([], {}),
             (["--phi", "0,2", "--mu", "3", "--horizon", "1.5", "--force-direction", "30", "--ci-width", "0.2",
               "--contact", "a:b", "--contact", "c:support", "--no-self-check", "--until-rest", "--seed", "7"],
              {"phi": [0.0, 2.0], "mu": 3.0, "horizon_s": 1.5, "force_direction_deg": 30.0, "target_ci_width": 0.2,
               "contact_pairs": "a:b,c:support", "self_check": False, "until_rest": True, "seed": 7})]
    for argv, values in cases:
        cli = build_request(**given_request_arguments(parse(["predict", "scene.json", *argv])))
        node = config_from_values(defaults | values).request
        if cli.stop is not None:  # the anytime batch follows each door's worker count
            cli = dataclasses.replace(cli, stop=dataclasses.replace(cli.stop, batch_size=node.stop.batch_size))
        assert cli == node, argv


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
    from ipe_ros.engine import Request
    from ipe_ros.engine.scene import validation as scene_module
    from ipe_ros.engine.predict import check_request
    from tests.helpers import block, floor_scene

    calls = []
    real = scene_module._validate
    monkeypatch.setattr(scene_module, "_validate", lambda s, m: calls.append(s.name) or real(s, m))
    scene = floor_scene(block("b", 0.0, 0.0, 0.1), name="checked_once")
    model, settings, query = ModelConfig(sigma_m=0.0, samples=1), preset("default"), QuerySpec()
    check_request(scene, query, model=model, settings=settings, budget_s=10.0)  # where the CLI costs it
    predict(scene, Request(model=model, settings=settings, query=query, check=None, budget_s=None))  # and where it is predicted
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
    ({"mesh_roots": "meshes"}, "mesh_roots: 'meshes' is not an absolute path of a folder; give folders as "
                               "/path/a:/path/b"),
    # a name past the file system's limit raised an OSError out of the parameter callback (issue 76)
    ({"mesh_roots": "/" + "a" * 300}, f"mesh_roots: '/{'a' * 300}' is not an absolute path of a folder; give "
                                      "folders as /path/a:/path/b"),
])
def test_node_settings_no_scene_could_answer_are_refused_when_set_naming_the_parameter(changes, reason):
    """Accepted, they made every later scene fail, with errors naming the CLI's --contact."""
    from ipe_ros.engine import ConfigError
    from ipe_ros.ros.params import all_parameters, config_from_values

    values = {spec.name: spec.default for spec in all_parameters()} | changes
    with pytest.raises(ConfigError) as info:
        config_from_values(values)
    assert str(info.value) == reason


def test_the_node_takes_phi_as_one_value_or_several_and_names_it_otherwise():
    """Params files written when phi was one number keep working; several are averaged as --phi 0,2."""
    import array

    from ipe_ros.engine.inputs import from_node, row

    phi = row("phi_m_s2")
    assert from_node(phi, 2.0) == (2.0,) and from_node(phi, array.array("d", [0.0, 2.0])) == (0.0, 2.0)
    for bad in ("2", [], [True], None):
        with pytest.raises(ConfigError) as caught:
            from_node(phi, bad)
        assert str(caught.value) == f"phi: must be a number or a non-empty list of numbers, got {bad!r}"
    with pytest.raises(ConfigError) as caught:
        from_node(row("force_direction_deg"), float("inf"))
    assert str(caught.value) == "force_direction_deg: must be finite degrees or NaN (any direction), got inf"
