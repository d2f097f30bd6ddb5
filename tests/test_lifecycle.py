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
from ipe_ros.engine.scene_io import scene_to_json
from ipe_ros.ros.node import LATCHED_QOS, IpeLifecycleNode
from tests.ros_harness import RosHarness, wait_until

TIMEOUT_S = 90.0


@pytest.fixture
def ros():
    harness = RosHarness()
    yield harness
    harness.close()


def _transition(ros: RosHarness, transition_id: int) -> bool:
    return ros.call(ChangeState, "/ipe/change_state",
                    ChangeState.Request(transition=Transition(id=transition_id)), timeout_s=TIMEOUT_S).success


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
