"""Perception sources are a protocol: a new one is one registration, and predict, the CLI and the node
use it without being edited. The source here: the scene as given, each object jittered by its own SD
read from a file (as a detector might report per-object uncertainty)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from ipe_ros.cli import main
from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine import Request
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.perceptions import (PerceptionSource, perception_names, perception_source, register_perception,
                                        unregister_perception)


@dataclass(frozen=True)
class Jittered:
    scenes: tuple
    sd_m: dict
    refined = None

    def with_samples(self, k: int) -> "Jittered":
        return dataclasses.replace(self, scenes=self.scenes[:k])

    def to_dict(self) -> dict:
        return {"kind": "jitter", "sd_m": self.sd_m, "samples": len(self.scenes)}


def jitter_from(path: Path) -> PerceptionSource:
    sd_m = json.loads(path.read_text())

    def run(scene, model, seed, map_fn, evidence, budget_s):
        rng = np.random.default_rng([seed, 0x717])
        scenes = []
        for _ in range(model.samples):
            objects = []
            for body in scene.objects:
                sd = 0.0 if body.static else float(sd_m.get(body.name, 0.0))
                dx, dy = rng.normal(0.0, sd, 2) if sd else (0.0, 0.0)
                objects.append(dataclasses.replace(body, position_m=(body.position_m[0] + dx, body.position_m[1] + dy,
                                                                     body.position_m[2])))
            scenes.append(dataclasses.replace(scene, objects=tuple(objects)))
        return Jittered(tuple(scenes), sd_m)

    return PerceptionSource("jitter", "each object jittered by its own SD from a file", posterior=True, run=run)


TOWER = load_scenes(example_scene_path())[0]


@pytest.fixture
def jitter(tmp_path):
    """Only the top block is uncertain, by 5 cm."""
    path = tmp_path / "sd.json"
    path.write_text(json.dumps({"block9": 0.05}))
    source = register_perception(jitter_from(path))
    yield source
    unregister_perception("jitter")


def test_a_registered_perception_is_drawn_from_by_predict(jitter):
    assert "jitter" in perception_names() and perception_source("jitter") is jitter
    answer = predict(TOWER,
                     Request(model=ModelConfig(perception="jitter", samples=16, sigma_m=0.04),
                             settings=preset("default"), query=QuerySpec(queries=frozenset({"fall"})), seed=3,
                             check=None, budget_s=None))
    assert answer.request["perception"] == {"kind": "jitter", "sd_m": {"block9": 0.05}, "samples": 16}
    falls = answer.object_fall_probability
    # sigma unused (the posterior is the noise): the tower as given stands, and only the top block moves
    # (in 6 of 16 samples it falls, taking three below it along in 3)
    assert 0.0 < falls["block9"] < 1.0 and all(falls[f"block{i}"] == 0.0 for i in range(5))
    with pytest.raises(ValueError, match="^a perception named 'jitter' is registered already$"):
        register_perception(jitter)


def test_a_chain_that_returns_no_perceived_scenes_is_named():
    source = register_perception(PerceptionSource("listed", "a list", posterior=True,
                                                  run=lambda *_: [TOWER] * 4))
    try:
        with pytest.raises(TypeError, match=r"^perception listed's run returned a list, which is not Perceived "
                                            r"\(engine.perceptions\): give it scenes, refined, with_samples\(k\) and "
                                            r"to_dict\(\)$"):
            predict(TOWER,
                    Request(model=ModelConfig(perception="listed", samples=4), settings=preset("default"),
                            query=QuerySpec(), check=None, budget_s=None))
    finally:
        unregister_perception(source.name)


def test_the_cli_offers_a_registered_perception(jitter, capsys):
    path = Path(example_scene_path())
    assert main(["predict", str(path), "--perception", "jitter", "--samples", "8", "--workers", "0", "--json",
                 "--no-self-check", "--query", "fall"]) == 0
    record = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert record["request"]["perception"]["kind"] == "jitter"


def test_an_unknown_or_removed_perception_is_refused(jitter):
    unregister_perception("jitter")
    with pytest.raises(ConfigError, match=r"^perception: must be one of gaussian, vision, depth, got 'jitter'$"):
        ModelConfig(perception="jitter")
    with pytest.raises(ValueError, match="^'depth' is built in$"):
        unregister_perception("depth")
    register_perception(jitter)  # for the fixture's teardown


@pytest.mark.ros
def test_the_node_predicts_from_a_registered_perception(jitter):
    from std_msgs.msg import String

    from ipe_ros.engine.scene.format import scene_to_json
    from ipe_ros.ros.node import LATCHED_QOS
    from tests.ros_harness import RosHarness, wait_until

    ros = RosHarness()
    try:
        node = ros.start_ipe_node(samples=8, perception="jitter", self_check=False, workers=0, queries=["fall"])
        got = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
        ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(TOWER)))
        wait_until(lambda: got, 60.0, "the prediction")
        answer = json.loads(got[-1].data)
        assert answer["request"]["perception"]["kind"] == "jitter", answer
        assert node.get_parameter("perception").value == "jitter"
    finally:
        ros.close()


# A source that needs evidence (tests/perception_plugin_detections.py): the detector's list, from a
# file through the CLI and from a topic through the node, drawn on two workers. No door names it.

#: block9 where the tower has it, uncertain by 5 cm along x (1 cm along y); block8 all but certain
DETECTIONS = {"frame_id": "world", "detections": [
    {"object": name, "position_m": [list(b.position_m[:2]) for b in TOWER.objects if b.name == name][0], "covariance_m2": cov}
    for name, cov in (("block9", [[25e-4, 0.0], [0.0, 1e-4]]), ("block8", [[1e-6, 0.0], [0.0, 1e-6]]))]}


@pytest.fixture
def detections():
    from tests import perception_plugin_detections as plugin

    source = register_perception(plugin.SOURCE)
    yield source
    unregister_perception("detections")


def _cli_prediction(tmp_path, capsys, workers: int) -> dict:
    path = tmp_path / "detections.json"
    path.write_text(json.dumps(DETECTIONS))
    assert main(["predict", str(example_scene_path()), "--perception", "detections", "--detections", str(path),
                 "--samples", "8", "--workers", str(workers), "--json", "--no-self-check", "--query", "fall"]) == 0
    return json.loads(capsys.readouterr().out.strip().splitlines()[-1])


def test_a_source_that_needs_evidence_reads_it_from_its_own_cli_option_and_draws_on_the_workers(detections, tmp_path,
                                                                                               capsys):
    on_two = _cli_prediction(tmp_path, capsys, workers=2)
    assert on_two["request"]["perception"] == {"kind": "detections", "samples": 8, "objects": {
        d["object"]: {"position_m": d["position_m"], "covariance_m2": d["covariance_m2"]}
        for d in DETECTIONS["detections"]}}
    falls = on_two["object_fall_probability"]
    # block9, uncertain by 5 cm, falls in some samples, not all; the blocks below it stand
    assert 0.0 < falls["block9"] < 1.0 and all(falls[f"block{i}"] == 0.0 for i in range(5)), falls
    on_none = _cli_prediction(tmp_path, capsys, workers=0)  # the same draws however many workers
    assert on_none["object_fall_probability"] == falls
    # its options belong to it: given without it, refused by name; it without them, refused too
    path = tmp_path / "detections.json"
    assert main(["predict", str(example_scene_path()), "--detections", str(path)]) == 2
    assert capsys.readouterr().err.strip() == "ipe: error: --perception: --detections need --perception detections"
    assert main(["predict", str(example_scene_path()), "--perception", "detections"]) == 2
    assert capsys.readouterr().err.strip() == ("ipe: error: --perception: detections perception needs "
                                               "--detections FILE")
    with pytest.raises(ConfigError, match=r"^perception: detections perception needs the detections: give them to "
                                          r"predict as its evidence \(ipe predict's --detections; the node's "
                                          r"~/detections\)$"):
        predict(TOWER,
                Request(model=ModelConfig(perception="detections", samples=4), settings=preset("default"),
                        query=QuerySpec(), check=None, budget_s=None))


def test_no_door_names_a_perception_or_a_query():
    """The CLI, the node and the service reach sources and queries only through their protocols
    (engine.perceptions, engine.evidence, engine.query): no branch on a source's or a query's name,
    no depth-only or vision-only code."""
    from ipe_ros.engine.query import QUERIES

    import re

    root = Path(__file__).resolve().parents[1] / "ipe_ros"
    doors = [*root.glob("cli*.py"), *(root / "service").glob("*.py"), *(root / "ros").glob("*.py")]
    names = (*perception_names(), *QUERIES)
    assert {"gaussian", "vision", "depth", "fall", "direction"} <= set(names)
    named = "|".join(names)
    pattern = re.compile(rf"""(==|!=|\bin)\s*["']({named})["']|["']({named})["']\s*(==|!=|\bin\b)|wants\(["']""")
    offending = [f"{p.name}:{i}" for p in doors for i, line in enumerate(p.read_text().splitlines(), 1)
                 if pattern.search(line) or re.search(r"\b(depth|vision)_(posterior|perceive|images?|settings|rrd)\b",
                                                      line)]
    assert not offending, offending


@pytest.mark.ros
def test_the_node_takes_a_sources_evidence_from_its_declared_topic_and_answers_as_the_cli(detections, tmp_path, capsys):
    from std_msgs.msg import String

    import re

    from std_srvs.srv import Trigger

    from ipe_ros.engine.scene.format import scene_to_json
    from ipe_ros.ros.node import LATCHED_QOS
    from tests.ros_harness import RosHarness, wait_until
    from tests.test_node import set_params

    expected = _cli_prediction(tmp_path, capsys, workers=2)
    ros = RosHarness()
    try:
        node = ros.start_ipe_node(samples=8, perception="detections", self_check=False, workers=2, queries=["fall"])
        got = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
        scenes = ros.publisher(String, "/ipe/scene_json")
        scenes.publish(String(data=scene_to_json(TOWER)))  # before any detections: answered with the reason
        wait_until(lambda: got, 60.0, "the refusal of a scene without detections")
        assert json.loads(got[-1].data)["error"] == ("perception: detections: no detection list received yet; "
                                                     "publish one on ~/detections")
        detector = ros.publisher(String, "/ipe/detections")
        detector.publish(String(data="{not json"))  # refused, counted, the node goes on
        wait_until(lambda: node.service.stats().evidence.get("detections_refused") == 1, 30.0, "the refusal")
        detector.publish(String(data="[]"))  # the plugin's own bug (an AttributeError): refused too
        wait_until(lambda: node.service.stats().evidence.get("detections_refused") == 2, 30.0, "the plugin's error")
        detector.publish(String(data=json.dumps(DETECTIONS)))
        wait_until(lambda: node.service.stats().evidence.get("detections") == 1, 30.0, "the detections")
        scenes.publish(String(data=scene_to_json(TOWER)))
        wait_until(lambda: len(got) >= 2 and "error" not in json.loads(got[-1].data), 120.0, "the prediction")
        answer = json.loads(got[-1].data)
        assert answer["request"]["perception"] == expected["request"]["perception"]
        assert answer["object_fall_probability"] == expected["object_fall_probability"]  # one seed, one answer
        assert node.service.stats().evidence["detections_posteriors"] == 1
        # its own parameter, declared with the node's: a view too old for it is refused, and counted
        assert node.get_parameter("detections.max_age_s").value == 60.0
        assert all(r.successful for r in set_params(ros, **{"detections.max_age_s": 0.001}))
        response = ros.call(Trigger, "/ipe/predict", Trigger.Request())
        assert not response.success
        assert re.search(r"perception: detections: the newest detection list is [0-9.e-]+ s from the scene's stamp, "
                         r"more than detections.max_age_s = 0.001 s", response.message), response.message
        assert node.service.stats().evidence["detections_stale"] == 1
    finally:
        ros.close()
