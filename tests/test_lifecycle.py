"""The managed node: nothing runs unconfigured, configure starts the workers, activate starts answering,
deactivate stops answering with the workers kept warm, cleanup ends the workers. Driven through the
standard lifecycle services, as a lifecycle manager would."""

from __future__ import annotations

import json

import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.parameter import Parameter
from std_msgs.msg import String

from ipe_ros.engine import load_scenes
from ipe_ros.engine.scene.format import scene_to_json
from ipe_ros.ros.lifecycle import IpeLifecycleNode
from ipe_ros.ros.node import LATCHED_QOS
from tests.ros_harness import RosHarness, wait_until

#: starts rclpy (a Context of its own, DDS on loopback)
pytestmark = pytest.mark.ros

TIMEOUT_S = 90.0


@pytest.fixture
def ros():
    harness = RosHarness()
    yield harness
    harness.close()


def _transition(ros: RosHarness, transition: int | str) -> bool:
    """Ask for a transition by id or, as ``ros2 lifecycle set`` may, by label."""
    asked = Transition(label=transition) if isinstance(transition, str) else Transition(id=transition)
    return ros.call(ChangeState, "/ipe/change_state", ChangeState.Request(transition=asked),
                    timeout_s=TIMEOUT_S).success


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split()[2] != "Z"  # a zombie has ended
    except FileNotFoundError:
        return False


def _state(ros: RosHarness) -> int:
    return ros.call(GetState, "/ipe/get_state", GetState.Request()).current_state.id


def test_configure_starts_the_workers_and_activate_starts_answering(ros):
    node = IpeLifecycleNode(context=ros.context, parameter_overrides=[Parameter("samples", value=4),
                                                                      Parameter("workers", value=2)])
    ros._nodes.append(node)
    ros.executor.add_node(node)
    answers = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
    scene = String(data=scene_to_json(load_scenes("ipe_ros/data/example_tower.json")[0]))

    assert _state(ros) == State.PRIMARY_STATE_UNCONFIGURED
    assert node.service is None and node.count_subscribers("/ipe/scene_json") == 0

    assert _transition(ros, Transition.TRANSITION_CONFIGURE)
    assert _state(ros) == State.PRIMARY_STATE_INACTIVE
    wait_until(lambda: node.service.stats().workers_alive == 2, TIMEOUT_S, "the worker processes")
    assert node.count_subscribers("/ipe/scene_json") == 0  # inactive: configured but not answering

    assert _transition(ros, Transition.TRANSITION_ACTIVATE)
    ros.publisher(String, "/ipe/scene_json").publish(scene)
    wait_until(lambda: len(answers), TIMEOUT_S, "an answer while active")
    assert json.loads(answers[0].data)["samples"] == 4

    assert _transition(ros, Transition.TRANSITION_DEACTIVATE)
    wait_until(lambda: node.count_subscribers("/ipe/scene_json") == 0, 10.0, "the subscriptions to go")
    pids = node.service.pool.worker_pids()
    assert len(pids) == 2 and node.service.stats().workers_alive == 2  # kept warm for the next activation

    assert _transition(ros, Transition.TRANSITION_CLEANUP)
    assert node.service is None
    wait_until(lambda: not any(_alive(pid) for pid in pids), 10.0, "the worker processes to end")
    assert _state(ros) == State.PRIMARY_STATE_UNCONFIGURED


def test_a_bad_parameter_fails_configure_by_name_and_the_node_stays_unconfigured(ros):
    node = IpeLifecycleNode(context=ros.context, parameter_overrides=[Parameter("frame_id", value="camera"),
                                                                      Parameter("workers", value=1)])
    ros._nodes.append(node)
    ros.executor.add_node(node)
    assert not _transition(ros, Transition.TRANSITION_CONFIGURE)
    assert _state(ros) == State.PRIMARY_STATE_UNCONFIGURED and node.service is None


def _managed_node(ros: RosHarness, **values) -> IpeLifecycleNode:
    node = IpeLifecycleNode(context=ros.context, parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])
    ros._nodes.append(node)
    ros.executor.add_node(node)
    return node


@pytest.mark.parametrize("in_state, transition_id", [
    ("unconfigured", Transition.TRANSITION_ACTIVATE),
    ("unconfigured", Transition.TRANSITION_DEACTIVATE),
    ("unconfigured", Transition.TRANSITION_CLEANUP),
    ("inactive", Transition.TRANSITION_CONFIGURE),
    ("unconfigured", 99),  # no such transition
    ("inactive", "configure"),  # by label
    ("unconfigured", "fly"),  # no such label
])
def test_a_transition_not_allowed_from_the_state_is_refused_and_the_state_kept(ros, in_state, transition_id):
    node = _managed_node(ros, samples=2, workers=1)
    if in_state == "inactive":
        assert _transition(ros, Transition.TRANSITION_CONFIGURE)
    state = _state(ros)
    assert not _transition(ros, transition_id)
    assert _state(ros) == state  # answered, and the node is still there with its state
    assert (node.service is None) == (in_state == "unconfigured")
    if in_state == "unconfigured":  # the node goes on with the transitions that are allowed
        assert _transition(ros, Transition.TRANSITION_CONFIGURE)
    assert _transition(ros, Transition.TRANSITION_ACTIVATE)
    assert _state(ros) == State.PRIMARY_STATE_ACTIVE


def test_cleanup_answers_the_prediction_and_the_question_in_flight_with_an_error(ros):
    # a prediction that takes long: the paper's settings, many samples, one worker
    node = _managed_node(ros, samples=400, workers=1, preset="paper", budget_s=120.0)
    predictions = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
    replies = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    assert _transition(ros, Transition.TRANSITION_CONFIGURE) and _transition(ros, Transition.TRANSITION_ACTIVATE)
    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: node.service.stats().in_flight, TIMEOUT_S, "the prediction to start")
    ros.publisher(String, "/ipe/ask").publish(String(data=json.dumps({"id": "q1", "question": "support"})))
    wait_until(lambda: node.questions._current is not None, TIMEOUT_S, "the question to start")
    assert _transition(ros, Transition.TRANSITION_DEACTIVATE)  # stops intake; what is in flight goes on
    assert node.service.stats().in_flight and not predictions and not replies
    assert _transition(ros, Transition.TRANSITION_CLEANUP)
    wait_until(lambda: predictions and replies, 10.0, "a reply on ~/prediction and on ~/answer")
    [prediction] = [json.loads(m.data) for m in predictions]
    assert prediction["error"] == "the node was cleaned up (lifecycle cleanup): the prediction was cancelled"
    assert prediction["scene_id"] == tower.name
    [reply] = [json.loads(m.data) for m in replies]
    assert (reply["id"], reply["error"]) == ("q1", "the node was cleaned up (lifecycle cleanup): the question was cancelled")
