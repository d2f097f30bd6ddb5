"""The rollout loop's parts, each on its own: settling, collapse watch, step sizes, rest watch, health."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ipe_ros.engine import PhysicsError, preset
from ipe_ros.engine.simulation import health
from ipe_ros.engine.simulation.collapse import CollapseWatch
from ipe_ros.engine.simulation.settling import Settling
from ipe_ros.engine.simulation.steps import substeps_for, ticks_allowed
from ipe_ros.engine.simulation.termination import REST_NOISE_FLOOR_PER_S, DecidedHeights, RestWatch
from ipe_ros.engine.simulation.world import World

DEFAULT = preset("default")


def test_settling_covers_the_first_ticks_only_when_it_has_substeps():
    settling = Settling(DEFAULT, 1 / 180)
    assert settling.ticks == 18 and settling.substeps == 2
    assert settling.covers(17) and not settling.covers(18)
    assert Settling(DEFAULT.changed(settling={"substeps": 1}), 1 / 180).ticks == 0


def test_collapse_starts_at_the_first_clear_fall_after_the_quiet_period():
    smallest = np.array([0.2, 0.2])  # default: collapsing below half of it, 0.1 m down
    watch = CollapseWatch(DEFAULT, np.array([0.5, 0.5]), smallest)
    assert watch.watching and not watch.collapsing
    assert not watch.look(10, 36, np.array([0.4, 0.6]), True)  # below, but still in the push / settling
    assert not watch.look(40, 36, np.array([0.6, 0.6]), True)
    assert watch.look(45, 36, np.array([0.6, 0.49]), True) and watch.collapsing and not watch.watching
    assert watch.coarse_factor(10) == 4 and watch.coarse_factor(2) == 2 and watch.coarse_factor(0) == 1
    assert not CollapseWatch(preset("fine"), np.array([0.5]), smallest[:1]).active  # no collapse steps in `fine`


def test_a_collapse_is_over_once_nothing_moves_fast_and_the_watch_starts_again_from_there():
    watch = CollapseWatch(DEFAULT, np.array([0.5, 0.5]), np.array([0.2, 0.2]))
    # fallen, but already still: no coarse steps, and what fell is where the watch starts again
    assert not watch.look(45, 36, np.array([0.6, 0.45]), False) and watch.watching
    assert not watch.look(50, 36, np.array([0.6, 0.40]), True)  # 5 cm further: not a clear fall
    assert watch.look(55, 36, np.array([0.6, 0.34]), True) and watch.collapsing
    assert watch.still_standing(np.array([0.6, 0.1])) and not watch.still_standing(np.array([0.3, 0.1]))
    watch.settled(np.array([0.6, 0.1]))
    assert watch.watching and not watch.collapsing
    assert not watch.look(60, 36, np.array([0.51, 0.1]), True)
    assert watch.look(65, 36, np.array([0.49, 0.1]), True)


def test_the_travel_limit_sets_substeps_and_coarse_steps():
    world = World(client=-1, dynamic_ids=[], scale_m=0.2, time_step_s=0.01)
    # 0.5 x 0.2 m per step: 10 m/s fits one step exactly, 25 m/s needs 3 substeps, 2 m/s allows 5 ticks
    assert substeps_for(10.0, DEFAULT, world) == 1
    assert substeps_for(25.0, DEFAULT, world) == 3
    assert ticks_allowed(2.0, DEFAULT, world) == 5 and ticks_allowed(50.0, DEFAULT, world) == 0


def _rest(decided=None, radii_m=(0.1, 0.1)):
    return RestWatch(DEFAULT.early_stop, scale_m=0.2, earliest_stop_s=0.2, decided=decided, n_boxes=2,
                     radii_m=np.array(radii_m))


def test_rest_needs_a_whole_window_without_growing_motion():
    rest, slow = _rest(), np.array([0.01, 0.01])
    assert not rest.should_stop(0.1, slow, slow, None)  # before the earliest stop
    assert not rest.should_stop(0.2, slow, slow, None)  # the window starts
    assert not rest.should_stop(0.3, slow, slow, None)  # 0.1 s of 0.15
    assert rest.should_stop(0.35, slow, slow, None)
    tipping = _rest()
    tipping.should_stop(0.2, slow, slow, None)
    assert not tipping.should_stop(0.35, slow * 3, slow, None)  # still slow but speeding up: no rest
    assert not _rest().should_stop(0.5, np.array([1.0, 0.0]), slow, None)  # too fast
    assert REST_NOISE_FLOOR_PER_S > 0


def test_a_decided_body_holds_up_the_end_while_it_can_still_reach_an_open_one():
    decided = DecidedHeights(fallen_below_z_m=np.array([0.1, 0.3]))
    radii = np.array([0.1, 0.1])
    moving, still = np.array([0.0, 5.0]), np.zeros(2)
    # the second body fell but rolls on beside the first, which stands: it may still knock it over
    beside = np.array([0.2, 0.15])
    rest = _rest(decided, radii)
    for t in (0.2, 0.35, 1.0):
        assert not rest.should_stop(t, moving, still, beside)
    assert rest.undecided.tolist() == [True, False]
    # once it lies still, its outcome and its motion are both settled
    assert not rest.should_stop(1.05, still, still, beside) and rest.should_stop(1.2, still, still, beside)
    # fallen off the table, wholly below the open body: nothing it does reaches it
    below = np.array([0.2, -0.5])
    rest = _rest(decided, radii)
    assert not rest.should_stop(0.2, moving, still, below) and rest.should_stop(0.35, moving, still, below)


def test_a_yes_no_question_ends_at_the_first_fall():
    first_fall = _rest(DecidedHeights(fallen_below_z_m=np.array([0.1, 0.3]), stop_at_first_fall=True))
    assert first_fall.should_stop(0.05, np.array([0.0, 5.0]), np.zeros(2), np.array([0.2, 0.05]))
    assert not _rest(DecidedHeights(fallen_below_z_m=np.array([0.1, 0.3]), stop_at_first_fall=True)).should_stop(
        0.05, np.array([0.0, 5.0]), np.zeros(2), np.array([0.2, 0.35]))


def test_health_names_divergence_and_watches_energy_after_the_inputs():
    health.check_speeds(np.array([1.0, 2.0]), 10.0, 0.5)
    with pytest.raises(PhysicsError, match=r"^a box reached 12 m/s at t = 0\.500 s, above the physical bound 10 m/s"):
        health.check_speeds(np.array([1.0, 12.0]), 10.0, 0.5)
    with pytest.raises(PhysicsError, match="^non-finite velocity at t = 0.500 s"):
        health.check_speeds(np.array([np.nan]), 10.0, 0.5)
    watch = health.EnergyWatch(np.ones(1), np.ones((1, 3)), np.array([0.0, 0.0, -10.0]))
    watch.look(100.0)  # before the reference (during the push) nothing counts
    watch.reference(5.0)
    watch.look(4.0)
    watch.look(5.5)
    assert watch.max_gain_j == pytest.approx(0.5)
    # energy made since the least seen: collisions took 1 J, the solver gave 0.5 J back
    assert watch.lowest_j == pytest.approx(4.0) and watch.created_j(4.5) == pytest.approx(0.5)


def test_a_collapse_trial_puts_the_world_and_the_loop_back_as_they_were():
    from ipe_ros.engine.simulation.collapse import CollapseTrial
    from ipe_ros.engine.simulation.bullet import pybullet
    from ipe_ros.engine.simulation.world import build_world, read_state

    from .helpers import block, floor_scene

    scene = floor_scene(block("low", 0.0, 0.0, 0.1), block("high", 0.0, 0.0, 0.6))
    world = build_world(scene, np.array([b.position_m for b in scene.dynamic_objects]), np.ones(2), DEFAULT)
    p = pybullet()
    for _ in range(10):
        p.stepSimulation(physicsClientId=world.client)
    saved = tuple(a.copy() for a in read_state(world))
    parts = {"watched": [1, 2]}
    trajectory = ["frame 0", "frame 1"]
    trial = CollapseTrial(world, 10, saved, parts, len(trajectory))
    parts["watched"].append(3)  # the loop goes on: its parts change after the trial was taken
    for _ in range(40):
        p.stepSimulation(physicsClientId=world.client)
        trajectory.append("later frame")
    assert not np.allclose(read_state(world)[0], saved[0])
    looked, restored = trial.restore(trajectory)
    assert trajectory == ["frame 0", "frame 1"] and restored == {"watched": [1, 2]}
    for now, then in zip(read_state(world), saved):
        np.testing.assert_array_equal(now, then)
    assert looked is saved
    trial.close()
    trial.close()  # once freed, closing again does nothing


def test_the_quick_depth_test_agrees_with_the_deepest_penetration():
    # a small cube sunk into a large one by several depths, with and without the small one counted:
    # deeper_than skips the per-body pass only when no body can be that deep
    from ipe_ros.engine.simulation.world import build_world

    from .helpers import block, floor_scene

    for sunk_m in (0.0, 0.004, 0.01, 0.03, 0.06):
        scene = floor_scene(block("big", 0.0, 0.0, 0.2, extents=(0.4, 0.4, 0.4)),
                            block("small", 0.0, 0.0, 0.45 - sunk_m, extents=(0.1, 0.1, 0.1)))
        positions = np.array([b.position_m for b in scene.dynamic_objects])
        world = build_world(scene, positions, np.array([1.0, 1.0]), DEFAULT)
        smallest = np.array([0.4, 0.1])
        for among in (None, np.array([True, False]), np.array([False, True])):
            deepest = health.deepest_penetration_fraction(world, smallest, among)
            for fraction in (0.0, 0.01, 0.05, 0.1, 0.2, 0.5):
                assert health.deeper_than(world, smallest, fraction, among) == (deepest > fraction), \
                    (sunk_m, among, fraction, deepest)
        if sunk_m >= 0.03:
            assert health.deepest_penetration_fraction(world, smallest) > 0.2  # the small cube, mostly


def test_the_step_follows_each_bodys_thickness_unless_asked_to_follow_its_tipping_lever():
    """``SimSettings.step_time_scale``: a 4 mm plate sets a world's step by its thickness (the
    presets' rule); "tipping" reads its middle extent instead, the shortest lever it can tip or roll
    about (a rod's width, not its length). Measured on the zoo and rejected for `default`
    (benchmarks/HISTORY.md), it stays a setting a trial can name."""
    from ipe_ros.engine import Box, Floor, Scene
    from ipe_ros.engine.errors import ConfigError
    from ipe_ros.engine.simulation import time_step_of

    def alone(extents):
        body = Box(name="b", extents_m=extents, position_m=(0.0, 0.0, 0.1), orientation_xyzw=(0, 0, 0, 1),
                   friction=0.5, restitution=0.0, mass_kg=1.0)
        return Scene(name="one", objects=(body,), support=Floor(friction=0.5, restitution=0.0))

    fraction = DEFAULT.max_step_fraction_of_time_scale
    tipping = DEFAULT.changed(step_time_scale="tipping")
    plate, rod = alone((0.2, 0.1, 0.004)), alone((0.4, 0.012, 0.004))
    assert time_step_of(plate, DEFAULT) == pytest.approx(fraction * math.sqrt(0.004 / 9.81))
    assert time_step_of(plate, tipping) == pytest.approx(min(1 / 180, fraction * math.sqrt(0.1 / 9.81)))
    assert time_step_of(rod, tipping) == pytest.approx(fraction * math.sqrt(0.012 / 9.81))
    # the travel limit still follows the smallest extent: a plate thrown at 5 m/s moves 1 mm a step
    thrown = Scene(name="thrown", objects=(dataclasses.replace(plate.objects[0], linear_velocity_m_s=(5.0, 0, 0)),),
                   support=plate.support)
    assert time_step_of(thrown, tipping) == pytest.approx(DEFAULT.max_travel_fraction * 0.004 / 5.0)
    with pytest.raises(ConfigError, match=r"^step_time_scale: unknown 'length'; choose one of thickness, tipping$"):
        DEFAULT.changed(step_time_scale="length")

