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
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.perceptions import (PerceptionSource, perception_names, perception_source, register_perception,
                                        unregister_perception)


@dataclass(frozen=True)
class Jittered:
    scenes: tuple
    sd_m: dict

    def to_dict(self) -> dict:
        return {"kind": "jitter", "sd_m": self.sd_m, "samples": len(self.scenes)}


def jitter_from(path: Path) -> PerceptionSource:
    sd_m = json.loads(path.read_text())

    def run(scene, model, seed, map_fn):
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
    answer = predict(TOWER, ModelConfig(perception="jitter", samples=16, sigma_m=0.04), preset("default"),
                     QuerySpec(queries=frozenset({"fall"})), seed=3, check=None)
    assert answer.request["perception"] == {"kind": "jitter", "sd_m": {"block9": 0.05}, "samples": 16}
    falls = answer.object_fall_probability
    # sigma unused (the posterior is the noise): the tower as given stands, and only the top block moves
    # (in 6 of 16 samples it falls, taking three below it along in 3)
    assert 0.0 < falls["block9"] < 1.0 and all(falls[f"block{i}"] == 0.0 for i in range(5))
    with pytest.raises(ValueError, match="^a perception named 'jitter' is registered already$"):
        register_perception(jitter)


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
