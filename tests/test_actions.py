"""Robot questions (engine): remove, support graph, clear order, place, push, on hand-built scenes
whose answers are known. Small k and a small sigma: the answers asserted are near 0 or near 1."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest

from ipe_ros.engine import Box, ConfigError, Floor, ModelConfig, Scene, Sphere, preset
from ipe_ros.engine import Request
from ipe_ros.engine import actions as A
from ipe_ros.engine.actions.answers import fell, ran
from ipe_ros.engine.sampling.decide import Ranking, SafeBelow, Tally
from ipe_ros.engine.actions.question import question_from_dict
from ipe_ros.engine.scene.bodies import Body

I = (0.0, 0.0, 0.0, 1.0)
MODEL = ModelConfig(sigma_m=0.005, samples=8)
SETTINGS = preset("default")


def box(name, x, y, z, extents=(0.2, 0.2, 0.2), mass=1.0):
    return Box(name=name, extents_m=extents, position_m=(x, y, z), orientation_xyzw=I, friction=0.6,
               restitution=0.0, mass_kg=mass)


def scene(name, *objects):
    return Scene(name=name, objects=objects, support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


STACK = scene("stack", box("bottom", 0, 0, 0.1), box("top", 0, 0, 0.3))
#: the stack and a block out of its reach: the block's removal is read from the scene as it is
FAR = scene("far", box("bottom", 0, 0, 0.1), box("top", 0, 0, 0.3), box("lone", 3.0, 0, 0.1))
LINTEL = scene("lintel", box("left", -0.3, 0, 0.3, (0.2, 0.2, 0.6)), box("right", 0.3, 0, 0.3, (0.2, 0.2, 0.6)),
               box("lintel", 0, 0, 0.65, (0.9, 0.2, 0.1)))
ARCH = scene("arch", box("pillar_l", -0.3, 0, 0.3, (0.2, 0.2, 0.6)), box("pillar_r", 0.3, 0, 0.3, (0.2, 0.2, 0.6)),
             box("cap_l", -0.3, 0, 0.65, (0.3, 0.2, 0.1)), box("cap_r", 0.3, 0, 0.65, (0.3, 0.2, 0.1)),
             box("keystone", 0, 0, 0.75, (0.6, 0.2, 0.1)))


def leaning_plank() -> Scene:
    """A plank leaning 20 degrees against a post's side, its foot on the floor."""
    angle = math.radians(20)
    q = (0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2))  # top tilts towards +x
    half = np.array([0.025, 0.1, 0.4])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    c, s = math.cos(angle), math.sin(angle)
    rotated = corners @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T
    post = box("post", 0.0, 0.0, 0.4, (0.4, 0.3, 0.8), mass=20.0)
    x = -0.2 - rotated[:, 0].max()  # the plank's far side touches the post's face at x = -0.2
    plank = Box(name="plank", extents_m=tuple(2 * half), position_m=(x, 0.0, -rotated[:, 2].min()), orientation_xyzw=q,
                friction=0.8, restitution=0.0, mass_kg=1.0)
    return scene("leaning", post, plank)


def _by_label(answers):
    return {v.label: v for v in answers.variants}


def test_two_block_stack_removing_the_bottom_drops_the_top_and_the_top_is_safe():
    graph = A.support_graph(STACK, MODEL, SETTINGS)
    assert [(a, b) for a, b, _ in graph.edges] == [("bottom", "top")]
    assert [name for name, _, _ in graph.safe] == ["top"]
    variants = _by_label(graph.answers)
    assert variants["remove/bottom"].object_fall_probability == {"top": 1.0}
    top = variants["remove/top"]
    # nothing rests on the top, but it presses on the bottom (a counterweight would): simulated
    assert top.any_fall_probability == 0.0 and top.simulated is True


def test_lintel_on_two_posts_and_an_arch():
    lintel = _by_label(A.remove(LINTEL, None, MODEL, SETTINGS))
    assert lintel["remove/left"].object_fall_probability["lintel"] == 1.0
    assert lintel["remove/lintel"].any_fall_probability == 0.0 and lintel["remove/lintel"].simulated
    arch = _by_label(A.remove(ARCH, ["keystone", "pillar_l"], MODEL, SETTINGS))
    assert arch["remove/keystone"].any_fall_probability == 0.0
    pillar = arch["remove/pillar_l"].object_fall_probability
    assert pillar["cap_l"] == 1.0 and pillar["keystone"] == 1.0 and pillar["cap_r"] == 0.0


def test_a_plank_leaning_on_a_post_falls_when_the_post_goes():
    leaning = leaning_plank()
    assert "plank" in A.resting_on(leaning)["post"]  # a lean counts as resting on it
    answers = _by_label(A.remove(leaning, None, MODEL, SETTINGS))
    assert answers["as_is"].any_fall_probability == 0.0
    assert answers["remove/post"].object_fall_probability["plank"] == 1.0
    assert answers["remove/plank"].any_fall_probability == 0.0


def _towers(n: int) -> Scene:
    objects = []
    for t in range(n):
        objects += [box(f"t{t}_bottom", 2.0 * t, 0, 0.1), box(f"t{t}_top", 2.0 * t, 0, 0.3)]
    return scene("shelf", *objects)


def test_a_shelf_of_separate_towers_simulates_only_the_tower_asked_about():
    shelf = _towers(3)
    assert sorted(map(sorted, A.groups(shelf))) == [["t0_bottom", "t0_top"], ["t1_bottom", "t1_top"],
                                                    ["t2_bottom", "t2_top"]]
    answer = _by_label(A.remove(shelf, ["t0_bottom"], MODEL, SETTINGS))["remove/t0_bottom"]
    assert answer.object_fall_probability == {"t0_top": 1.0}
    assert answer.not_simulated == ("t1_bottom", "t1_top", "t2_bottom", "t2_top")


def test_towers_close_enough_to_topple_onto_each_other_are_one_group():
    near = scene("near", box("a_bottom", 0, 0, 0.1), box("a_top", 0, 0, 0.3), box("b", 0.5, 0, 0.1))
    assert len(A.groups(near)) == 1  # 0.3 m apart, a tower 0.4 m tall


def test_common_random_numbers_make_answers_independent_of_the_other_variants():
    alone = A.ask(ARCH, [A.Remove(("pillar_r",))],
                  Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), seed=3, budget_s=None, check=None))
    together = A.ask(ARCH, [A.Remove(("keystone",)), None, A.Remove(("pillar_r",)), A.Remove(("cap_l",))],
                     Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), seed=3, budget_s=None,
                             check=None))
    paired = _by_label(together)["remove/pillar_r"]
    assert _by_label(alone)["remove/pillar_r"] == dataclasses.replace(paired, caused_fall_probability=None,
                                                                    given_stands=None)
    # paired with "as is" sample by sample: what the removal itself made fall
    assert paired.caused_fall_probability == {"pillar_l": 0.0, "cap_l": 0.0, "cap_r": 1.0, "keystone": 1.0}
    # a placement's own noise is keyed by the placement, not by its place in the list
    cap = box("cap", 0.0, 0.0, 0.85)
    wobbly = ModelConfig(sigma_m=0.05, samples=8)
    first = A.ask(ARCH, [A.Place(cap)],
                  Request(model=wobbly, settings=SETTINGS, query=A.question_spec(), seed=3, budget_s=None, check=None)).variants[0]
    later = _by_label(A.ask(ARCH, [A.Remove(("cap_l",)), A.Place(cap)],
                            Request(model=wobbly, settings=SETTINGS, query=A.question_spec(), seed=3, budget_s=None,
                                    check=None)))[A.Place(cap).label]
    assert first == later
    other_seed = A.ask(ARCH, [A.Remove(("pillar_r",))],
                       Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), seed=4, budget_s=None,
                               check=None))
    assert other_seed.variants[0].samples == 8


def _exhaustive_total_risk(start: Scene) -> float:
    """The least total risk over every removal order (dynamic programming over removed sets)."""
    names = [b.name for b in start.dynamic_objects]
    best = {frozenset(names): 0.0}  # all removed: no risk left
    for size in range(len(names) - 1, -1, -1):
        for removed in map(frozenset, itertools.combinations(names, size)):
            current = dataclasses.replace(start, objects=tuple(b for b in start.objects if b.name not in removed))
            remaining = [n for n in names if n not in removed]
            if len(remaining) == 1:
                best[removed] = 0.0
                continue
            risks = {v.action.names[0]: v.any_fall_probability for v in A.remove(current, remaining, MODEL, SETTINGS).variants[1:]}
            best[removed] = min(1 - (1 - risks[n]) * (1 - best[removed | {n}]) for n in remaining)
    return best[frozenset()]


@pytest.mark.parametrize("settings", [SETTINGS, preset("paper")], ids=["default", "paper"])
def test_the_scene_as_it_is_is_exactly_a_prediction(settings):
    """A question's "as is" variant is a prediction's sample, bit for bit (the same task, the same
    separated world simulated on): its answer is the prediction's, whatever else is asked beside it."""
    from ipe_ros.engine import QuerySpec, predict
    from ipe_ros.engine import Request
    from ipe_ros.engine.sampling.rollout import SampleTask, run_sample

    model = ModelConfig(sigma_m=0.03, samples=6)
    query = QuerySpec(queries=frozenset({"fall"}))
    prediction = predict(LINTEL,
                         Request(model=model, settings=settings, query=query, seed=7, check=None, budget_s=None))
    for actions in ([None], [None, A.Remove(("left",))]):
        (as_is, *_) = A.ask(LINTEL, actions,
                            Request(model=model, settings=settings, query=A.question_spec(), seed=7, check=None,
                                    budget_s=None)).variants
        assert as_is.object_fall_probability == prediction.object_fall_probability
    seed = np.random.SeedSequence(7).spawn(6)[2]
    alone = run_sample(SampleTask(scene=LINTEL, model=model, settings=settings, query=query, index=2, seed=seed))
    (variant,) = A.run_variants(A.VariantTask(scene=LINTEL, model=model, settings=settings, query=query, index=2,
                                              seed=seed, actions=(None,), regions=(None,)))
    assert variant.names == tuple(b.name for b in LINTEL.dynamic_objects)
    assert (variant.rollouts[0].final_positions_m == alone.rollouts[0].final_positions_m).all()
    assert dataclasses.replace(variant, names=None).rollouts[0].fallen.tolist() == alone.rollouts[0].fallen.tolist()


def test_the_greedy_clear_order_matches_exhaustive_search_on_a_small_scene():
    small = scene("small", *LINTEL.objects, box("block", 0, 0, 0.8))
    order = A.clear_order(small, MODEL, SETTINGS)
    assert [s.name for s in order.steps][:2] == ["block", "lintel"]
    assert order.total_risk <= _exhaustive_total_risk(small) + 0.05  # the stated tolerance


def test_clearing_towards_a_target_removes_what_rests_on_it_first():
    order = A.clear_order(scene("tall", box("a", 0, 0, 0.1), box("b", 0, 0, 0.3), box("c", 0, 0, 0.5)),
                          MODEL, SETTINGS, target="b")
    assert [s.name for s in order.steps] == ["c", "b"] and order.total_risk == 0.0


TOWER_3 = scene("tower_3", box("a", 0, 0, 0.1), box("b", 0, 0, 0.3), box("c", 0, 0, 0.5))


def test_an_object_is_lowered_onto_the_top_of_a_stack_of_identical_boxes():
    """pybullet makes identical boxes in one batched call, and its body count then misses all but one
    of them: the probe sank through a and b to the floor (0.1 m)."""
    new = box("new", 0, 0, 1.0)
    assert A.resting_height_m(TOWER_3, new, 0.0, 0.0, I) == pytest.approx(0.7, abs=1e-3)
    assert A.resting_height_m(TOWER_3, new, 0.17, 0.0, I) == pytest.approx(0.7, abs=1e-3)


def _recording_map(seen: list):
    """A map that runs tasks here and keeps (sample, variant label, simulated s, anything fell) per rollout."""
    def run(fn, items, on_lost=None):
        out = [fn(t) for t in items]
        for task, results in zip(items, out):
            for action, result in zip(task.actions, results):
                if result.ok:
                    seen.append((task.index, "as_is" if action is None else action.label, ran(result).simulated_s,
                                 fell(ran(result))))
        return out
    return run


def test_a_question_that_reads_only_whether_anything_falls_ends_each_rollout_at_the_first_fall():
    """Placing decides on P(anything falls): unless what falls is asked, each rollout ends at its
    first fall. The same samples then give the same P (the physics is the same up to that fall),
    the rollouts in which something fell end sooner, and what else falls is None, not a guess."""
    new = box("new", 0, 0, 1.0)
    flat, over = (dataclasses.replace(new, position_m=(x, 0.0, A.resting_height_m(TOWER_3, new, x, 0.0, I)))
                  for x in (0.0, 0.17))
    runs = {}
    for what_falls in (False, True):
        seen = []
        answers = A.place(TOWER_3, [flat, over], MODEL, SETTINGS, what_falls=what_falls, sequential=False,
                          map_fn=_recording_map(seen))
        runs[what_falls] = answers, sorted(seen)
    (first_fall, short), (everything, full) = runs[False], runs[True]
    assert [v.any_fall_probability for v in first_fall.variants] == [v.any_fall_probability
                                                                    for v in everything.variants] == [0.0, 0.0, 1.0]
    assert all(v.object_fall_probability is None and v.caused_fall_probability is None
               and v.given_stands.object_fall_probability is None for v in first_fall.variants)
    assert everything.variants[2].object_fall_probability == {"a": 0.0, "b": 0.0, "c": 0.0, "new": 1.0}
    assert [(i, label, f) for i, label, _, f in short] == [(i, label, f) for i, label, _, f in full]
    for (_, _, short_s, fell_here), (_, _, full_s, _) in zip(short, full):
        assert short_s < full_s if fell_here else short_s == full_s
    # "is it safe to take?" likewise; "what falls if I take it?" says what falls
    assert A.remove(TOWER_3, ["c"], MODEL, SETTINGS, safe_below=0.05).variants[1].object_fall_probability is None
    assert A.remove(TOWER_3, ["c"], MODEL, SETTINGS).variants[1].object_fall_probability == {"a": 0.0, "b": 0.0}


def test_placing_on_a_flat_top_or_across_a_gap_is_safe_and_overhanging_or_on_a_ball_is_not():
    post = scene("post", box("post", 0, 0, 0.2, (0.2, 0.2, 0.4)))
    new = box("new", 0, 0, 1.0)
    flat = dataclasses.replace(new, position_m=(0.0, 0.0, A.resting_height_m(post, new, 0.0, 0.0, I)))
    overhang = dataclasses.replace(new, position_m=(0.16, 0.0, A.resting_height_m(post, new, 0.16, 0.0, I)))
    assert flat.position_m[2] == pytest.approx(0.5, abs=1e-3) and overhang.position_m[2] == pytest.approx(0.5, abs=1e-3)
    answers = _by_label(A.place(post, [flat, overhang], MODEL, SETTINGS, what_falls=True))
    assert answers[A.Place(flat).label].any_fall_probability == 0.0
    assert answers[A.Place(overhang).label].object_fall_probability["new"] == 1.0
    # across a gap: a plank spanning two posts 10 cm apart rests on both and stays
    posts = scene("posts", box("p1", -0.15, 0, 0.2, (0.2, 0.2, 0.4)), box("p2", 0.15, 0, 0.2, (0.2, 0.2, 0.4)))
    plank = box("plank", 0, 0, 1.0, (0.3, 0.1, 0.05))
    across = dataclasses.replace(plank, position_m=(0.0, 0.0, A.resting_height_m(posts, plank, 0.0, 0.0, I)))
    assert across.position_m[2] == pytest.approx(0.425, abs=1e-3)
    assert A.place(posts, [across], MODEL, SETTINGS).variants[1].any_fall_probability == 0.0
    ball = scene("ball", Body(name="ball", shape=Sphere(0.1), position_m=(0, 0, 0.1), orientation_xyzw=I,
                              friction=0.6, restitution=0.0, mass_kg=1.0))
    on_ball = dataclasses.replace(new, position_m=(0.0, 0.0, A.resting_height_m(ball, new, 0.0, 0.0, I)))
    assert on_ball.position_m[2] == pytest.approx(0.3, abs=2e-3)
    assert A.place(ball, [on_ball], ModelConfig(sigma_m=0.01, samples=8), SETTINGS).variants[1].any_fall_probability >= 0.75


def test_best_place_ranks_the_centre_of_a_top_first():
    ranked, _ = A.best_place(STACK, box("new", 0, 0, 1.0), A.Region((-0.16, 0.16), (-0.16, 0.16)), MODEL, SETTINGS,
                             candidates=9)
    best_body, best = ranked[0]
    assert best_body.position_m[:2] == (0.0, 0.0) and best.any_fall_probability == 0.0
    assert ranked[-1][1].any_fall_probability == 1.0


def test_pushing_the_bottom_block_drops_the_top_in_the_push_direction():
    answers = A.push(STACK, [A.Push("bottom", (2.0, 0.0, 0.0)), A.Push("top", (0.05, 0.0, 0.0))], MODEL, SETTINGS)
    hard, gentle = answers.variants[1], answers.variants[2]
    assert hard.object_fall_probability["top"] == 1.0 and abs(hard.direction_rad) < math.radians(45)
    assert gentle.any_fall_probability == 0.0


def test_bad_questions_name_the_field():
    with pytest.raises(ConfigError, match=r"^actions\[0\]\.names: no object named 'nope' in 'stack'$"):
        A.ask(STACK, [A.Remove(("nope",))],
              Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), budget_s=None, check=None))
    with pytest.raises(ConfigError, match=r"^actions\[0\]\.body\.name: 'top' is already in the scene"):
        A.ask(STACK, [A.Place(box("top", 0, 0, 0.5))],
              Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), budget_s=None, check=None))
    with pytest.raises(ConfigError, match=r"^actions\[0\]\.velocity_m_s: must be a finite horizontal velocity"):
        A.ask(STACK, [A.Push("top", (0.0, 0.0, 1.0))],
              Request(model=MODEL, settings=SETTINGS, query=A.question_spec(), budget_s=None, check=None))
    with pytest.raises(ConfigError, match=r"^target: no dynamic object named 'x' in 'stack'$"):
        A.clear_order(STACK, MODEL, SETTINGS, target="x")


# -- answers that must not change: found by a user on published brick piles, rebuilt here -----------------
def table_scene(name, *objects, top=0.5, size=(1.0, 1.0)):
    from ipe_ros.engine import Table

    return Scene(name=name, objects=objects, support=Table(top_height_m=top, size_m=size, center_xy_m=(0.0, 0.0),
                                                           thickness_m=0.05, friction=0.6, restitution=0.0,
                                                           floor_z_m=0.0), gravity_m_s2=(0.0, 0.0, -9.81))


def counterweighted(z0=0.0):
    """A plank on a post, its centre of mass 0.2 m beyond the post's edge, held by a 5 kg weight on
    its other end: nothing rests on the weight, but taking it away tips the plank."""
    return [box("post", 0, 0, z0 + 0.1), box("plank", 0.3, 0, z0 + 0.225, (1.0, 0.2, 0.05)),
            box("weight", -0.15, 0, z0 + 0.3, (0.1, 0.1, 0.1), mass=5.0)]


def test_taking_a_counterweight_away_tips_what_it_held_down():
    answer = _by_label(A.remove(scene("lever", *counterweighted()), ["weight"], MODEL, SETTINGS))
    assert answer["as_is"].any_fall_probability == 0.0
    removal = answer["remove/weight"]
    assert removal.simulated and removal.object_fall_probability["plank"] == 1.0  # was: not simulated, 0.0


def test_a_gap_wider_than_the_contact_margin_does_not_make_a_removal_harmless():
    """The upper brick hangs 9 mm above the lower (dropping 9 mm is not a fall: 12.5 mm is); the
    contact search reaches ~5 mm. Without the lower brick the upper one drops 10 cm."""
    model = ModelConfig(sigma_m=0.001, samples=4)
    gap = scene("gap", box("low", 0, 0, 0.05, (0.2, 0.2, 0.1)), box("high", 0, 0, 0.1 + 0.009 + 0.05, (0.2, 0.2, 0.1)))
    answer = _by_label(A.remove(gap, ["low"], model, SETTINGS))
    assert answer["as_is"].any_fall_probability == 0.0
    assert answer["remove/low"].simulated and answer["remove/low"].object_fall_probability == {"high": 1.0}


def test_a_removal_out_of_everything_s_reach_is_still_read_from_the_scene_as_is():
    removal = _by_label(A.remove(FAR, ["lone"], MODEL, SETTINGS))["remove/lone"]
    assert not removal.simulated and removal.object_fall_probability == {"bottom": 0.0, "top": 0.0}


def test_reach_grows_with_what_can_slide_bounce_or_roll():
    # 1.8 m apart; the 0.4 m tower topples (0.49 m) and slides on at friction 0.6 x 0.6: 0.4 / 0.36 m
    wall = [box("a_bottom", 0, 0, 0.1), box("a_top", 0, 0, 0.3), box("b", 2.0, 0, 0.1)]
    assert len(A.groups(scene("grippy", *wall))) == 2
    slippery = [dataclasses.replace(b, friction=0.2) for b in wall]
    assert len(A.groups(scene("slippery", *slippery))) == 1  # slides 0.4 / (0.2 x 0.6) = 3.3 m
    ball = Body(name="ball", shape=Sphere(0.05), position_m=(0.0, 0.0, 0.45), orientation_xyzw=I, friction=0.6,
                restitution=0.0, mass_kg=0.1)  # on the tower: when it falls it rolls on
    assert len(A.groups(scene("rolls", *wall, ball))) == 1
    bouncy = [dataclasses.replace(b, restitution=0.9) for b in wall]
    assert len(A.groups(scene("bouncy", *bouncy))) == 1  # off each other at 0.9 x 0.9: 3.8 m more


def test_what_a_removal_makes_fall_is_told_apart_from_what_falls_anyway():
    """The top block's centre sits on the bottom's edge: the stack falls by itself in about half the
    noisy samples. Removing the bottom drops the top in every sample; counted only where it would
    not have fallen anyway, that shows as ~0.5 - below the support threshold, so the edge vanished."""
    model = ModelConfig(sigma_m=0.01, samples=40)
    edge = scene("edge", box("bottom", 0, 0, 0.1), box("top", 0.1, 0, 0.3))
    graph = A.support_graph(edge, model, SETTINGS, seed=1, sequential=False)
    as_is = graph.answers.alone
    assert 0.2 <= as_is.any_fall_probability <= 0.8 and as_is.unstable
    removal = _by_label(graph.answers)["remove/bottom"]
    assert removal.given_stands.samples == as_is.samples_standing == round(40 * (1 - as_is.any_fall_probability))
    assert removal.given_stands.object_fall_probability == {"top": 1.0}
    assert removal.caused_fall_probability["top"] == pytest.approx(1 - as_is.any_fall_probability)
    assert ("bottom", "top", 1.0) in graph.edges
    assert graph.to_dict()["answers"]["alone"]["unstable"] is True


def test_a_scene_that_always_falls_has_no_edges_and_nothing_safe():
    falls = scene("falls", box("bottom", 0, 0, 0.1), box("top", 0.25, 0, 0.3))
    graph = A.support_graph(falls, MODEL, SETTINGS)
    assert graph.answers.alone.samples_standing == 0 and graph.answers.alone.unstable
    assert graph.edges == () and graph.safe == ()
    assert _by_label(graph.answers)["remove/bottom"].given_stands.any_fall_probability is None


def test_questions_ask_what_falls_off_the_table():
    # the lever at the table's +x edge: without the weight the plank tips off the table
    lever = table_scene("lever", *(dataclasses.replace(b, position_m=(b.position_m[0] + 0.35, *b.position_m[1:]))
                                   for b in counterweighted(0.5)))
    answer = _by_label(A.remove(lever, ["weight"], MODEL, SETTINGS, fell_off=True))
    assert answer["as_is"].any_fell_off_probability == 0.0
    assert answer["remove/weight"].fell_off_probability == {"post": 0.0, "plank": 1.0}
    assert answer["remove/weight"].to_dict()["any_fell_off_probability"] == 1.0
    question = question_from_dict({"question": "remove", "objects": ["weight"], "fell_off": True})
    reply = question.answer(lever, MODEL, SETTINGS).data
    assert reply["variants"][1]["fell_off_probability"]["plank"] == 1.0
    assert "fell_off_probability" not in A.remove(lever, ["weight"], MODEL, SETTINGS).to_dict()["variants"][1]
    with pytest.raises(ConfigError) as info:
        A.remove(STACK, ["top"], MODEL, SETTINGS, fell_off=True)
    assert str(info.value) == ("fell_off: 'stack' stands on a floor: nothing can fall off it (ask it of a scene on a "
                               "table)")
    with pytest.raises(ConfigError, match="^fell_off: must be true or false$"):
        question_from_dict({"question": "remove", "fell_off": "yes"})


def test_a_question_sent_as_json_asks_what_falls_or_not():
    safe = {"question": "remove", "objects": ["c"], "safe_below": 0.05}
    for extra, objects in (({}, None), ({"what_falls": True}, {"a": 0.0, "b": 0.0})):
        reply = question_from_dict({**safe, **extra}).answer(TOWER_3, MODEL, SETTINGS).data
        assert reply["variants"][1]["object_fall_probability"] == objects
    reply = question_from_dict({"question": "remove", "objects": ["c"]}).answer(TOWER_3, MODEL, SETTINGS).data
    assert reply["variants"][1]["object_fall_probability"] == {"a": 0.0, "b": 0.0}
    with pytest.raises(ConfigError, match="^what_falls: must be true or false$"):
        question_from_dict({**safe, "what_falls": 1})
    with pytest.raises(ConfigError, match="^what_falls: unknown field of a support question"):
        question_from_dict({"question": "support", "what_falls": True})


# -- sequential decisions ---------------------------------------------------------------------------------
def test_a_decided_variant_stops_and_an_undecided_one_runs_to_the_cap():
    model = ModelConfig(sigma_m=0.005, samples=24)
    variants = _by_label(A.support_graph(STACK, model, SETTINGS).answers)
    bottom, top = variants["remove/bottom"], variants["remove/top"]
    # the top falls in each of the first batch of 4: 4 of 4 puts the interval above 0.5 (an edge) and
    # above 0.05 ("unsafe"); 0 of 4 would put it below 0.5 (no edge)
    assert (bottom.decision, bottom.stopped_by, bottom.samples_drawn, bottom.samples) == ("unsafe", "decided", 4, 4)
    # nothing falls: "safe below 0.05" needs 73 samples of 0 for a 95% Wilson interval, more than the cap
    assert (top.decision, top.stopped_by, top.samples_drawn, top.samples) == (None, "cap", 24, 24)
    assert variants["as_is"].samples == 24 and variants["as_is"].stopped_by is None


def test_a_variant_no_further_sample_could_decide_stops_before_the_cap():
    """Curtailment: taking the top off the stack, nothing falls. "Safe below 0.05" needs 73 samples
    of no fall; with a cap of 48, 4 more falls after 44 samples could not make it "unsafe" either
    (Wilson low end of 4 of 48: 0.03), so it stops there, undecided as the fixed-k run is."""
    model = ModelConfig(sigma_m=0.005, samples=48)
    top = _by_label(A.remove(STACK, ["top"], model, SETTINGS, safe_below=0.05))["remove/top"]
    assert (top.decision, top.stopped_by, top.samples_drawn, top.samples) == (None, "undecidable", 44, 44)
    fixed = _by_label(A.remove(STACK, ["top"], model, SETTINGS, safe_below=0.05, sequential=False))["remove/top"]
    assert fixed.samples == 48 and SafeBelow(0.05).decide({"t": Tally(48, 0, {})}, {"t"}) == {}
    # two spots on two posts, tied at no fall: after 12 of 16 samples, neither could be ranked out by
    # the last 4 (the low end of 4 of 16 is below the high end of 0 of 16), nor so be left as best
    posts = scene("posts", box("p1", -0.5, 0, 0.1), box("p2", 0.5, 0, 0.1))
    new = box("new", 0, 0, 1.0)
    spots = [dataclasses.replace(new, position_m=(x, 0.0, A.resting_height_m(posts, new, x, 0.0, I)))
             for x in (-0.5, 0.5, 0.62)]
    answers = A.place(posts, spots, ModelConfig(sigma_m=0.005, samples=16), SETTINGS)
    assert [(v.decision, v.stopped_by, v.samples_drawn) for v in answers.variants[1:]] == [
        (None, "undecidable", 12), (None, "undecidable", 12), ("ranked out", "decided", 4)]
    assert Ranking().decide({"a": Tally(16, 0, {}), "b": Tally(16, 0, {})}, {"a", "b"}) == {}


def test_the_next_batch_of_the_scene_as_it_is_runs_beside_this_batch_of_variants():
    """Two variants undecided: samples 4-7 of the scene as it is run in the map call of batch 0's
    variants. Both are decided after batch 0 (the top falls without the bottom in 4 of 4; nothing
    falls without the top, safe below 0.5 after 4 of 4), so samples 4-7 are dropped: the answer is
    the batch-by-batch one, 4 samples."""
    calls = []

    def spy(fn, items, on_lost=None):
        items = list(items)
        calls.append([(t.index, tuple("as_is" if a is None else a.label for a in t.actions)) for t in items])
        return [fn(t) for t in items]

    variants = _by_label(A.support_graph(STACK, ModelConfig(sigma_m=0.005, samples=24), SETTINGS, safe_below=0.5,
                                         map_fn=spy).answers)
    as_is = ("as_is",)
    assert calls[0] == [(i, as_is) for i in range(4)]
    assert calls[1] == [(i, ("remove/bottom", "remove/top")) for i in range(4)] + [(i, as_is) for i in range(4, 8)]
    assert len(calls) == 2
    assert {label: (v.decision, v.samples_drawn) for label, v in variants.items() if label != "as_is"} == {
        "remove/bottom": ("unsafe", 4), "remove/top": ("safe", 4)}
    assert variants["as_is"].samples == 4


def test_a_sequential_answer_equals_the_fixed_k_answer_cut_where_it_stopped():
    """Sample i keeps seed i: in the edge stack (falls by itself in about half the samples) the
    removal decided after n drawn samples answers what a fixed-k run of n samples answers over its
    standing samples."""
    model = ModelConfig(sigma_m=0.01, samples=40)
    edge = scene("edge", box("bottom", 0, 0, 0.1), box("top", 0.1, 0, 0.3))
    sequential = _by_label(A.support_graph(edge, model, SETTINGS, seed=1).answers)["remove/bottom"]
    assert sequential.stopped_by == "decided" and sequential.samples_drawn < 40
    fixed = _by_label(A.support_graph(edge, dataclasses.replace(model, samples=sequential.samples_drawn), SETTINGS,
                                      seed=1, sequential=False).answers)["remove/bottom"]
    assert sequential.given_stands == fixed.given_stands
    assert (sequential.any_fall_probability, sequential.samples) == (fixed.given_stands.any_fall_probability,
                                                                     fixed.given_stands.samples)


def test_best_place_ranks_hopeless_spots_out_early_and_says_so():
    model = ModelConfig(sigma_m=0.005, samples=32)
    new = box("new", 0, 0, 0, (0.2, 0.2, 0.2))
    rows, answers = A.place_at(STACK, new, [(0.0, 0.0, 0.0), (0.17, 0.0, 0.0)], model, SETTINGS)
    (centre, on_top), (edge_spot, overhanging) = rows
    assert centre.position_m[0] == 0.0 and edge_spot.position_m[0] == 0.17
    assert overhanging.decision == "ranked out" and overhanging.samples_drawn == 4
    assert on_top.decision == "best" and on_top.stopped_by == "decided"
    fixed_rows, _ = A.place_at(STACK, new, [(0.0, 0.0, 0.0), (0.17, 0.0, 0.0)], model, SETTINGS, sequential=False)
    assert [b.position_m for b, _ in fixed_rows] == [b.position_m for b, _ in rows]  # the same order


def test_candidates_are_ranked_on_the_samples_where_the_scene_stands():
    # what falls anyway weighs on every candidate alike (common random numbers): the ranking reads
    # the standing samples, as the sequential rule does, so a sequential and a fixed-k answer agree
    from ipe_ros.engine.actions.answers import GivenStands, VariantAnswer
    from ipe_ros.engine.actions.questions import _rank_key

    def candidate(label, p_all, p_standing):
        return VariantAnswer(label=label, action=None, any_fall_probability=p_all, any_fall_probability_ci95=None,
                             object_fall_probability={}, direction_rad=None, samples=16, failed_samples=0,
                             given_stands=GivenStands(12, p_standing, None, {}))

    # "a" props the scene up in two of the four samples where it falls by itself but topples it in one
    # of the twelve where it stands; "b" never makes anything fall: "b" first (over all samples, "a")
    props_up, harmless = candidate("a", 0.1875, 1 / 12), candidate("b", 0.25, 0.0)
    assert [v.label for v in sorted([props_up, harmless], key=_rank_key)] == ["b", "a"]
    never_stands = dataclasses.replace(candidate("c", 0.5, None), given_stands=GivenStands(0, None, None, {}))
    assert _rank_key(never_stands) == (False, 0.5)


# -- questions as objects: read, answered and written back by one class per kind ---------------------------------
QUESTION_JSON = [
    {"id": "r1", "question": "support", "threshold": 0.4, "samples": 2},
    {"id": "r2", "question": "remove", "objects": ["box0"], "safe_below": 0.1, "contact": ["box1:support"],
     "what_falls": True, "fell_off": True},
    {"id": "r3", "question": "clear", "target": "box1", "sequential": False},
    {"id": "r4", "question": "push", "object": "box1", "velocity_m_s": [1.0, 0.0], "point_m": [0.1, 0.0, 0.5],
     "direction_sigma_deg": 5.0, "speed_sigma": 0.1, "contact": ["box1:box0"], "cancel_older": True},
    {"id": "r5", "question": "place", "object": {"name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]},
                                                 "mass_kg": 1.0, "friction": 0.5, "restitution": 0.0},
     "at": [[0.6, 0.0, 30.0], [0.2, 0.1]], "what_falls": False, "self_check": True},
    {"id": "r6", "question": "place", "object": {"name": "new", "shape": {"type": "sphere", "radius_m": 0.05},
                                                 "mass_kg": 1.0, "friction": 0.5, "restitution": 0.0},
     "region": {"x_m": [0.5, 0.9], "y_m": [-0.2, 0.2], "yaw_deg": [0, 90], "candidates": 4, "yaws": 2}},
]


@pytest.mark.parametrize("data", QUESTION_JSON, ids=lambda d: d["id"])
def test_a_question_writes_itself_back_to_the_json_it_was_read_from(data):
    question = question_from_dict(data)
    assert type(question) is A.QUESTION_KINDS[data["question"]]
    written = question.to_dict()
    assert question_from_dict(json.loads(json.dumps(written))) == question
    assert {k: written[k] for k in data if k not in ("object", "at")} == {k: v for k, v in data.items()
                                                                          if k not in ("object", "at")}


def test_a_question_built_in_python_is_checked_as_the_json_is():
    with pytest.raises(ConfigError, match=r"^safe_below: must be in \(0, 1\], got 2$"):
        A.RemoveQuestion(safe_below=2)
    with pytest.raises(ConfigError, match=r"^objects: names no object"):
        A.RemoveQuestion(objects=())
    with pytest.raises(ConfigError, match=r"^threshold: must be in \(0, 1\], got 0$"):
        A.SupportQuestion(threshold=0)
    body = question_from_dict(QUESTION_JSON[4]).body
    with pytest.raises(ConfigError, match=r"^at: give candidate spots in \"at\" or a \"region\""):
        A.PlaceQuestion(body=body)
    with pytest.raises(ConfigError, match=r"^region.candidates: 200 candidates x 3 yaws are 600 placements"):
        A.PlaceQuestion(body=body, region=A.Region((0, 1), (0, 1)), candidates=200, yaws=3)


@pytest.mark.parametrize("argv, data", [
    (["remove", "--object", "c", "--what-falls", "--contact", "a:b"],
     {"question": "remove", "objects": ["c"], "what_falls": True, "contact": ["a:b"]}),
    (["support", "--threshold", "0.4", "--fixed-k", "--self-check"],
     {"question": "support", "threshold": 0.4, "sequential": False, "self_check": True}),
    (["clear", "--target", "b"], {"question": "clear", "target": "b"}),
    (["push", "--object", "b", "--velocity", "0.5,0", "--direction-sigma-deg", "5", "--speed-sigma", "0.1"],
     {"question": "push", "object": "b", "velocity_m_s": [0.5, 0.0], "direction_sigma_deg": 5.0, "speed_sigma": 0.1}),
    (["place", "--object", json.dumps(QUESTION_JSON[4]["object"]), "--at", "0.6,0,30", "--at", "0.2,0.1"],
     {**{k: QUESTION_JSON[4][k] for k in ("object", "at")}, "question": "place", "what_falls": False}),
])
def test_ipe_ask_asks_the_very_question_the_node_reads_from_json(argv, data):
    """One class per kind answers both doors: the command line's options make the same object as the
    node's ~/ask JSON, so both are answered alike (benchmarks/bit_identity.py holds the answers)."""
    from ipe_ros.cli import build_parser
    from ipe_ros.cli_ask import question_from_args

    args = build_parser().parse_args(["ask", argv[0], "scene.json", *argv[1:]])
    assert question_from_args(args) == question_from_dict(data)


@pytest.mark.parametrize("kind", [[], {}, None, 3, "fly"])
def test_a_question_of_no_known_kind_is_refused_by_name(kind):
    with pytest.raises(ConfigError, match=r"^question: must be one of remove, support, clear, place, push, got "):
        question_from_dict({"question": kind})


def test_a_question_and_a_prediction_each_refuse_the_others_stopping_rule():
    from ipe_ros.engine import AdaptiveStop, QuerySpec, predict
    from ipe_ros.engine.sampling.decide import Ranking, Sequential

    with pytest.raises(ConfigError, match=r"^stop: a question stops by a Sequential rule \(engine.sampling.decide\); "
                                          r"anytime sampling \(AdaptiveStop\) is for predictions$"):
        A.ask(STACK, [None], Request(model=MODEL, settings=SETTINGS, query=A.question_spec(),
                                     stop=AdaptiveStop(ci_width=0.2), budget_s=None, check=None))
    with pytest.raises(ConfigError, match=r"^stop: a prediction stops by an AdaptiveStop \(a deadline or an interval "
                                          r"width\); a Sequential rule decides robot questions$"):
        predict(STACK, Request(model=MODEL, settings=SETTINGS, query=QuerySpec(), stop=Sequential(Ranking()),
                               budget_s=None))


def test_the_ask_table_says_why_a_variant_was_escalated():
    from ipe_ros.cli_ask import _table
    from ipe_ros.engine.actions.answers import VariantAnswer
    from ipe_ros.engine.actions.kinds import Remove

    def variant(name, fidelity, self_check):
        return VariantAnswer(label=f"remove/{name}", action=Remove((name,)), any_fall_probability=0.5,
                             any_fall_probability_ci95=(0.2, 0.8), object_fall_probability={"top": 0.5},
                             direction_rad=None, samples=8, failed_samples=0, fidelity=fidelity, self_check=self_check)

    table = _table(A.Answers("tower", (variant("a", "escalated", {"escalated_because": ["beyond_tolerance", "refined"]}),
                                       variant("b", "contradicted", {}), variant("c", "verified", {})), 8, 1.0))
    a, b, c = table.splitlines()[1:]
    assert a.endswith("(escalated: beyond_tolerance, refined)") and b.endswith("(contradicted)")
    assert "(" not in c.split("top 0.50")[1]
