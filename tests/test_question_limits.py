"""Questions under the same budget rule as predictions (issue 34): every number a question carries has
a limit, the estimated cost is refused up front, and a wall-clock deadline is checked inside (also
in the geometry before any simulation). Each test failed before the fix."""

from __future__ import annotations

import time

import pytest

from ipe_ros.engine import ConfigError
from ipe_ros.engine import actions as A
from ipe_ros.engine.actions import questions
from ipe_ros.engine.actions.checks import check_action
from ipe_ros.engine.actions.question import new_object_from_dict, question_from_dict
from tests.test_actions import MODEL, SETTINGS, STACK, box, scene

CUBE = {"name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]}, "mass_kg": 1.0, "friction": 0.5,
        "restitution": 0.0}


def _refused(data) -> str:
    started = time.perf_counter()
    with pytest.raises(ConfigError) as caught:
        question_from_dict(data)
    assert time.perf_counter() - started < 1.0  # refused by counting, not by trying
    return str(caught.value)


def test_a_place_question_asking_for_more_variants_than_the_limit_is_refused_at_once():
    region = {"x_m": [-0.5, 0.5], "y_m": [-0.5, 0.5], "yaw_deg": [0, 90], "candidates": 400, "yaws": 400}
    assert _refused({"question": "place", "object": CUBE, "region": region}) == (
        "region.candidates: 400 candidates x 400 yaws are 160000 placements, more than the 400 one question may "
        "ask about; search a smaller region or fewer yaws")
    spots = [[0.5 + 0.001 * i, 0.0] for i in range(100_000)]
    assert _refused({"question": "place", "object": CUBE, "at": spots}) == (
        "at: 100000 spots are more than the 400 one question may ask about; split them into several questions")


def test_a_placement_search_beyond_the_budget_is_refused_before_any_geometry():
    region = A.Region((-0.5, 0.5), (-0.5, 0.5))
    with pytest.raises(ConfigError, match=r"^budget_s: one sample of these 401 variants takes up to ~\S+ s, far "
                                          r"more than the budget of 1 s; ask fewer variants or raise the budget$"):
        A.best_place(STACK, new_object_from_dict(CUBE, "object"), region, MODEL, SETTINGS, candidates=400,
                     budget_s=1.0)


def test_lowering_candidates_stops_at_the_deadline(monkeypatch):
    monkeypatch.setattr(questions, "PLACEMENT_GEOMETRY_S", 0.0)  # let the estimate pass; the deadline must catch it
    real = questions._Lowering.height_m

    def slow(self, *args):
        time.sleep(0.1)
        return real(self, *args)

    monkeypatch.setattr(questions._Lowering, "height_m", slow)
    spots = [(0.6 + 0.01 * i, 0.0, 0.0) for i in range(40)]
    started = time.perf_counter()
    with pytest.raises(ConfigError, match=r"^budget_s: lowering 40 candidate placements onto the scene took the "
                                          r"whole budget of 1 s \(\d+ done\); ask fewer candidates or raise the budget$"):
        A.place_at(STACK, new_object_from_dict(CUBE, "object"), spots, MODEL, SETTINGS, budget_s=1.0)
    assert time.perf_counter() - started < 1.5


def test_lowering_in_one_world_gives_the_heights_of_one_world_per_spot():
    body = new_object_from_dict(CUBE, "object")
    spots = [(0.0, 0.0, 0.0), (0.05, 0.02, 0.7), (0.6, 0.0, 0.0)]  # on the stack, tilted, on the floor
    lowered = questions._lowered(STACK, body, spots, questions._Deadline(None))
    assert [b.position_m[2] for b in lowered] == [A.resting_height_m(STACK, body, x, y, b.orientation_xyzw)
                                                  for (x, y, _), b in zip(spots, lowered)]
    assert lowered[0].position_m[2] == pytest.approx(0.45, abs=1e-3) and lowered[2].position_m[2] == pytest.approx(
        0.05, abs=1e-3)


@pytest.mark.parametrize("point, message", [
    ([1e6, 0.0, 1e6], "actions[1].point_m: [1000000.0, 0.0, 1000000.0] is 1.41e+06 m from the centre of mass of "
                      "'top', outside its reach of 0.174 m; push a point on the object"),
    ([0.0, 0.0, 0.1], "actions[1].point_m: [0.0, 0.0, 0.1] is 0.2 m from the centre of mass of 'top', outside its "
                      "reach of 0.174 m; push a point on the object"),
])
def test_a_push_point_off_the_object_is_refused(point, message):
    with pytest.raises(ConfigError) as caught:
        A.push(STACK, [A.Push("top", (1.0, 0.0, 0.0), tuple(point))], MODEL, SETTINGS)
    assert str(caught.value) == message


def test_a_push_whose_implied_spin_exceeds_what_a_scene_may_start_with_is_refused():
    small = scene("small", box("base", 0, 0, 0.1), box("chip", 0, 0, 0.2025, extents=(0.005, 0.005, 0.005), mass=0.001))
    corner = (0.0025, 0.0025, 0.205)
    with pytest.raises(ConfigError, match=r"^actions\[1\]\.point_m: pushed there at this speed 'chip' would spin at up "
                                          r"to \S+ rad/s, more than the 1000 rad/s a scene may start with; push "
                                          r"nearer its centre of mass or slower$"):
        A.push(small, [A.Push("chip", (50.0, 0.0, 0.0), corner)], MODEL, SETTINGS)
    check_action(small, A.Push("chip", (0.5, 0.0, 0.0), corner), "push")  # slowly there: allowed


def test_a_removal_of_no_object_is_refused():
    assert _refused({"question": "remove", "objects": []}) == (
        "objects: names no object; name at least one, or leave it out to ask about every one")
    with pytest.raises(ConfigError, match="^objects: names no object"):
        A.remove(STACK, [], MODEL, SETTINGS)


def test_a_clearing_order_spends_one_budget_over_all_its_steps(monkeypatch):
    tall = scene("tall", *(box(f"b{i}", 0, 0, 0.1 + 0.2 * i) for i in range(4)))
    full = A.clear_order(tall, MODEL, SETTINGS)
    assert full.stopped_by == "done" and len(full.steps) == 4
    real = A.ask

    def slow(*args, **kw):
        time.sleep(0.6)
        return real(*args, **kw)

    monkeypatch.setattr(questions, "ask", slow)  # each step's removals
    started = time.perf_counter()
    cut = A.clear_order(tall, MODEL, SETTINGS, budget_s=1.0)
    assert time.perf_counter() - started < 2.5  # before: each of the 3 steps had its own budget
    assert cut.stopped_by == "budget" and 1 <= len(cut.steps) < 4
    assert [s.name for s in cut.steps] == [s.name for s in full.steps[:len(cut.steps)]]
    assert cut.to_dict()["stopped_by"] == "budget"


@pytest.mark.parametrize("changes, message", [
    ({"gravity_aligned_frames": []}, "gravity_aligned_frames: is empty; list the frames whose -z axis is gravity, or "
                                     "[''] to accept scenes in every frame"),
    ({"rerun.save_dir": "../../etc"}, "rerun.save_dir: must not climb out of a folder ('..'), got '../../etc'; give "
                                      "the folder itself"),
    ({"rerun.save_dir": "/tmp/rec/../../root"}, "rerun.save_dir: must not climb out of a folder ('..'), got "
                                                "'/tmp/rec/../../root'; give the folder itself"),
])
def test_node_parameters_that_would_trust_every_frame_or_write_anywhere_are_refused(changes, message):
    from ipe_ros.ros.params import all_parameters, config_from_values

    values = {spec.name: spec.default for spec in all_parameters()} | changes
    with pytest.raises(ConfigError) as caught:
        config_from_values(values)
    assert str(caught.value) == message
    config_from_values(values | {"gravity_aligned_frames": [""], "rerun.save_dir": "/tmp/recordings"})  # allowed
