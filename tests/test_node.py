"""The ROS 2 node in-process: isolated Context per test, executor in a thread, deadline waits."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import signal

import numpy as np
import pytest

from tests.ros_harness import RosHarness, wait_until

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import Vector3Stamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from std_msgs.msg import Float64, String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.scene.format import scene_to_json  # noqa: E402
from ipe_ros.ros.node import INPUT_QOS as RELIABLE_QOS, LATCHED_QOS  # noqa: E402
from msg_bridge.markers import markers_to_scene, scene_to_markers  # noqa: E402

#: starts rclpy (a Context of its own, DDS on loopback)
pytestmark = pytest.mark.ros

EXAMPLE = "ipe_ros/data/example_tower.json"
TIMEOUT_S = 90.0
FAST = dict(samples=6)  # enough samples to be a real Monte Carlo run, few enough to be quick


@pytest.fixture
def ros():
    harness = RosHarness()
    yield harness
    harness.close()


@pytest.fixture(scope="module")
def tower():
    return load_scenes(EXAMPLE)[0]


def answers(ros: RosHarness) -> list[dict]:
    received = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
    return _Decoded(received)


class _Decoded:
    """A live view of received prediction messages, decoded on access."""

    def __init__(self, raw: list):
        self.raw = raw

    def __len__(self) -> int:
        return len(self.raw)

    def __getitem__(self, i):
        return json.loads(self.raw[i].data)


def set_params(ros: RosHarness, **values):
    client = AsyncParameterClient(ros.client, "ipe")
    wait_until(lambda: client.services_are_ready(), 10.0, "the parameter services of /ipe")
    future = client.set_parameters([Parameter(k, value=v) for k, v in values.items()])
    wait_until(future.done, 10.0, "set_parameters")
    return future.result().results


def test_will_anything_fall_is_published_on_its_own_topic(ros, tower):
    ros.start_ipe_node(**FAST, seed=7, queries=["any_fall"])
    got = answers(ros)
    anything = ros.collect(Float64, "/ipe/fall_probability", LATCHED_QOS)
    fractions = ros.collect(Float64, "/ipe/fall_fraction", LATCHED_QOS)
    directions = ros.collect(Vector3Stamped, "/ipe/fall_direction", LATCHED_QOS)
    ros.publisher(MarkerArray, "/ipe/scene").publish(scene_to_markers(tower, "odom", 1))
    wait_until(lambda: len(got) and len(anything), TIMEOUT_S, "an answer and /ipe/fall_probability")
    # direction was not asked: no zero vector that would read as "nothing falls"
    assert len(directions) == 0
    with WorkerPool(1) as pool:
        expected = predict(tower,
                           Request(model=ModelConfig(sigma_m=0.04, samples=6), settings=preset("default"),
                                   query=QuerySpec(queries=frozenset({"any_fall"})), seed=7, budget_s=None),
                           Context(map_fn=pool.map))
    assert anything[0].data == got[0]["any_fall_probability"] == expected.any_fall_probability
    assert got[0]["fall_fraction"] is None and len(fractions) == 0  # the fraction was not asked


def test_marker_tower_in_stamped_prediction_out_matching_the_engine(ros, tower):
    node = ros.start_ipe_node(**FAST, seed=7)
    got = answers(ros)
    fractions = ros.collect(Float64, "/ipe/fall_fraction", LATCHED_QOS)
    probabilities = ros.collect(Float64, "/ipe/fall_probability", LATCHED_QOS)
    directions = ros.collect(Vector3Stamped, "/ipe/fall_direction", LATCHED_QOS)
    markers = ros.collect(MarkerArray, "/ipe/markers", LATCHED_QOS)
    pub = ros.publisher(MarkerArray, "/ipe/scene")
    stamp_ns = 1_700_000_000_123_456_789
    pub.publish(scene_to_markers(tower, "odom", stamp_ns))
    wait_until(lambda: len(got) and len(fractions) and len(probabilities) and len(directions) and len(markers), TIMEOUT_S,
               "a prediction on every output topic")
    answer = got[0]
    assert answer["stamp"] == {"sec": 1_700_000_000, "nanosec": 123_456_789}
    assert answer["frame_id"] == "odom"
    assert answer["scene_id"] == tower.name and answer["scene_seq"] == 1
    assert answer["compute_s"] > 0 and answer["latency_s"] >= answer["compute_s"] * 0.5

    # Same scene, settings and seed through the engine API: the same numbers.
    with WorkerPool(1) as pool:
        expected = predict(tower,
                           Request(model=ModelConfig(sigma_m=0.04, samples=6), settings=preset("default"),
                                   query=QuerySpec(queries=frozenset({"fall", "any_fall", "direction", "far"})),
                                   seed=7, budget_s=None),
                           Context(map_fn=pool.map)).to_dict()
    for key in ("fall_fraction", "fall_fraction_ci95", "object_fall_probability", "any_fall_probability",
                "direction_rad", "direction_decisiveness", "far_m", "samples", "failed_samples"):
        assert answer[key] == expected[key], key

    # ~/fall_fraction: the expected fraction of objects that fall; ~/fall_probability: P(anything falls)
    assert fractions[0].data == answer["fall_fraction"]
    assert probabilities[0].data == answer["any_fall_probability"] >= answer["fall_fraction"]
    d = directions[0]
    assert (d.header.frame_id, d.header.stamp.sec, d.header.stamp.nanosec) == ("odom", 1_700_000_000, 123_456_789)
    if answer["direction_rad"] is None:
        assert (d.vector.x, d.vector.y, d.vector.z) == (0.0, 0.0, 0.0)
    else:
        assert math.hypot(d.vector.x, d.vector.y) == pytest.approx(answer["direction_decisiveness"])
        assert math.atan2(d.vector.y, d.vector.x) == pytest.approx(answer["direction_rad"])
    shown = markers[0].markers
    assert shown[0].action == Marker.DELETEALL
    cubes = [m for m in shown if m.ns == "ipe/objects"]
    assert len(cubes) == len(tower.objects) and all(m.header.frame_id == "odom" for m in cubes)
    assert node.service.stats().predicted == 1


def test_json_topic_uses_the_frame_parameter(ros, tower):
    ros.start_ipe_node(**FAST, frame_id="map")
    got = answers(ros)
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: len(got), TIMEOUT_S, "a prediction for the JSON scene")
    assert got[0]["frame_id"] == "map" and got[0]["scene_id"] == tower.name
    assert got[0]["samples"] == 6 and 0.0 <= got[0]["fall_fraction"] <= 1.0


def test_ground_truth_takes_the_scene_exactly_as_given_even_where_its_bodies_carry_their_own_noise(ros, tower):
    # a perception stack may give each body its own noise; sigma = phi = 0 only drops the model's own
    noisy = dataclasses.replace(tower, objects=tuple(dataclasses.replace(b, position_sigma_m=0.02)
                                                     for b in tower.objects))
    node = ros.start_ipe_node(samples=4, sigma=0.0, phi=0.0, queries=["fall"])
    got = answers(ros)
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(noisy)))
    wait_until(lambda: len(got), TIMEOUT_S, "the answer at sigma = phi = 0")
    assert got[0]["deterministic"] is False and got[0]["samples"] == 4  # the bodies' own noise, drawn
    (result,) = set_params(ros, ground_truth=True)
    assert result.successful, result.reason
    response = ros.call(Trigger, "/ipe/predict", Trigger.Request(), timeout_s=TIMEOUT_S)
    assert response.success, response.message
    answer = json.loads(response.message)
    assert answer["deterministic"] is True and answer["samples"] == 1  # the scene exactly as given
    assert node.service.config.request.model.object_noise is False
    # questions are asked of the same model: one rollout per variant
    replies = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    ros.publisher(String, "/ipe/ask").publish(String(data=json.dumps(
        {"id": "g", "question": "remove", "objects": [tower.objects[-1].name]})))
    wait_until(lambda: any(json.loads(m.data)["final"] for m in list(replies)), TIMEOUT_S, "the question's answer")
    reply = next(json.loads(m.data) for m in replies if json.loads(m.data)["final"])
    assert reply["answer"]["samples_requested"] == 1, reply
    # the ground truth with a push is no ground truth: phi is read as 0 while it is on
    (result,) = set_params(ros, phi=[2.0])
    assert result.successful, result.reason
    assert node.service.config.request.model.phi_m_s2 == (0.0,)


def test_trigger_service_without_and_with_a_scene(ros, tower):
    node = ros.start_ipe_node(**FAST)
    response = ros.call(Trigger, "/ipe/predict", Trigger.Request())
    assert not response.success
    assert response.message == "no scene received yet; publish one on ~/scene (MarkerArray) or ~/scene_json"

    got = answers(ros)
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: node.service.stats().received == 1, TIMEOUT_S, "the scene to arrive")
    response = ros.call(Trigger, "/ipe/predict", Trigger.Request(), timeout_s=TIMEOUT_S)
    assert response.success
    answer = json.loads(response.message)
    assert answer["scene_id"] == tower.name and answer["samples"] == 6
    wait_until(lambda: len(got), TIMEOUT_S, "the topic answer")
    assert got[-1]["fall_fraction"] == answer["fall_fraction"]
    # Nothing changed: the service answers from the last prediction without simulating again.
    again = json.loads(ros.call(Trigger, "/ipe/predict", Trigger.Request()).message)
    assert again == answer and node.service.stats().predicted == 1


def test_parameter_updates_accepted_and_rejected(ros, tower):
    node = ros.start_ipe_node(**FAST)
    [ok] = set_params(ros, samples=3)
    assert ok.successful
    [bad_query] = set_params(ros, queries=["fall", "nope"])
    assert not bad_query.successful
    assert bad_query.reason == ("queries: unknown query 'nope'; choose from fall, any_fall, direction, far, bump, "
                                "contact, rest, final_pose, tipped")
    [bad_pair] = set_params(ros, contact_pairs="ball")
    assert bad_pair.reason == ('contact_pairs: a pair is written A:B (B may be support; names holding ":" as JSON: '
                               '["A", "B"]), got \'ball\'')
    [bad_preset] = set_params(ros, preset="fastest")
    assert bad_preset.reason == "preset: unknown preset 'fastest'; choose one of paper, accurate, fine, default"
    [bad_direction] = set_params(ros, force_direction_deg=math.inf)
    assert bad_direction.reason == "force_direction_deg: must be finite degrees or NaN (any direction), got inf"
    [width] = set_params(ros, target_ci_width=0.3)
    assert width.successful
    [bad_queries] = set_params(ros, queries=["far"])  # the width target needs the fall or any_fall query
    assert bad_queries.reason == ("target_ci_width: a target interval width needs the fall or any_fall query; add one "
                                  "to the queries or drop the target width")
    assert set_params(ros, target_ci_width=0.0)[0].successful
    [out_of_range] = set_params(ros, samples=0)
    assert not out_of_range.successful and "samples" in out_of_range.reason
    [empty_frame] = set_params(ros, frame_id="")
    assert empty_frame.reason == "frame_id: must be a non-empty frame name without surrounding spaces, got ''"
    [budget] = set_params(ros, budget_s=30.0)
    assert budget.successful and node.service.config.request.budget_s == 30.0
    [read_only] = set_params(ros, workers=1)
    assert not read_only.successful and "read-only" in read_only.reason
    assert node.get_parameter("samples").value == 3

    got = answers(ros)
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: len(got), TIMEOUT_S, "a prediction with the new sample count")
    assert got[0]["samples"] == 3 and got[0]["request"]["preset"] == "default"
    assert got[0]["stopped_by"] == "samples"


def test_contact_rest_and_final_pose_through_parameters(ros, tower):
    """Event questions on the node: the pairs as a parameter, the answers in the JSON, and a scene
    without an asked object answered with an error naming the parameter."""
    from tests.test_queries import _rolled

    node = ros.start_ipe_node(samples=4, sigma=0.01, seed=3, queries=["rest", "final_pose"],
                              contact_pairs="ball:box, ball:support")
    assert node.service.config.request.query.contact_pairs == (("ball", "box"), ("ball", "support"))
    got = answers(ros)
    pub = ros.publisher(String, "/ipe/scene_json")
    pub.publish(String(data=scene_to_json(_rolled(1.5))))
    wait_until(lambda: len(got), TIMEOUT_S, "an answer about the rolled ball")
    answer = got[0]
    assert answer["contact_probability"] == {"ball:box": 1.0, "ball:support": 1.0}
    assert answer["contact_at_start"] == {"ball:box": 0.0, "ball:support": 1.0}
    assert answer["request"]["contact"] == ["ball:box", "ball:support"]
    assert set(answer["final_pose"]) == {"ball", "box"} and answer["rest_probability"] is not None
    pub.publish(String(data=scene_to_json(tower)))  # no ball in it
    wait_until(lambda: len(got) == 2, TIMEOUT_S, "the refusal of the tower")
    assert got[1]["error"].startswith("contact_pairs: ball:box: no object 'ball' in scene")


def test_gravity_aligned_frames_decide_which_scene_frames_are_answered(ros, tower):
    node = ros.start_ipe_node(**FAST, gravity_aligned_frames=["odom", "base_footprint"], frame_id="odom")
    got = answers(ros)
    pub = ros.publisher(MarkerArray, "/ipe/scene")
    pub.publish(scene_to_markers(tower, "world"))  # not in this node's list
    wait_until(lambda: node.service.stats().rejected == 1, TIMEOUT_S, "the scene in 'world' to be refused")
    assert node.service.stats().last_error.startswith("header.frame_id: 'world' is not a gravity-aligned frame "
                                                      "(odom, base_footprint)")
    pub.publish(scene_to_markers(tower, "base_footprint"))
    wait_until(lambda: len(got) == 2, TIMEOUT_S, "the scene in 'base_footprint' to be answered")
    assert (got[0]["frame_id"], got[0]["error"]) == ("world", node.service.stats().last_error)  # the refusal
    assert got[1]["frame_id"] == "base_footprint" and "error" not in got[1]
    [outside] = set_params(ros, frame_id="camera_link")  # ~/scene_json's frame must be gravity-aligned too
    assert outside.reason == ("frame_id: 'camera_link' is not in gravity_aligned_frames ['odom', 'base_footprint']; "
                              "add it there if its -z axis is gravity, or publish scenes in one of those frames")
    trust_all = set_params(ros, gravity_aligned_frames=[""], frame_id="camera_link")  # [""]: every frame
    assert all(r.successful for r in trust_all) and node.service.config.gravity_aligned_frames == ()


@pytest.mark.parametrize("reliability", ["both", "best_effort", "reliable"])
def test_scene_topics_take_reliable_and_sensor_style_publishers_once_each(ros, tower, reliability):
    node = ros.start_ipe_node(**FAST, scene_reliability=reliability)
    got = answers(ros)
    reliable = ros.publisher(String, "/ipe/scene_json", RELIABLE_QOS)
    if reliability == "both":
        wait_until(lambda: reliable.get_subscription_count() == 2, 10.0, "both scene_json subscriptions")
    reliable.publish(String(data=scene_to_json(tower)))
    wait_until(lambda: len(got), TIMEOUT_S, "the reliably published scene's answer")
    if reliability == "reliable":  # a sensor-style publisher matches no subscription: documented
        sensor = ros.client.create_publisher(MarkerArray, "/ipe/scene", qos_profile_sensor_data)
        wait_until(lambda: node.count_publishers("/ipe/scene") >= 1, 10.0, "discovery of the sensor publisher")
        assert sensor.get_subscription_count() == 0
        return
    sensor = ros.publisher(MarkerArray, "/ipe/scene", qos_profile_sensor_data)
    scene = scene_to_markers(dataclasses.replace(tower, name="sensor_style"), "world", 1)
    wait_until(lambda: (sensor.publish(scene), any(a["scene_id"] == "sensor_style" for a in got))[1], TIMEOUT_S,
               "the best-effort scene's answer")  # best effort may drop a message: publish until one arrives
    # the reliable scene reached both subscriptions of "both" and was still used once
    assert sum(a["scene_id"] == tower.name for a in got) == 1
    assert node.service.stats().rejected == 0


def _good_and_bad_inputs(tower):
    nan_pose = scene_to_markers(tower, "world")
    nan_pose.markers[3].pose.position.x = math.nan
    zero_size = scene_to_markers(tower, "world")
    zero_size.markers[2].scale.y = 0.0
    mixed_frames = scene_to_markers(tower, "world")
    mixed_frames.markers[4].header.frame_id = "map"
    cube = scene_to_markers(tower, "world").markers[1]
    flood = MarkerArray(markers=[cube] * 10_000)
    return [
        ("scene_json", String(data='{"format": "ipe_ros.scene/1", "boxes": ['),
         "json: malformed JSON at line 1 column 41: Expecting value"),
        ("scene", nan_pose, "markers[3].pose.position: must be finite, got [nan, 0.025634670161324646, 0.5]"),
        ("scene", zero_size, "markers[2].scale: full sizes must be finite and > 0 m, got [0.2, 0.0, 0.2]"),
        ("scene", mixed_frames, "markers[4].header.frame_id: is 'map' but markers[0] is in 'world'; "
                                "publish every marker of a scene in one frame"),
        ("scene", flood, "markers: 10000 markers exceed max_objects = 200; raise the max_objects parameter "
                         "or publish a smaller scene"),
        ("scene_json", String(data="[" * 5000 + "]" * 5000),
         "json: nested too deeply to read; a scene nests a few levels (objects, shapes, parts), not hundreds"),
        ("scene_json", String(data=scene_to_json(dataclasses.replace(tower, name="\ud800"))),
         "name: must be valid Unicode text (it holds a lone surrogate), got '\\ud800'"),
        ("scene", scene_to_markers(tower, "camera_link"),
         "header.frame_id: 'camera_link' is not a gravity-aligned frame (world, map, odom); transform the scene "
         "into one of them, or add the frame to the gravity_aligned_frames parameter if its -z axis is gravity"),
        ("scene", MarkerArray(), "markers: the array holds no ADD markers; publish one CUBE, SPHERE, CYLINDER or "
                                 "TRIANGLE_LIST marker per body"),
    ]


def test_bad_inputs_are_rejected_and_the_next_good_scene_is_answered(ros, tower):
    node = ros.start_ipe_node(**FAST)
    diagnostics = ros.collect(DiagnosticArray, "/diagnostics", 10)
    got = answers(ros)
    pubs = {"scene": ros.publisher(MarkerArray, "/ipe/scene"), "scene_json": ros.publisher(String, "/ipe/scene_json")}
    bad = _good_and_bad_inputs(tower)
    for i, (topic, msg, reason) in enumerate(bad, start=1):
        pubs[topic].publish(msg)
        wait_until(lambda: node.service.stats().rejected == i and len(got) == i, TIMEOUT_S,
                   f"bad input {i} to be rejected and answered")
        assert node.service.stats().last_error == reason
        refusal = got[i - 1]  # the client hears why on the topic it reads answers from
        assert (refusal["error"], refusal["refused_on"], refusal["scene_seq"]) == (reason, f"/ipe/{topic}", None)
        if topic == "scene" and msg.markers:
            assert refusal["frame_id"] == msg.markers[0].header.frame_id
    assert got[0]["scene_id"] == "" and got[8]["frame_id"] == ""  # unreadable: what is known is echoed
    response = ros.call(Trigger, "/ipe/predict", Trigger.Request())
    assert response.message == ("the latest scene was rejected: markers: the array holds no ADD markers; "
                                "publish one CUBE, SPHERE, CYLINDER or TRIANGLE_LIST marker per body")
    pubs["scene"].publish(scene_to_markers(tower, "world"))
    wait_until(lambda: len(got) == len(bad) + 1, TIMEOUT_S, "the good scene's prediction")
    assert "error" not in got[len(bad)]
    stats = node.service.stats()
    assert (stats.rejected, stats.received, stats.predicted) == (len(bad), 1, 1)

    def rejected_in_diagnostics():
        for array in list(diagnostics):
            values = {kv.key: kv.value for kv in array.status[0].values}
            if values.get("scenes_rejected") == str(len(bad)) and values.get("scenes_predicted") == "1":
                return values
        return None
    values = wait_until(rejected_in_diagnostics, 10.0, "diagnostics counting the rejections")
    assert values["workers_alive"] == "2"
    assert diagnostics[-1].status[0].name == "/ipe: IPE prediction service"  # namespaced by the node's name


def test_a_killed_worker_is_replaced_and_the_prediction_still_answered(ros, tower):
    node = ros.start_ipe_node(samples=16)
    got = answers(ros)
    pool = node.service.pool
    pids = wait_until(lambda: len(pool.worker_pids()) == 2 and pool.worker_pids(), 30.0, "two live workers")
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: node.service.stats().in_flight, TIMEOUT_S, "the prediction to start")
    os.kill(pids[0], signal.SIGKILL)
    wait_until(lambda: len(got), TIMEOUT_S, "the prediction despite the killed worker")
    assert got[0]["samples"] == 16 and got[0]["failed_samples"] == 0
    stats = node.service.stats()
    assert stats.worker_replacements >= 1
    assert pids[0] not in pool.worker_pids()
    # And the node keeps serving with the new workers.
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
    wait_until(lambda: len(got) >= 2, TIMEOUT_S, "a second prediction on the replaced pool")
    assert got[1]["fall_fraction"] == got[0]["fall_fraction"]


def test_rerun_recording_is_written_and_holds_the_rollouts(ros, tower, tmp_path):
    from rerun.chunk import RrdReader

    ros.start_ipe_node(**FAST, **{"rerun.save_dir": str(tmp_path), "rerun.rollouts_logged": 2})
    got = answers(ros)
    ros.publisher(MarkerArray, "/ipe/scene").publish(scene_to_markers(tower, "world", 42))
    wait_until(lambda: len(got), TIMEOUT_S, "a prediction with a recording")
    path = got[0]["rrd_path"]
    assert path and os.path.exists(path) and got[0]["rollouts_logged"] == 2
    chunks = RrdReader(path).stream().to_chunks()
    entities = {c.entity_path for c in chunks}
    name = tower.dynamic_objects[0].name
    assert {f"/world/rollouts/0/{name}", f"/world/rollouts/1/{name}", f"/world/scene/objects/{name}",
            "/answer"} <= entities
    assert f"/world/rollouts/2/{name}" not in entities
    moving = [c for c in chunks if c.entity_path == f"/world/rollouts/0/{name}" and not c.is_static]
    assert moving and set(moving[0].timeline_names) == {"sim_time", "ros_stamp"}
    # a frame every 20 ms (rounded to whole steps) of the simulated time, plus t = 0
    from ipe_ros.engine import preset as get_preset
    step_s = get_preset("default").time_step_s
    every = max(1, round(0.02 / step_s))
    assert 1 + round(0.3 / step_s) // every <= sum(c.num_rows for c in moving) <= 1 + round(2.0 / step_s) // every


def test_questions_on_ask_are_answered_on_answer_with_their_id(ros, tower, tmp_path):
    from tests.test_actions import STACK

    node = ros.start_ipe_node(samples=4, sigma=0.005, **{"rerun.save_dir": str(tmp_path), "rerun.rollouts_logged": 2})
    got = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    graph_markers = ros.collect(MarkerArray, "/ipe/support_graph", LATCHED_QOS)
    ask = ros.publisher(String, "/ipe/ask")
    ask.publish(String(data=json.dumps({"id": "too-early", "question": "remove"})))
    wait_until(lambda: len(got), TIMEOUT_S, "the refusal of a question with no scene")
    first = json.loads(got[0].data)
    assert first["id"] == "too-early" and first["error"].startswith("no scene received yet") and first["final"]
    finals = lambda: [json.loads(m.data) for m in list(got) if json.loads(m.data)["final"]]  # noqa: E731
    # a question that brings its own scene
    request = {"id": "r1", "question": "support", "samples": 4, "scene": json.loads(scene_to_json(STACK))}
    ask.publish(String(data=json.dumps(request)))
    wait_until(lambda: len(finals()) >= 2 and len(graph_markers), TIMEOUT_S, "the support graph answer and its markers")
    answer = finals()[1]
    assert answer["id"] == "r1" and answer["scene_id"] == "stack"
    assert answer["answer"]["edges"] == [["bottom", "top", 1.0]]
    assert [s["name"] for s in answer["answer"]["safe_to_remove"]] == ["top"]
    assert answer["rrd_path"].endswith("_support_r1.rrd") and os.path.getsize(answer["rrd_path"]) > 0
    # before it, what was decided after the one batch of 4 samples (anytime)
    (partial,) = [json.loads(m.data) for m in got if not json.loads(m.data)["final"]]
    assert partial["id"] == "r1" and partial["progress"]["samples_drawn"] == 4
    assert partial["progress"]["decided"] == [{"label": "remove/bottom", "decision": "unsafe", "stopped_by": "decided",
                                               "samples_drawn": 4, "samples": 4}]
    assert [u["label"] for u in partial["progress"]["undecided"]] == ["remove/top"]
    lines = [m for m in graph_markers[-1].markers if m.type == Marker.LINE_LIST]
    assert len(lines) == 1 and len(lines[0].points) == 2
    # about the newest scene the node accepted, and a bad question refused by name
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(STACK)))
    wait_until(lambda: node.service.latest_scene() is not None, TIMEOUT_S, "the scene to be accepted")
    ask.publish(String(data=json.dumps({"id": "r2", "question": "push", "object": "bottom", "velocity_m_s": [2, 0],
                                        "contact": ["top:support"]})))
    ask.publish(String(data=json.dumps({"id": "r3", "question": "fly"})))
    wait_until(lambda: len(finals()) >= 4, TIMEOUT_S, "answers to r2 and r3")
    by_id = {m["id"]: m for m in finals()}
    assert by_id["r3"]["error"] == "question: must be one of remove, support, clear, place, push, got 'fly'"
    as_is, pushed = by_id["r2"]["answer"]["variants"]
    assert pushed["label"] == "push/bottom" and pushed["object_fall_probability"]["top"] == 1.0
    # the event question on ~/ask: pushed away at 2 m/s, the bottom leaves the top to fall to the floor
    assert pushed["contact_probability"] == {"top:support": 1.0} and as_is["contact_probability"] == {"top:support": 0.0}



def test_every_question_gets_exactly_one_reply_under_a_flood_and_when_too_large(ros):
    import collections

    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    from ipe_ros.ros.node import ASK_QOS
    from tests.test_actions import STACK

    node = ros.start_ipe_node(samples=2, sigma=0.005)
    reader = QoSProfile(depth=1, history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)
    got = ros.collect(String, "/ipe/answer", reader)
    ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(STACK)))
    wait_until(lambda: node.service.latest_scene() is not None, TIMEOUT_S, "the scene to be accepted")
    ask = ros.publisher(String, "/ipe/ask", ASK_QOS)
    flood = 5000
    for i in range(flood):  # as fast as one publisher goes (~0.4 s here)
        ask.publish(String(data=json.dumps({"id": f"q{i}", "question": "remove", "objects": ["top"]})))
    ask.publish(String(data=json.dumps({"id": "huge", "question": "support", "note": "x" * 16_500_000})))
    region = {"x_m": [-1, 1], "y_m": [-1, 1], "candidates": 400, "yaws": 400}
    ask.publish(String(data=json.dumps({"id": "search", "question": "place", "region": region, "object": {
        "name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]}, "mass_kg": 1.0, "friction": 0.5,
        "restitution": 0.0}})))
    replies = lambda: [json.loads(m.data) for m in list(got)]  # noqa: E731
    wait_until(lambda: len(got) >= flood + 2, 120.0, f"{flood + 2} replies")
    counts = collections.Counter(r["id"] for r in replies())
    assert len(counts) == flood + 2 and set(counts.values()) == {1}  # every question once, none twice
    by_id = {r["id"]: r for r in replies()}
    busy = [r for r in by_id.values() if r.get("error", "").startswith("busy: ")]
    answered = [r for r in by_id.values() if "answer" in r]
    assert len(busy) + len(answered) == flood and len(answered) >= 1
    assert by_id["huge"]["error"] == ("data: 16500049 characters exceed the maximum of 16000000 for a question; send "
                                      "the scene on ~/scene_json and ask about it without \"scene\"")
    assert by_id["search"]["error"].startswith("region.candidates: 400 candidates x 400 yaws are 160000 placements")
    ask.publish(String(data=json.dumps({"id": "after", "question": "remove", "objects": ["top"]})))  # still answering
    wait_until(lambda: any(r["id"] == "after" and "answer" in r for r in replies()), TIMEOUT_S, "the next answer")


def test_depth_perception_predicts_from_the_newest_depth_image(ros):
    import time

    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import CameraInfo, Image

    from ipe_ros.engine.vision.camera import look_at
    from ipe_ros.engine.vision.tinyrenderer import depth_with_pybullet
    from msg_bridge.depth import depth_m_to_image
    from msg_bridge.stamps import stamp_ns_to_header
    from tests.test_depth import cube, floor

    scene = floor(cube("bottom", 0, 0, 0.05), cube("top", 0.01, 0, 0.15), name="seen")
    camera = look_at((1.0, -0.7, 0.6), (0, 0, 0.1))
    node = ros.start_ipe_node(samples=4, perception="depth", self_check=False, workers=0)
    got = answers(ros)
    perceived = ros.collect(MarkerArray, "/ipe/perceived_scene", LATCHED_QOS)
    scenes = ros.publisher(String, "/ipe/scene_json")
    scenes.publish(String(data=scene_to_json(scene)))  # no depth image yet: answered with the reason
    wait_until(lambda: len(got) >= 1, TIMEOUT_S, "the refusal of a scene without a depth image")
    assert got[0]["error"].startswith("perception: depth: no depth image received yet; publish ~/depth/image")
    info = CameraInfo(width=camera.width_px, height=camera.height_px,
                      k=[camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy, 0.0, 0.0, 1.0])
    pose = PoseStamped(header=stamp_ns_to_header(time.time_ns(), "world"))
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = camera.position_m
    (pose.pose.orientation.x, pose.pose.orientation.y, pose.pose.orientation.z,
     pose.pose.orientation.w) = camera.orientation_xyzw
    ros.publisher(CameraInfo, "/ipe/depth/camera_info", qos_profile_sensor_data).publish(info)
    ros.publisher(PoseStamped, "/ipe/depth/camera_pose", qos_profile_sensor_data).publish(pose)
    wait_until(lambda: {"~/depth/camera_info", "~/depth/camera_pose"} <= set(node.service.evidence.held("depth")),
               TIMEOUT_S, "camera info and pose")
    images = ros.publisher(Image, "/ipe/depth/image", qos_profile_sensor_data)
    images.publish(Image(encoding="rgb8", width=2, height=1, step=6, data=bytes(6)))  # not a depth image: refused
    wait_until(lambda: node.service.stats().evidence["depth_images_refused"] == 1, TIMEOUT_S, "the refusal of an rgb8 image")
    images.publish(depth_m_to_image(depth_with_pybullet(scene, camera), time.time_ns(), "camera", "16UC1"))
    wait_until(lambda: node.service.evidence.latest_view_stamp_ns("depth") is not None, TIMEOUT_S, "the depth image")
    scenes.publish(String(data=scene_to_json(scene)))
    wait_until(lambda: len(got) >= 2, TIMEOUT_S * 2, "the prediction with depth perception")
    perception = got[1]["request"]["perception"]
    assert perception["kind"] == "depth" and set(perception["objects"]) == {"bottom", "top"}
    assert perception["objects"]["top"]["x_sd_m"] < 0.01 and got[1]["samples"] == 4
    # the refined scene, in ~/scene's own format, its objects where the posterior puts them
    wait_until(lambda: perceived, TIMEOUT_S, "the perceived scene")
    refined = {b.name: b for b in markers_to_scene(perceived[-1]).scene.objects}
    for name, estimate in perception["objects"].items():
        assert np.allclose(refined[name].position_m, estimate["position_m"], atol=1e-6)
    # the same view predicted again (a parameter changed, ~/predict called) reuses its posterior
    assert all(r.successful for r in set_params(ros, preset="fine"))
    response = ros.call(Trigger, "/ipe/predict", Trigger.Request())
    assert response.success, response.message
    again = json.loads(response.message)
    assert again["request"]["preset"] == "fine" and again["request"]["perception"]["objects"] == perception["objects"]
    assert node.service.stats().evidence["depth_posteriors"] == 1
    # questions about the view draw from the same chain (thinned to their k), and say so
    replies = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    ros.publisher(String, "/ipe/ask").publish(String(data=json.dumps({"id": "q", "question": "push", "samples": 2,
                                                                      "object": "top", "velocity_m_s": [1, 0]})))
    wait_until(lambda: any(json.loads(m.data)["final"] for m in replies), TIMEOUT_S, "the answer to the question")
    final = next(json.loads(m.data) for m in replies if json.loads(m.data)["final"])
    assert final["perception"]["kind"] == "depth" and final["perception"]["samples"] == 2, final
    assert final["perception"]["objects"] == perception["objects"]  # the view's posterior, not a chain of its own
    assert "answer" in final and node.service.stats().evidence["depth_posteriors"] == 1


def test_a_640_x_480_depth_stream_at_10_hz_arrives_whole(ros):
    """Fast DDS loses most best-effort messages over ~500 KB in their fragments on loopback (0-3 of 20
    measured); a reliable publisher's images come through the node's reliable subscription, each used once."""
    import time

    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CameraInfo, Image

    from msg_bridge.depth import depth_m_to_image
    from msg_bridge.stamps import stamp_ns_to_header

    node = ros.start_ipe_node(samples=4, perception="depth", self_check=False, workers=0)
    info = CameraInfo(width=640, height=480, k=[525.0, 0.0, 319.5, 0.0, 525.0, 239.5, 0.0, 0.0, 1.0])
    pose = PoseStamped(header=stamp_ns_to_header(time.time_ns(), "world"))
    pose.pose.position.z, pose.pose.orientation.w = 1.5, 1.0
    reliable = QoSProfile(depth=5, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.RELIABLE)
    ros.publisher(CameraInfo, "/ipe/depth/camera_info", reliable, subscribers=2).publish(info)
    ros.publisher(PoseStamped, "/ipe/depth/camera_pose", reliable, subscribers=2).publish(pose)
    wait_until(lambda: {"~/depth/camera_info", "~/depth/camera_pose"} <= set(node.service.evidence.held("depth")),
               TIMEOUT_S, "camera info and pose")
    images = ros.publisher(Image, "/ipe/depth/image", reliable, subscribers=2)  # both subscriptions match
    depth = np.full((480, 640), 1.5)
    for i in range(10):
        images.publish(depth_m_to_image(depth, time.time_ns(), "camera", "16UC1"))
        time.sleep(0.1)  # the camera's 10 Hz
    wait_until(lambda: node.service.stats().evidence["depth_images"] == 10, TIMEOUT_S, "all 10 depth images")
    stats = node.service.stats()
    assert stats.evidence["depth_images"] == 10 and stats.evidence["depth_images_refused"] == 0  # each once, though both subscriptions match


def test_a_mesh_marker_is_read_under_mesh_roots_and_refused_where_none_are_set(ros, tmp_path, monkeypatch):
    """A robot names its objects by their models: a MESH_RESOURCE mug with a ball in it is answered
    (the ball stays in), and only from the folders the operator configured."""
    pytest.importorskip("trimesh")
    from tests.test_meshes import mug_mesh

    monkeypatch.setenv("IPE_CACHE_DIR", str(tmp_path / "cache"))
    mug_mesh().export(tmp_path / "mug.obj")
    mug = Marker(type=Marker.MESH_RESOURCE, action=Marker.ADD, ns="objects", id=1, text="name=mug density=2000",
                 mesh_resource=f"file://{tmp_path}/mug.obj")
    mug.scale.x = mug.scale.y = mug.scale.z = 1.0
    ball = Marker(type=Marker.SPHERE, action=Marker.ADD, ns="objects", id=2, text="name=ball mass=0.02")
    ball.scale.x = ball.scale.y = ball.scale.z = 0.03
    ball.pose.position.z = 0.0215
    for m in (mug, ball):
        m.header.frame_id = "world"
        m.pose.orientation.w = 1.0
    node = ros.start_ipe_node(samples=1, ground_truth=True, preset="paper", mesh_roots=str(tmp_path))
    got = answers(ros)
    pub = ros.publisher(MarkerArray, "/ipe/scene")
    pub.publish(MarkerArray(markers=[mug, ball]))
    wait_until(lambda: len(got) >= 2, TIMEOUT_S, "the mug's answer")
    # first "decomposing" (the mesh is new: decomposed off the executor), then the answer
    assert got[0]["decomposing"]["object"] == "markers[0].mesh_resource", got[0]
    assert got[0]["decomposing"]["mesh"] == "mug.obj" and got[0]["received_on"] == "/ipe/scene"
    assert "error" not in got[1], got[1]
    assert got[1]["object_fall_probability"] == {"mug": 0.0, "ball": 0.0}
    # where the node may read is fixed at start-up: no participant may point it elsewhere (issue 76)
    (result,) = set_params(ros, mesh_roots="/")
    assert not result.successful and "read-only" in result.reason
    assert node.service.config.meshes.roots == (tmp_path,)
    assert node.service.stats().rejected == 0


def _mesh_scene(name: str, uri: str, **fields) -> str:
    return json.dumps({"format": "ipe_ros.scene/2", "name": name, "gravity_m_s2": [0.0, 0.0, -9.81],
                       "support": {"type": "floor", "height_m": 0.0, "friction": 0.6, "restitution": 0.0},
                       "objects": [{"name": name, "shape": {"type": "mesh", "uri": uri}, "position_m": [0, 0, 0.016],
                                    "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], "mass_kg": 0.2, "friction": 0.6,
                                    "restitution": 0.0, "group": "", "static": False, **fields}]})


def test_a_new_mesh_decomposes_off_the_executor_and_its_refusal_is_remembered(ros, tmp_path, monkeypatch):
    """Issues 73 and 76: a mesh not yet decomposed never holds up intake. Its scene is answered
    "decomposing" at once while a question about another scene is answered; a decomposition over
    ``mesh_decomposition_s`` is ended and the scene refused, and sent again it is refused at once
    (remembered, not decomposed for another 8 s); a question whose own scene holds a new mesh
    hears "decomposing" (not final), then its one final answer."""
    trimesh = pytest.importorskip("trimesh")
    from tests.test_actions import STACK

    monkeypatch.setenv("IPE_CACHE_DIR", str(tmp_path / "cache"))
    # ~25 s to decompose here (16 200 vertices): far over the 8 s allowed on any machine
    trimesh.creation.torus(0.05, 0.015, major_sections=180, minor_sections=90).export(tmp_path / "slow.obj")
    trimesh.creation.torus(0.05, 0.015, major_sections=24, minor_sections=12).export(tmp_path / "quick.obj")
    node = ros.start_ipe_node(samples=1, ground_truth=True, mesh_roots=str(tmp_path), mesh_decomposition_s=8.0)
    got = answers(ros)
    replies = ros.collect(String, "/ipe/answer", LATCHED_QOS)
    decoded = lambda: [json.loads(m.data) for m in list(replies)]  # noqa: E731
    scenes = ros.publisher(String, "/ipe/scene_json")
    ask = ros.publisher(String, "/ipe/ask")
    scenes.publish(String(data=_mesh_scene("slow", str(tmp_path / "slow.obj"))))
    wait_until(lambda: len(got), TIMEOUT_S, "the slow mesh's scene answered \"decomposing\"")
    assert got[0]["decomposing"] == {"object": "objects[0].shape.uri", "mesh": "slow.obj", "triangles": 32400,
                                     "meshes_ahead": 0, "within_s": 8.0}, got[0]
    ask.publish(String(data=json.dumps({"id": "other", "question": "remove", "objects": ["top"],
                                        "scene": json.loads(scene_to_json(STACK))})))
    wait_until(lambda: any(r["final"] for r in decoded()), TIMEOUT_S, "the other scene's question answered")
    assert node.decompositions.status()["decomposing"]["mesh"] == "slow.obj"  # answered meanwhile
    assert len(got) == 1 and "answer" in decoded()[-1], decoded()[-1]
    wait_until(lambda: len(got) >= 2, TIMEOUT_S, "the slow mesh's refusal")
    assert got[1]["error"].startswith("objects[0].shape.uri: its convex decomposition did not finish within 8 s; "
                                      "decompose it once ahead"), got[1]
    assert got[1]["refused_on"] == "/ipe/scene_json" and node.decompositions.status()["decomposing"] is None
    scenes.publish(String(data=_mesh_scene("slow", str(tmp_path / "slow.obj"))))
    wait_until(lambda: len(got) >= 3, 5.0, "the same scene refused at once")
    assert "decomposing" not in got[2] and "(remembered from " in got[2]["error"], got[2]
    beside = json.loads(_mesh_scene("quick", str(tmp_path / "quick.obj")))
    beside["objects"].append({**beside["objects"][0], "name": "block", "position_m": [0.5, 0.0, 0.05],
                              "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]}})
    ask.publish(String(data=json.dumps({"id": "ring", "question": "remove", "objects": ["block"], "scene": beside})))
    wait_until(lambda: any(r["final"] and r["id"] == "ring" for r in decoded()), TIMEOUT_S, "the ring's answer")
    ring = [r for r in decoded() if r["id"] == "ring"]
    assert [r["final"] for r in ring] == [False, True] and ring[0]["decomposing"]["mesh"] == "quick.obj", ring
    assert "answer" in ring[1] and ring[1]["scene_id"] == "quick", ring[1]
    assert node.decompositions.status() == {"decomposing": None, "meshes_waiting": 0, "inputs_waiting": 0,
                                            "decomposed": 1, "refused": 1}


def test_a_parameter_set_replaces_the_defaults_and_an_override_wins(ros, tmp_path):
    """``inputs_from``: ipe fit's output loaded at start (issue 74): its inputs become the parameters'
    values, an override given beside it wins, and the request the node answers with has them."""
    fitted = tmp_path / "fit.json"
    fitted.write_text(json.dumps({"format": "ipe_ros.inputs/1", "inputs": {
        "sigma": 0.01, "launch_direction_sd_deg": 12.0, "phi": [0.0, 0.5]}, "provenance": {"made_by": "a test"}}))
    node = ros.start_ipe_node(**{**FAST, "sigma": 0.03}, inputs_from=str(fitted))
    assert node.get_parameter("sigma").value == 0.03  # the override
    assert node.get_parameter("launch_direction_sd_deg").value == 12.0
    assert list(node.get_parameter("phi").value) == [0.0, 0.5]
    model = node.service.config.request.model
    assert model.sigma_m == 0.03 and model.phi_m_s2 == (0.0, 0.5)
    assert model.launch_spread.direction_sd_rad == pytest.approx(math.radians(12.0))


def test_a_file_that_is_not_a_parameter_set_is_refused_naming_inputs_from(ros, tmp_path):
    bad = tmp_path / "fit.json"
    bad.write_text(json.dumps({"format": "ipe_ros.inputs/1", "inputs": {"sigma": -1}}))
    with pytest.raises(ConfigError) as caught:
        ros.start_ipe_node(**FAST, inputs_from=str(bad))
    assert str(caught.value) == "inputs_from: fit.json: sigma: must be in [0, 10] m, got -1"
