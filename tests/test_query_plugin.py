"""A query added at run time with a parameter of its own (tests/query_plugin_tilt.py: one module, one
registration, nothing else edited): predicted by the engine in this process and in worker processes,
set and read through the CLI, the node's parameters and ~/prediction, and a robot question's variants."""

from __future__ import annotations

import importlib
import json
from pathlib import Path

import pytest

from ipe_ros.cli import main
from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.actions.question import question_from_dict
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.query import QUERIES, register
from ipe_ros.engine.query.spec import plugin_modules, unregister

TOWER = load_scenes(example_scene_path())[0]
MODEL = ModelConfig(sigma_m=0.04, samples=8)


@pytest.fixture
def tilt():
    module = importlib.import_module("tests.query_plugin_tilt")
    if "tilt" not in QUERIES:  # imported by an earlier test, and unregistered after it
        register(module.QUERY)
    yield module
    unregister("tilt")


def _spec(module, threshold_deg: float) -> QuerySpec:
    return QuerySpec(queries=frozenset({"fall", "tilt"}),
                     parameters=(("tilt", module.TiltParameters(threshold_deg=threshold_deg)),))


def test_a_registered_query_answers_with_its_own_parameter_here_and_in_workers(tilt):
    assert plugin_modules() == ("tests.query_plugin_tilt",)
    strict = predict(TOWER,
                     Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 5.0), seed=3, check=None,
                             budget_s=None))
    loose = predict(TOWER,
                    Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 179.0), seed=3, check=None,
                            budget_s=None))
    # the same rollouts (same seed): only the threshold differs, and what fell lies tilted (a block
    # landing upside down, within a degree, is all that passes 179)
    assert strict.fall_fraction == loose.fall_fraction > 0
    assert strict.value("tilt_probability") >= 0.5 > 0.2 >= loose.value("tilt_probability")
    assert set(strict.value("tilted_object_probability")) == {b.name for b in TOWER.dynamic_objects}
    assert strict.to_dict()["tilt_probability"] == strict.value("tilt_probability")
    with WorkerPool(2, start_method="spawn") as pool:  # workers import the plugin to know the query
        there = predict(TOWER,
                        Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 5.0), seed=3, check=None,
                                budget_s=None),
                        Context(map_fn=pool.map))
    assert there.value("tilted_object_probability") == strict.value("tilted_object_probability") and there.failed_samples == 0
    with pytest.raises(AttributeError):  # a plugin's fields are values, not typed attributes
        strict.tilt_probability  # noqa: B018
    # a worker that does not know the query says so in every sample, never answers without it
    def unaware_map(fn, tasks, on_lost=None):
        unregister("tilt")
        try:
            return [fn(t) for t in tasks]
        finally:
            register(tilt.QUERY)

    unaware = predict(TOWER,
                      Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 5.0), seed=3, check=None,
                              budget_s=None),
                      Context(map_fn=unaware_map))
    assert unaware.samples == 0 and unaware.failed_samples == 8
    assert "ConfigError: queries: query 'tilt' is not registered in this process" in unaware.failure_reasons[0]
    # the default when no parameters are given, and the query's own check of its values
    assert QuerySpec(queries=frozenset({"tilt"})).parameters_of("tilt") == tilt.TiltParameters(threshold_deg=30.0)
    with pytest.raises(ConfigError) as info:
        _spec(tilt, 0.0)
    assert str(info.value) == "tilt.threshold_deg: must be in (0, 180) degrees, got 0.0"
    with pytest.raises(ConfigError) as info:
        QuerySpec(queries=frozenset({"fall"}), parameters=(("tilt", tilt.TiltParameters()),))
    assert str(info.value) == "parameters: parameters for 'tilt', which is not asked; ask it or drop them"


def test_the_cli_sets_a_registered_querys_parameter_by_its_own_option(tilt, capsys):
    path = str(Path(example_scene_path()))
    common = ["predict", path, "--query", "fall,tilt", "--samples", "8", "--seed", "3", "--workers", "0", "--json",
              "--no-self-check"]
    assert main(common + ["--tilt-threshold-deg", "5"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    expected = predict(TOWER,
                       Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 5.0), seed=3, check=None,
                               budget_s=None))
    assert record["tilt_probability"] == expected.value("tilt_probability") > 0
    assert main(common + ["--tilt-threshold-deg", "0"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == \
        "ipe: error: --tilt-threshold-deg: must be in (0, 180) degrees, got 0.0"
    assert main(common + ["--tilt-threshold-deg", "steep"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == \
        "ipe: error: --tilt-threshold-deg: must be a float, got 'steep'"


def test_a_questions_variants_answer_a_registered_query(tilt):
    question = question_from_dict({"question": "remove", "objects": ["block4"], "queries": ["tilt"],
                                   "query_parameters": {"tilt.threshold_deg": 5.0}, "samples": 8,
                                   "sequential": False})
    reply = question.answer(TOWER, ModelConfig(sigma_m=0.005, samples=8), preset("default"), seed=3)
    as_is, removed = reply.data["variants"]
    assert set(removed["tilted_object_probability"]) == {b.name for b in TOWER.dynamic_objects} - {"block4"}
    assert removed["tilt_probability"] > as_is["tilt_probability"]  # taking block4 topples what stood on it
    assert question_from_dict(question.to_dict()) == question
    for data, message in (
            ({"queries": ["fall"]}, "queries: fall is answered by the question itself (fell_off, contact, what_falls "
                                    "ask for it); list other queries: far, rest, final_pose, tipped, tilt"),
            ({"queries": ["tilt"], "query_parameters": {"tilt.threshold_deg": 0}},
             "tilt.threshold_deg: must be in (0, 180) degrees, got 0.0"),
            ({"queries": ["tilt"], "query_parameters": {"tilt.steepness": 1}},
             "tilt.steepness: not a parameter of the tilt query; choose from tilt.threshold_deg"),
            ({"query_parameters": {"tilt.threshold_deg": 5.0}},
             "query_parameters: were given but no queries; list the queries they are for in \"queries\"")):
        with pytest.raises(ConfigError) as info:
            question_from_dict({"question": "remove", **data}).answer(TOWER, MODEL, preset("default"))
        assert str(info.value) == message


@pytest.mark.ros
def test_the_node_declares_a_registered_querys_parameter_and_publishes_its_answer(tilt):
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    from ipe_ros.engine.scene.format import scene_to_json
    from ipe_ros.ros.node import LATCHED_QOS
    from tests.ros_harness import RosHarness, wait_until

    ros = RosHarness()
    try:
        node = ros.start_ipe_node(samples=8, seed=3, self_check=False, workers=0, queries=["fall", "tilt"],
                                  **{"tilt.threshold_deg": 5.0})
        got = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
        ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(TOWER)))
        wait_until(lambda: got, 60.0, "the prediction")
        answer = json.loads(got[-1].data)
        expected = predict(TOWER,
                           Request(model=MODEL, settings=preset("default"), query=_spec(tilt, 5.0), seed=3,
                                   check=None, budget_s=None))
        assert answer["tilt_probability"] == expected.value("tilt_probability") > 0, answer
        refused = node.set_parameters([Parameter("tilt.threshold_deg", value=0.0)])[0]
        assert not refused.successful
        assert refused.reason == "tilt.threshold_deg: must be in (0, 180) degrees, got 0.0"
    finally:
        ros.close()


def test_ipe_ask_asks_a_registered_query_of_every_variant(tilt, capsys):
    path = str(Path(example_scene_path()))
    assert main(["ask", "remove", path, "--object", "block4", "--query", "tilt", "--tilt-threshold-deg", "5",
                 "--sigma", "0.005", "--samples", "8", "--seed", "3", "--workers", "0", "--fixed-k", "--json"]) == 0
    reply = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    expected = question_from_dict({"question": "remove", "objects": ["block4"], "queries": ["tilt"],
                                   "query_parameters": {"tilt.threshold_deg": 5.0}, "samples": 8,
                                   "sequential": False}).answer(TOWER, ModelConfig(sigma_m=0.005, samples=8),
                                                                preset("default"), seed=3)
    assert [v["tilt_probability"] for v in reply["variants"]] == \
        [v["tilt_probability"] for v in expected.data["variants"]]
    assert main(["ask", "remove", path, "--query", "fall"]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith(
        "ipe: error: --query: fall is answered by the question itself")
