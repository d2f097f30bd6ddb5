"""The node's ``~/observe``: an observation answered on latched ``~/properties`` with its id, a bad one
refused in one line, and what was learned used by the predictions that follow (which say so)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.ros_harness import RosHarness, wait_until

from std_msgs.msg import String  # noqa: E402

from ipe_ros.engine.inference.known import probe_push  # noqa: E402
from ipe_ros.ros.node import LATCHED_QOS  # noqa: E402

pytestmark = pytest.mark.ros
TIMEOUT_S = 120.0


@pytest.fixture
def ros():
    harness = RosHarness()
    yield harness
    harness.close()


def test_an_observation_is_answered_on_properties_and_its_lesson_reaches_the_next_prediction(ros):
    ros.start_ipe_node(samples=4, sigma=0.0, learned_properties_s=600.0)
    properties = ros.collect(String, "/ipe/properties", LATCHED_QOS)
    predictions = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
    observe = ros.publisher(String, "/ipe/observe")
    observation = probe_push(np.random.default_rng(5))
    observe.publish(String(data=json.dumps({**observation, "id": "bad", "position_sd_m": -1})))
    wait_until(lambda: len(properties), TIMEOUT_S, "the refusal of a bad observation")
    assert json.loads(properties[0].data) == {"id": "bad", "error": "position_sd_m: must be a number in (0, 1], got -1"}
    observe.publish(String(data=json.dumps({**observation, "id": "probe-1"})))
    wait_until(lambda: len(properties) >= 2, TIMEOUT_S, "the properties of the probe push")
    answer = json.loads(properties[1].data)
    assert answer["id"] == "probe-1" and answer["consistent"]
    friction = answer["unknowns"]["box.friction"]
    assert friction["interval_90"][0] <= 0.45 <= friction["interval_90"][1]
    # the box, seen again in a scene of its own: the learned mass and friction replace its own
    scene = dict(observation["scene"], name="box-again")
    ros.publisher(String, "/ipe/scene_json").publish(String(data=json.dumps(scene)))
    wait_until(lambda: any(json.loads(m.data).get("scene_id") == "box-again" for m in predictions), TIMEOUT_S,
               "the prediction of the box seen again")
    (prediction,) = [json.loads(m.data) for m in predictions if json.loads(m.data).get("scene_id") == "box-again"]
    used = {(u["object"], u["property"]): u["value"] for u in prediction["learned_properties"]}
    assert used == {("box", "mass_kg"): answer["unknowns"]["box.mass_kg"]["median"],
                    ("box", "friction"): friction["median"]}


def test_an_infer_question_on_ask_is_answered_on_answer_with_the_other_questions(ros):
    """``~/ask`` takes an ``infer`` question (the observation as its field): answered once, final, on
    ``~/answer``; a bad one refused there in one line naming the field."""
    ros.start_ipe_node(samples=4, sigma=0.0)
    replies = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    ask = ros.publisher(String, "/ipe/ask")
    observation = probe_push(np.random.default_rng(6))
    ask.publish(String(data=json.dumps({"question": "infer", "id": "bad", "observations": observation})))
    wait_until(lambda: len(replies), TIMEOUT_S, "the refusal of a bad infer question")
    assert json.loads(replies[0].data) == {
        "question": "infer", "final": True, "id": "bad",
        "error": "observations: unknown field of an infer question; allowed: id, observation"}
    ask.publish(String(data=json.dumps({"question": "infer", "id": "i1", "observation": observation})))
    wait_until(lambda: len(replies) >= 2, TIMEOUT_S, "the answer to the infer question")
    answer = json.loads(replies[1].data)
    assert (answer["question"], answer["id"], answer["final"], answer["consistent"]) == ("infer", "i1", True, True)
    low, high = answer["unknowns"]["box.friction"]["interval_90"]
    assert low <= 0.45 <= high
    assert answer["refined_scene"]["objects"][0]["friction_prior"]["median"] == \
        answer["unknowns"]["box.friction"]["median"]
