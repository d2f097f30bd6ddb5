"""The query protocol and the event questions: contact, rest, final_pose.

Contact is tested on scenes where the physics decides it (a ball that reaches a box within the
horizon or not, a block slid at a box that friction stops short of it or not, a domino chain that
reaches the last slab or has a gap it cannot bridge, a block dropped onto a target or beside it),
in the ground truth (one deterministic rollout) at every preset.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ipe_ros.engine import PRESETS, Body, Box, ConfigError, Floor, ModelConfig, QuerySpec, Scene, Sphere, preset
from ipe_ros.engine.sampling.estimate import Prediction
from ipe_ros.engine.query import ALL_QUERIES, ANSWER_FIELDS, QUERIES
from ipe_ros.engine.query.contact import parse_pair
from ipe_ros.engine.predict import predict
from ipe_ros.engine.predict import Context, Request
from tests.helpers import IDENTITY, block, floor_scene

GROUND_TRUTH = ModelConfig(sigma_m=0.0, samples=1)


def _ask(scene: Scene, *pairs: str, queries=("contact",), settings="default", model=GROUND_TRUTH, **kw) -> Prediction:
    spec = QuerySpec(queries=frozenset(queries), contact_pairs=tuple(parse_pair(p) for p in pairs))
    return predict(scene, Request(model=model, settings=preset(settings), query=spec, seed=3, budget_s=None, check=None),
                   Context(**kw))


def _ball(name: str, x: float, speed_m_s: float, radius: float = 0.05) -> Body:
    return Body(name=name, shape=Sphere(radius), position_m=(x, 0.0, radius), orientation_xyzw=IDENTITY,
                friction=0.5, restitution=0.0, mass_kg=0.5, linear_velocity_m_s=(speed_m_s, 0.0, 0.0))


def _rolled(speed_m_s: float) -> Scene:
    # 1.5 m to the box's face: within the 2 s horizon at 1.5 m/s, not at 0.5 m/s
    return floor_scene(_ball("ball", 0.0, speed_m_s), block("box", 1.6, 0.0, 0.1, extents=(0.2, 0.4, 0.2)),
                       name="rolled")


def _slid(speed_m_s: float) -> Scene:
    # friction 0.9 x 1.0: a block slid at v stops after v^2 / (2 mu g): 0.23 m at 2 m/s, 0.51 m at 3 m/s
    slider = block("slider", 0.0, 0.0, 0.05, extents=(0.1, 0.1, 0.1), linear_velocity_m_s=(speed_m_s, 0.0, 0.0))
    return floor_scene(slider, block("box", 0.45, 0.0, 0.1, extents=(0.2, 0.4, 0.2)), name="slid")


def _dominoes(gap_at: int | None) -> Scene:
    height, thickness, width, spacing = 0.15, 0.025, 0.08, 0.09
    slabs, x = [], 0.0
    for i in range(6):
        fields = {}
        if i == 0:
            spin = 3.0
            fields = {"angular_velocity_rad_s": (0.0, spin, 0.0),
                      "linear_velocity_m_s": (spin * height / 2, 0.0, spin * thickness / 2)}
        slabs.append(block(f"d{i}", x, 0.0, height / 2, extents=(thickness, width, height), mass_kg=0.2, **fields))
        x += spacing * (2.5 if gap_at is not None and i + 1 == gap_at else 1.0)
    return floor_scene(*slabs, name="dominoes")


def _dropped(offset_m: float) -> Scene:
    target = block("target", 0.0, 0.0, 0.05, extents=(0.2, 0.2, 0.1))
    return floor_scene(target, block("drop", offset_m, 0.0, 0.6, extents=(0.1, 0.1, 0.1)), name="drop")


CASES = [
    ("ball reaches the box", _rolled(1.5), "ball:box", 1.0),
    ("ball does not reach the box in time", _rolled(0.5), "ball:box", 0.0),
    ("slid block reaches the box", _slid(3.0), "slider:box", 1.0),
    ("slid block stops short", _slid(2.0), "slider:box", 0.0),
    ("chain reaches the last slab", _dominoes(None), "d4:d5", 1.0),
    ("chain stops at a gap", _dominoes(3), "d4:d5", 0.0),
    ("dropped onto the target", _dropped(0.0), "drop:target", 1.0),
    ("dropped beside the target", _dropped(0.4), "drop:target", 0.0),
]


@pytest.mark.parametrize("settings", sorted(PRESETS))
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_contact_is_decided_by_the_physics_at_every_preset(case, settings):
    _, scene, pair, expected = case
    answer = _ask(scene, pair, settings=settings)
    assert answer.samples == 1 and answer.deterministic
    assert answer.contact_probability == {pair: expected}
    assert answer.contact_probability_ci95 == {pair: [expected, expected]}
    assert answer.contact_at_start == {pair: 0.0}
    if expected:
        assert 0.0 < answer.contact_time_s[pair] <= 2.0
    else:
        assert answer.contact_time_s[pair] is None


def test_first_contact_time_is_when_the_ball_arrives():
    # launched sliding at v0 = 1.5 m/s, friction (mu = 0.5 x 1.0) slows it until it rolls at 5/7 v0
    # after 2 v0 / (7 mu g); then it rolls on (no rolling resistance) across the rest of the 1.45 m gap
    v0, a = 1.5, 0.5 * 9.81
    slip_s = 2 * v0 / (7 * a)
    slip_m = v0 * slip_s - a * slip_s ** 2 / 2
    arrival_s = slip_s + (1.45 - slip_m) / (5 / 7 * v0)
    answer = _ask(_rolled(v0), "ball:box")
    assert answer.contact_time_s["ball:box"] == pytest.approx(arrival_s, abs=0.03)


def test_a_rollout_asked_only_contacts_ends_once_they_have_all_touched():
    answer = _ask(_dropped(0.0), "drop:target")
    (rollout,) = answer.outcomes[0].rollouts
    assert rollout.simulated_s == pytest.approx(answer.contact_time_s["drop:target"])
    assert rollout.simulated_s < 0.5
    # asked with a query that reads the end, it runs on to rest
    both = _ask(_dropped(0.0), "drop:target", queries=("contact", "final_pose"))
    assert both.outcomes[0].rollouts[0].simulated_s > rollout.simulated_s + 0.2


def test_pairs_touching_at_the_start_are_flagged_and_count_at_zero_seconds():
    scene = floor_scene(block("low", 0.0, 0.0, 0.1), block("high", 0.0, 0.0, 0.3), name="stack")
    answer = _ask(scene, "high:low", "low:support")
    assert answer.contact_at_start == {"high:low": 1.0, "low:support": 1.0}
    assert answer.contact_probability == {"high:low": 1.0, "low:support": 1.0}
    assert answer.contact_time_s == {"high:low": 0.0, "low:support": 0.0}


def test_support_includes_the_floor_under_a_table():
    from ipe_ros.engine import Table

    table = Table(size_m=(0.6, 0.6), center_xy_m=(0.0, 0.0), thickness_m=0.05, top_height_m=0.5, friction=0.8, restitution=0.0,
                  floor_z_m=0.0)
    off = block("off", 0.5, 0.0, 0.6, extents=(0.1, 0.1, 0.1))  # beside the table: falls to the floor
    scene = Scene(name="table", objects=(off,), support=table, gravity_m_s2=(0.0, 0.0, -9.81))
    answer = _ask(scene, "off:support")
    assert answer.contact_probability == {"off:support": 1.0}
    assert answer.contact_time_s["off:support"] == pytest.approx(math.sqrt(2 * 0.55 / 9.81), abs=0.05)


def test_contact_with_noise_counts_samples_and_gives_an_interval():
    # the dropped block lands on the target's edge: noise decides, about half the samples
    scene = _dropped(0.15)
    answer = _ask(scene, "drop:target", model=ModelConfig(sigma_m=0.03, samples=16))
    p = answer.contact_probability["drop:target"]
    lo, hi = answer.contact_probability_ci95["drop:target"]
    assert 0.0 < p < 1.0 and lo < p < hi
    touched = sum(r.value("contact")["first_s"]["drop:target"] is not None
                  for o in answer.outcomes for r in o.rollouts)
    assert p == touched / 16


@pytest.mark.parametrize("pairs, message", [
    ((), "the contact query needs pairs to watch"),
    ((("ball", "nothing"),), "ball:nothing: no object 'nothing' in scene 'rolled'"),
    ((("ball", "ball"),), "ball:ball: an object always touches itself"),
])
def test_contact_questions_that_cannot_be_answered_are_refused(pairs, message):
    with pytest.raises(ConfigError, match=message):  # refused by QuerySpec where no scene could answer it
        predict(_rolled(1.0),
                Request(model=GROUND_TRUTH, settings=preset("default"),
                        query=QuerySpec(queries=frozenset({"contact"}), contact_pairs=pairs), budget_s=None))


def test_contact_pairs_without_the_query_and_badly_written_pairs_are_refused():
    with pytest.raises(ConfigError, match="pairs were given but the contact query was not asked"):
        QuerySpec(queries=frozenset({"fall"}), contact_pairs=(("a", "b"),))
    with pytest.raises(ConfigError, match="a pair is written A:B"):
        parse_pair("ab")
    with pytest.raises(ConfigError, match="both names given"):
        parse_pair("a:")


def test_rest_tells_a_settled_scene_from_one_still_moving():
    still = _ask(floor_scene(block("b", 0.0, 0.0, 0.1)), queries=("rest",))
    assert still.rest_probability == 1.0 and still.rest_probability_ci95 == (1.0, 1.0)
    assert still.max_final_speed_m_s < 0.005
    rolling = _ask(_rolled(0.5), queries=("rest",))  # the ball still rolls at the horizon
    assert rolling.rest_probability == 0.0
    assert rolling.max_final_speed_m_s == pytest.approx(5 / 7 * 0.5, rel=0.02)  # rolling: 5/7 of its launch speed


def test_rest_makes_early_termination_read_rest_strictly():
    from ipe_ros.engine.sampling.rollout import query_settings

    default = preset("default")
    strict = query_settings(default, QuerySpec(queries=frozenset({"rest", "fall"})))
    assert (strict.early_stop.speed_sizes_per_s, strict.early_stop.angular_rad_s) == (0.05, 0.05)
    assert query_settings(default, QuerySpec(queries=frozenset({"fall"}))) is default


def test_rests_own_parameters_set_its_reading_of_rest_and_the_rollouts_end():
    from ipe_ros.engine.query.rest import RestParameters
    from ipe_ros.engine.sampling.rollout import query_settings

    rolling = _rolled(0.5)  # still rolling at 5/7 of 0.5 m/s at the horizon: at rest only by a loose reading
    loose = QuerySpec(queries=frozenset({"rest"}), parameters=(("rest", RestParameters(100.0, 100.0)),))
    assert predict(rolling,
                   Request(model=GROUND_TRUTH, settings=preset("default"), query=loose, check=None, budget_s=None)).rest_probability == 1.0
    strict = QuerySpec(queries=frozenset({"rest"}), parameters=(("rest", RestParameters(spin_rad_s=0.01)),))
    assert query_settings(preset("default"), strict).early_stop.angular_rad_s == 0.01
    with pytest.raises(ConfigError) as info:
        RestParameters(speed_sizes_per_s=0.0)
    assert str(info.value).startswith("rest.speed_sizes_per_s: ")


def test_final_pose_reports_where_things_end_up():
    answer = _ask(_slid(2.0), queries=("final_pose",))
    slider = answer.final_pose["slider"]
    # friction stops it after v^2 / (2 mu g) = 0.227 m (mu: 0.9 x 1.0)
    assert slider["position_m"][0] == pytest.approx(4.0 / (2 * 0.9 * 9.81), abs=0.02)
    assert slider["position_m"][2] == pytest.approx(0.05, abs=0.002)
    assert slider["position_sd_m"] == [0.0, 0.0, 0.0]
    # it slides straight: the sequential solver's contact order leaves its four corners' friction a
    # little uneven, a few mrad of turn (3-9 mrad at 1-3 m/s for residuals of 3e-6 to 1e-5)
    assert slider["yaw_rad"] == pytest.approx(0.0, abs=0.01)
    box = answer.final_pose["box"]
    assert box["position_m"] == pytest.approx([0.45, 0.0, 0.1], abs=1e-3)


def test_final_pose_spread_follows_the_noise():
    scene = floor_scene(block("b", 0.0, 0.0, 0.1, extents=(0.2, 0.2, 0.2)))
    answer = _ask(scene, queries=("final_pose",), model=ModelConfig(sigma_m=0.05, samples=24))
    sd = answer.final_pose["b"]["position_sd_m"]
    assert sd[0] == pytest.approx(0.05, rel=0.4) and sd[1] == pytest.approx(0.05, rel=0.4)
    assert sd[2] < 1e-3


def _standing(name: str, x: float, extents, beyond: float = 0.0) -> Scene:
    """A tall box on the floor, its top half shifted ``beyond`` of its width past a square base: it
    tips over (as two boxes, glued by nothing, the top one tips off the base)."""
    w, _, h = extents
    base = block(f"{name}_base", x, 0.0, h / 4, extents=(w, w, h / 2))
    top = block(name, x + beyond * w, 0.0, 3 * h / 4, extents=(w, w, h / 2))
    return floor_scene(base, top, name=name)


def test_tipped_tells_an_object_tipping_over_from_one_spun_about_the_vertical():
    spun = floor_scene(block("spinner", 0.0, 0.0, 0.05, extents=(0.3, 0.1, 0.1), angular_velocity_rad_s=(0, 0, 6.0)))
    answer = _ask(spun, queries=("tipped", "final_pose"))
    assert abs(answer.final_pose["spinner"]["yaw_rad"]) > 0.05  # it turned about the vertical
    assert answer.tipped_object_probability == {"spinner": 0.0} and answer.tipped_probability == 0.0
    tipping = _standing("top", 0.0, (0.1, 0.1, 0.2), beyond=0.7)  # its centre past the base's edge
    answer = _ask(tipping, queries=("tipped", "fall"))
    assert answer.tipped_object_probability == {"top_base": 0.0, "top": 1.0}
    assert answer.tipped_probability == 1.0 and answer.tipped_probability_ci95 == (1.0, 1.0)
    upright = _ask(_standing("top", 0.0, (0.1, 0.1, 0.2), beyond=0.3), queries=("tipped",))
    assert upright.tipped_object_probability == {"top_base": 0.0, "top": 0.0}


def test_tipped_counts_a_turn_beyond_its_threshold_and_refuses_a_bad_one():
    from ipe_ros.engine.query.tipped import TippedParameters, tipped_by_deg
    from scipy.spatial.transform import Rotation

    start = Rotation.from_euler("y", 90, degrees=True)  # lying on its side
    ends = [start * Rotation.from_euler("z", 70, degrees=True),  # turned about its own axis
            Rotation.from_euler("z", 70, degrees=True) * start,  # about the world's vertical: not tipping
            Rotation.from_euler("x", 50, degrees=True) * start]  # tipped by 50 degrees
    turned = tipped_by_deg(np.array([start.as_quat()] * 3), np.array([e.as_quat() for e in ends]))
    assert turned == pytest.approx([70.0, 0.0, 50.0], abs=1e-6)
    # up to a body's own symmetry: a ball never tips; a can lying on its side and rolling has not tipped,
    # a can standing that ends on its side has
    from ipe_ros.engine.scene.shapes import Cylinder, Sphere

    lying = Rotation.from_euler("x", 90, degrees=True)
    rolled = Rotation.from_euler("y", 120, degrees=True) * lying
    turned = tipped_by_deg(np.array([start.as_quat(), lying.as_quat(), [0, 0, 0, 1.0]]),
                           np.array([ends[2].as_quat(), rolled.as_quat(), lying.as_quat()]),
                           (Sphere(0.1), Cylinder(0.03, 0.1), Cylinder(0.03, 0.1)))
    assert turned == pytest.approx([0.0, 0.0, 90.0], abs=1e-6)
    for bad in (0.0, 180.0, float("nan"), True):
        with pytest.raises(ConfigError, match=r"tipped.threshold_deg: must be in \(0, 180\) degrees"):
            TippedParameters(threshold_deg=bad)


def test_every_query_is_registered_with_its_fields_and_none_when_not_asked():
    assert ALL_QUERIES == ("fall", "any_fall", "direction", "far", "bump", "contact", "rest", "final_pose", "tipped")
    assert len(ANSWER_FIELDS) == len(set(ANSWER_FIELDS))
    answer = _ask(_rolled(1.5), "ball:box")
    data = answer.to_dict()
    for name, query in QUERIES.items():
        for field in query.fields:
            assert field in data
            if name != "contact":
                assert data[field] is None and answer.value(field) is None
    assert data["request"]["contact"] == ["ball:box"]
    with pytest.raises(AttributeError):
        answer.not_a_field  # noqa: B018
    with pytest.raises(TypeError, match="not_a_field: not a field of any query"):
        dataclasses.replace(answer, answers={"not_a_field": 1})


def test_a_new_query_is_one_module_and_its_registration(monkeypatch):
    """What the protocol promises: a query registered by name is asked, read, aggregated and
    answered without touching the sampler, the rollout or the answer type."""
    from ipe_ros.engine import query as registry
    from ipe_ros.engine.query.base import Query

    class Highest(Query):
        name = "highest"
        fields = ("fall_fraction",)  # reuses a field so the answer type accepts it

        def read(self, reading):
            return {"highest": float(reading.final_m[:, 2].max())}

        def aggregate(self, samples):
            return {"fall_fraction": float(np.mean([r.value("highest") for r in samples.rollouts]))}

    monkeypatch.setitem(registry.QUERIES, "highest", Highest())
    answer = _ask(floor_scene(block("b", 0.0, 0.0, 0.1)), queries=("highest",))
    assert answer.fall_fraction == pytest.approx(0.1, abs=1e-3)


def test_recordings_show_where_and_when_each_pair_first_touched(tmp_path):
    from rerun.chunk import RrdReader

    from ipe_ros.viz.rerun_log import write_prediction_rrd

    scene = _dropped(0.0)
    answer = _ask(scene, "drop:target", "drop:support", queries=("contact", "rest"),
                  model=ModelConfig(sigma_m=0.01, samples=3), record_every=10, record_samples=2)
    path = tmp_path / "contact.rrd"
    write_prediction_rrd(path, scene, answer, answer=answer.to_dict(), stamp_ns=1, rollouts_logged=2)
    entities = {chunk.entity_path for chunk in RrdReader(path).stream().to_chunks()}
    # entity path parts escape the pair's ':' and the column's space
    assert {"/world/rollouts/0/contacts/drop\\:target", "/world/rollouts/1/contacts/drop\\:target",
            "/outcomes/contact\\ drop\\:target", "/outcomes/at_rest"} <= entities, sorted(entities)
    assert "/world/rollouts/2/contacts/drop\\:target" not in entities  # not recorded
    assert answer.contact_probability["drop:target"] == 1.0
    where = answer.outcomes[0].rollouts[0].value("contact")["where_m"]["drop:target"]
    assert where[2] == pytest.approx(0.1, abs=0.01)  # on the target's top face


def _cup_and_glass() -> Scene:
    return floor_scene(block("cup", 0.0, 0.0, 0.05, extents=(0.1, 0.1, 0.1)),
                       block("glass", 0.4, 0.0, 0.1, extents=(0.1, 0.1, 0.2)), name="cup_and_glass")


@pytest.mark.parametrize("speed, expected", [(1.0, 0.0), (3.0, 1.0)])
def test_a_push_question_answers_whether_the_pushed_cup_touches_the_glass(speed, expected):
    # friction 0.9: the cup slides v^2 / (2 mu g): 0.06 m at 1 m/s, 0.51 m at 3 m/s; the glass is 0.3 m away
    from ipe_ros.engine.actions import Push, push

    answers = push(_cup_and_glass(), [Push("cup", (speed, 0.0, 0.0))], GROUND_TRUTH, preset("default"),
                   contact=(("cup", "glass"),))
    as_is, pushed = answers.variants
    assert as_is.contact_probability == {"cup:glass": 0.0}
    assert pushed.contact_probability == {"cup:glass": expected}
    assert pushed.to_dict()["contact_probability_ci95"] == {"cup:glass": [expected, expected]}


def test_contact_on_robot_questions_through_the_question_json():
    from ipe_ros.engine.actions.question import question_from_dict

    question = question_from_dict({"question": "push", "object": "cup", "velocity_m_s": [3.0, 0.0],
                                   "direction_sigma_deg": 10, "samples": 8, "contact": ["cup:glass", "glass:support"]})
    assert question.contact == (("cup", "glass"), ("glass", "support"))
    answer = question.answer(_cup_and_glass(), ModelConfig(sigma_m=0.005, samples=8), preset("default")).data
    pushed = answer["variants"][1]
    assert pushed["contact_probability"]["cup:glass"] >= 0.75
    assert pushed["contact_probability"]["glass:support"] == 1.0  # it stands on the floor from the start
    lo, hi = pushed["contact_probability_ci95"]["cup:glass"]
    assert lo <= pushed["contact_probability"]["cup:glass"] <= hi
    with pytest.raises(ConfigError, match="contact: cup:mug: no object 'mug' in scene 'cup_and_glass'"):
        dataclasses.replace(question, contact=(("cup", "mug"),)).answer(_cup_and_glass(), GROUND_TRUTH,
                                                                        preset("default"))
    with pytest.raises(ConfigError, match="unknown field of a support question"):
        question_from_dict({"question": "support", "contact": ["a:b"]})


def test_event_values_survive_the_result_store():
    """Resumable runs store each sample's outcome: the new queries' values (mappings of times,
    flags and arrays) come back equal."""
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.compute.store import decode_entry, encode_entry

    spec = QuerySpec(queries=frozenset({"contact", "rest", "final_pose"}), contact_pairs=(("drop", "target"),))
    [task] = make_tasks(_dropped(0.0), ModelConfig(sigma_m=0.01, samples=1), preset("default"), spec, 0)
    outcome = run_sample(task)
    back = decode_entry(encode_entry(outcome, "k" * 64), "k" * 64)
    (before,), (after,) = outcome.rollouts, back.rollouts
    assert after.value("contact") == before.value("contact")
    assert after.value("rest") == before.value("rest")
    np.testing.assert_array_equal(after.value("final_pose")["position_m"], before.value("final_pose")["position_m"])
    np.testing.assert_array_equal(after.value("final_pose")["moved"], before.value("final_pose")["moved"])


def test_bump_counts_only_what_started_on_the_table_as_fallen_off():
    """One rule for "fell off the table" in predictions and robot questions: started on or above the
    top and ended below it. A block standing on the floor beside the table never fell off (it was
    counted as fallen off before: it ends below the top)."""
    from ipe_ros.engine import Table

    table = Table(size_m=(0.6, 0.6), center_xy_m=(0.0, 0.0), thickness_m=0.05, top_height_m=0.5, friction=0.8,
                  restitution=0.0, floor_z_m=0.0)
    on_table = block("on_table", 0.0, 0.0, 0.55, extents=(0.1, 0.1, 0.1), group="red")
    beside = block("beside", 0.6, 0.0, 0.05, extents=(0.1, 0.1, 0.1), group="yellow")
    scene = Scene(name="beside_table", objects=(on_table, beside), support=table, gravity_m_s2=(0.0, 0.0, -9.81))
    answer = predict(scene,
                     Request(model=GROUND_TRUTH, settings=preset("default"),
                             query=QuerySpec(queries=frozenset({"bump"})), check=None, budget_s=None))
    assert answer.fell_off_fraction_by_group == {"red": 0.0, "yellow": 0.0}
    assert answer.bump_rollouts == 0  # nothing fell off: no share to report


def test_names_holding_colons_commas_or_edge_spaces_can_be_named_in_a_pair():
    from ipe_ros.engine.query.contact import parse_pair, parse_pairs

    assert parse_pair('["cup:1", " glass"]', "--contact") == ("cup:1", " glass")
    assert parse_pairs('[["cup:1", "glass"], ["a,b", "support"]]', "contact_pairs") == (("cup:1", "glass"),
                                                                                     ("a,b", "support"))
    assert parse_pairs("cup:glass, ball:support", "contact_pairs") == (("cup", "glass"), ("ball", "support"))
    with pytest.raises(ConfigError, match=r'^--contact: a pair in JSON is \["A", "B"\] \(two non-empty names\), '
                                          r'got \'\["cup"\]\'$'):
        parse_pair('["cup"]', "--contact")
    with pytest.raises(ConfigError, match=r'^contact_pairs: a pair in JSON is \["A", "B"\]: Expecting value at column 3$'):
        parse_pairs("[[", "contact_pairs")


def test_many_contact_pairs_are_watched_per_contact_and_priced_up_front():
    """Every pair of 60 boxes on a floor (1830 pairs): the rollout's estimate counts them, and a budget
    between the estimates with and without them refuses the question before any simulation."""
    import itertools

    from ipe_ros.engine.sampling.montecarlo import FAR_OVER_BUDGET
    from ipe_ros.engine.predict import SECONDS_PER_WATCHED_PAIR, check_request, rollout_cost

    boxes = tuple(Box(name=f"b{i}", extents_m=(0.1, 0.1, 0.1), position_m=(0.15 * (i % 10), 0.15 * (i // 10), 0.05),
                      orientation_xyzw=(0, 0, 0, 1), friction=0.6, restitution=0.0, mass_kg=1.0) for i in range(60))
    scene = Scene(name="grid", objects=boxes, support=Floor(friction=0.6, restitution=0.0),
                  gravity_m_s2=(0.0, 0.0, -9.81))
    names = [b.name for b in boxes]
    pairs = tuple(itertools.combinations(names, 2)) + tuple((n, "support") for n in names)
    model, settings = ModelConfig(sigma_m=0.01, samples=2), preset("default")
    bare, watched = rollout_cost(scene, model, settings), rollout_cost(scene, model, settings, len(pairs))
    assert watched.seconds == pytest.approx(bare.seconds + len(pairs) * SECONDS_PER_WATCHED_PAIR)
    pushed = ModelConfig(sigma_m=0.01, phi_m_s2=(1.0, 2.0), samples=2)  # two runs a sample, each watching every pair
    assert rollout_cost(scene, pushed, settings, len(pairs)).seconds == pytest.approx(
        rollout_cost(scene, pushed, settings).seconds + 2 * len(pairs) * SECONDS_PER_WATCHED_PAIR)
    budget = watched.seconds / (1.1 * FAR_OVER_BUDGET)  # refused only far over: watched is, bare is not
    assert bare.seconds < FAR_OVER_BUDGET * budget
    check_request(scene, QuerySpec(queries=frozenset({"fall"})), model=model, settings=settings, budget_s=budget)
    with pytest.raises(ConfigError, match=r"^budget_s: one rollout of this scene takes up to \d+ steps x 60 bodies "
                                          r"and 1830 contact pairs .* or ask fewer pairs$"):
        check_request(scene, QuerySpec(queries=frozenset({"contact"}), contact_pairs=pairs), model=model,
                      settings=settings, budget_s=budget)
    answer = predict(scene,
                     Request(model=model, settings=settings,
                             query=QuerySpec(queries=frozenset({"contact"}), contact_pairs=pairs), seed=1, check=None,
                             budget_s=None))
    probability = answer.to_dict()["contact_probability"]
    assert probability["b0:support"] == 1.0 and probability["b0:b1"] == 0.0  # resting on the floor, 5 cm apart


def test_every_built_in_query_field_is_a_typed_attribute_of_the_prediction():
    """Prediction's typed access (estimate.QueryValue) covers every built-in query's fields; any
    query's, a plugin's too, reads through value(), and a name no query answers is refused."""
    from ipe_ros.engine.query.spec import BUILT_IN_PACKAGE
    from ipe_ros.engine.sampling.estimate import Prediction, QueryValue

    built_in = [f for q in QUERIES.values() if type(q).__module__.startswith(BUILT_IN_PACKAGE) for f in q.fields]
    assert sorted(n for n, v in vars(Prediction).items() if isinstance(v, QueryValue)) == sorted(built_in)
    answer = Prediction("s", 1, 1, 0, (), True, answers={"fall_fraction": 0.25})
    assert answer.fall_fraction == answer.value("fall_fraction") == 0.25 and answer.far_m is None
    with pytest.raises(ValueError, match="^'fall_fractoin' is not a field of any registered query"):
        answer.value("fall_fractoin")
