"""Property-based fuzzing of everything a robot (or an attacker) can send, through the node's own path.

The node reads a scene (``msg_bridge``), checks it against its config (``PredictionService.check``:
validation, ranges, the budget's up-front estimate) and predicts (the engine, with the budget).
The invariant, for any input: either a one-line error that names a field (``SceneError`` /
``ConfigError``, both ``ValueError``), or a valid answer (JSON-ready, every sample accounted for)
within the budget; never an exception of another kind, never longer than the budget.

Profiles (tests/conftest.py): ``ci`` (default, ~1 min) and ``soak`` for long local runs:
``scripts/test.sh tests/test_fuzz.py --hypothesis-profile soak``.
"""

from __future__ import annotations

import copy
import json
import time

import pytest

from hypothesis import HealthCheck, given, settings, strategies as st

from geometry_msgs.msg import Point
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from ipe_ros.engine import ModelConfig, QuerySpec, SceneError, ConfigError, predict, preset
from ipe_ros.engine import Context
from ipe_ros.engine.scene.catalogue import capped_tower
from ipe_ros.engine.errors import MAX_PROBLEM_CHARS, MAX_SHOWN_CHARS
from ipe_ros.engine.scene.format import scene_to_dict
from ipe_ros.engine.request import Request
from ipe_ros.service import ServiceConfig
from msg_bridge.json_text import string_to_scene
from msg_bridge.markers import markers_to_scene, scene_to_markers

BUDGET_S = 3.0
#: what a prediction may overrun its budget by: the rollout in flight notices within one step
BUDGET_SLACK_S = 1.0
CONFIG = ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.02, samples=2), settings=preset("default"),
                                       query=QuerySpec(queries=frozenset({"fall", "direction", "far", "any_fall"})),
                                       budget_s=BUDGET_S), max_objects=20)
REQUEST = CONFIG.request
BASE = scene_to_dict(capped_tower(3.0))


def _check_error(exc: ValueError) -> None:
    text = str(exc)
    assert "\n" not in text, text
    assert len(text) <= MAX_SHOWN_CHARS + MAX_PROBLEM_CHARS + 80, len(text)
    if isinstance(exc, (SceneError, ConfigError)):
        assert exc.field and text.startswith(exc.field), text
    else:  # the bridge's own errors name a field too: "data: ...", "markers[2].scale: ..."
        assert ": " in text, text
    assert "NoneType" not in text and "<class" not in text, text  # JSON type names, not Python's


def _through_the_node(read):
    """Read, check, predict: the invariant above. Returns the prediction, or None for a refusal."""
    from ipe_ros.engine.predict import check_request

    try:
        scene = read()
        check_request(scene, REQUEST.query, CONFIG.max_objects, model=REQUEST.model, settings=REQUEST.settings,
                      budget_s=REQUEST.budget_s)
    except ValueError as exc:
        _check_error(exc)
        return None
    start = time.monotonic()
    prediction = predict(scene,
                         Request(model=REQUEST.model, settings=REQUEST.settings, query=REQUEST.query, seed=1,
                                 budget_s=REQUEST.budget_s),
                         Context(max_objects=CONFIG.max_objects))
    assert time.monotonic() - start <= BUDGET_S + BUDGET_SLACK_S
    assert prediction.samples + prediction.failed_samples + prediction.budget_skipped_samples == \
        prediction.samples_requested
    json.dumps(prediction.to_dict(), allow_nan=False)  # what the node publishes
    return prediction


# -- random JSON -----------------------------------------------------------------------------------
json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=12), inner, max_size=5),
    max_leaves=30)


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(json_values)
def test_any_json_value_is_answered_or_refused_by_name(value):
    _through_the_node(lambda: string_to_scene(String(data=json.dumps(value))))


@given(st.text(max_size=200))
def test_any_text_is_answered_or_refused_by_name(text):
    _through_the_node(lambda: string_to_scene(String(data=text)))


# -- mutations of a valid scene -------------------------------------------------------------------------
def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _paths(value, prefix + (i,))


numbers = st.one_of(st.floats(), st.integers(min_value=-10**30, max_value=10**30),
                    st.sampled_from([0.0, -0.0, 1e-320, 1e-9, 1e15, 1e300, -1e300, 5e-324]))


MUTATIONS = ("number", "scale", "value", "delete", "extra")


def _mutated(draw, base, scale_exponent: int = 0, kinds: tuple[str, ...] = MUTATIONS):
    """A copy of ``base`` with 1-3 of its values replaced (a number, the value scaled by 10^+-n, any
    JSON value, any text where it was text), deleted, or given a sibling key."""
    document = copy.deepcopy(base)
    paths = [p for p in _paths(document) if p]
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(paths))
        parent = document
        try:
            for key in path[:-1]:
                parent = parent[key]
            old = parent[path[-1]]
        except (KeyError, IndexError, TypeError):
            continue
        if not isinstance(parent, (dict, list)):  # an earlier mutation made it a string
            continue
        kind = draw(st.sampled_from(kinds))
        if kind == "number":
            parent[path[-1]] = draw(numbers)
        elif kind == "scale" and isinstance(old, (int, float)) and not isinstance(old, bool):
            exponent = draw(st.integers(-scale_exponent, scale_exponent))
            parent[path[-1]] = old * 10.0 ** exponent * draw(st.sampled_from([1, -1]))
        elif kind == "value":
            parent[path[-1]] = draw(json_values)
        elif kind == "delete" and isinstance(parent, dict):
            del parent[path[-1]]
        elif kind == "extra" and isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=8))] = draw(json_values)
        elif kind == "text" and isinstance(old, str):
            parent[path[-1]] = draw(st.text(max_size=40))
    return document


@st.composite
def mutated_scenes(draw):
    return _mutated(draw, BASE, 12)


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(mutated_scenes())
@pytest.mark.slow
def test_mutated_scenes_are_answered_within_budget_or_refused_by_name(scene):
    _through_the_node(lambda: string_to_scene(String(data=json.dumps(scene))))


# -- random MarkerArrays ---------------------------------------------------------------------------------
MARKER_TYPES = [Marker.CUBE, Marker.SPHERE, Marker.CYLINDER, Marker.TRIANGLE_LIST, Marker.ARROW, Marker.TEXT_VIEW_FACING]
floats = st.one_of(st.floats(width=64), st.sampled_from([0.0, 1e-320, 0.2, 0.05, 1e9, -0.1]))


@st.composite
def marker_arrays(draw):
    base = scene_to_markers(capped_tower(3.0), "world")
    markers = list(base.markers)
    for _ in range(draw(st.integers(0, 4))):
        if not markers:
            break
        i = draw(st.integers(0, len(markers) - 1))
        m = markers[i]
        field = draw(st.sampled_from(["type", "scale", "position", "orientation", "text", "frame", "action",
                                      "points", "drop", "duplicate"]))
        if field == "type":
            m.type = draw(st.sampled_from(MARKER_TYPES))
        elif field == "scale":
            setattr(m.scale, draw(st.sampled_from("xyz")), draw(floats))
        elif field == "position":
            setattr(m.pose.position, draw(st.sampled_from("xyz")), draw(floats))
        elif field == "orientation":
            setattr(m.pose.orientation, draw(st.sampled_from("xyzw")), draw(floats))
        elif field == "text":
            m.text = draw(st.one_of(st.text(max_size=60), st.sampled_from(
                ["mass=1e300", "vx=nan", "sigma=-1", "name=\u00e9;mass=1", "role=support", "vx=1e9", "mass=abc"])))
        elif field == "frame":
            m.header.frame_id = draw(st.sampled_from(["", "map", "world"]))
        elif field == "action":
            m.action = draw(st.sampled_from([Marker.ADD, Marker.DELETE, Marker.DELETEALL, 7]))
        elif field == "points":
            m.points = [Point(x=draw(floats), y=draw(floats), z=draw(floats)) for _ in range(draw(st.integers(0, 5)))]
        elif field == "drop":
            markers.pop(i)
        else:
            markers.append(copy.deepcopy(m))
    return MarkerArray(markers=markers)


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(marker_arrays())
@pytest.mark.slow
def test_random_marker_arrays_are_answered_within_budget_or_refused_by_name(msg):
    _through_the_node(lambda: markers_to_scene(msg, max_objects=CONFIG.max_objects).scene)


def test_the_unmutated_inputs_reach_the_engine():
    """The fuzzing starts from inputs that are answered, so mutations probe the engine, not only the parser."""
    for read in (lambda: string_to_scene(String(data=json.dumps(BASE))),
                 lambda: markers_to_scene(scene_to_markers(capped_tower(3.0), "world"), max_objects=20).scene):
        prediction = _through_the_node(read)
        assert prediction is not None and prediction.samples == REQUEST.model.samples


# -- questions (~/ask) --------------------------------------------------------------------------------------
QUESTIONS = [
    {"id": "r1", "question": "support", "samples": 2},
    {"id": "r2", "question": "remove", "objects": ["box0"], "samples": 2, "contact": ["box1:support"]},
    {"id": "r3", "question": "clear", "target": "box1", "samples": 2},
    {"id": "r4", "question": "push", "object": "box1", "velocity_m_s": [1.0, 0.0], "point_m": [0.1, 0.0, 0.5],
     "direction_sigma_deg": 5.0, "speed_sigma": 0.1, "samples": 2, "contact": ["box1:box0", "cone:support"]},
    {"id": "r5", "question": "place", "object": {"name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]}, "mass_kg": 1.0,
                                                 "friction": 0.5, "restitution": 0.0},
     "at": [[0.6, 0.0, 30.0]], "samples": 2},
    {"id": "r6", "question": "place", "object": {"name": "new", "shape": {"type": "sphere", "radius_m": 0.05}, "mass_kg": 1.0,
                                                 "friction": 0.5, "restitution": 0.0},
     "region": {"x_m": [0.5, 0.9], "y_m": [-0.2, 0.2], "yaw_deg": [0, 90], "candidates": 4, "yaws": 2}, "samples": 2},
]
QUESTION_SCENE = capped_tower(3.0)  # box0..box2, a cone on top, a ball at x = -1


@st.composite
def mutated_questions(draw):
    return _mutated(draw, draw(st.sampled_from(QUESTIONS)), 6)


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(mutated_questions())
def test_mutated_questions_are_answered_within_budget_or_refused_by_name(question):
    """The node's question path: read (msg_bridge), then answer with the node's budget. Either a
    one-line error naming a field, or a JSON answer within the budget (+ slack)."""
    from msg_bridge.ask_json import string_to_question

    start = time.monotonic()
    try:
        parsed, _ = string_to_question(String(data=json.dumps(question)))
        answer = parsed.answer(QUESTION_SCENE, REQUEST.model, REQUEST.settings, seed=1, budget_s=BUDGET_S).data
    except ValueError as exc:
        _check_error(exc)
        return
    assert time.monotonic() - start <= BUDGET_S + BUDGET_SLACK_S
    json.dumps(answer, allow_nan=False)


# -- the result store --------------------------------------------------------------------------------------
def _store_entry() -> tuple[str, dict]:
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.compute.store import encode_entry

    # the contact and final_pose values ride in the entry too (mappings of arrays and numbers)
    [task] = make_tasks(capped_tower(3.0), ModelConfig(sigma_m=0.02, samples=1), preset("default"),
                        QuerySpec(queries=frozenset({"fall", "direction", "contact", "final_pose"}),
                                  contact_pairs=(("cone", "support"),)), 0)
    return "k" * 64, json.loads(encode_entry(run_sample(task), "k" * 64))


STORE_KEY, STORE_ENTRY = _store_entry()


@st.composite
def mutated_entries(draw):
    return json.dumps(_mutated(draw, STORE_ENTRY, kinds=("value", "delete", "extra", "text"))).encode()


@settings(suppress_health_check=[HealthCheck.too_slow])
@given(mutated_entries() | st.binary(max_size=200))
def test_any_store_entry_reads_back_as_a_result_or_is_refused_in_one_line(data):
    from ipe_ros.engine.sampling.rollout import SampleOutcome
    from ipe_ros.engine.compute.store import StoreEntryError, decode_entry

    try:
        result = decode_entry(data, STORE_KEY)
    except StoreEntryError as exc:
        assert "\n" not in str(exc) and len(str(exc)) < 400
        return
    assert isinstance(result, SampleOutcome)  # the only type this key's entry may hold


def test_the_unmutated_questions_are_answered():
    """The fuzz starts from questions the engine answers (else it would only exercise refusals)."""
    from msg_bridge.ask_json import string_to_question

    for question in QUESTIONS:
        parsed, _ = string_to_question(String(data=json.dumps(question)))
        answer = parsed.answer(QUESTION_SCENE, REQUEST.model, REQUEST.settings, seed=1, budget_s=BUDGET_S).data
        json.dumps(answer, allow_nan=False)
