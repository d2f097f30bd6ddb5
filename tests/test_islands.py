"""Islands (``SimSettings.islands``, simulation/islands.py): groups of bodies that nothing brings
together, each simulated in a world of its own, and the whole scene as one world once two could
have met."""

import dataclasses
import math

import numpy as np
import pytest

from ipe_ros.engine import Box, ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine import simulation
from ipe_ros.engine.sampling import rollout
from ipe_ros.engine.sampling.perturb import draw_sample_inputs

from .helpers import block, floor_scene

ISLANDS = preset("default").changed("default-islands", islands=True)
FAR = QuerySpec(queries=frozenset({"far", "fall"}))  # rollouts run to rest: every pose read


def _tile(name: str, x: float, **kw) -> Box:
    """A 3 x 3 x 1 cm tile: the size cap gives it (and any world it is in) 2.2 ms steps against 1/180 s."""
    return Box(name=name, extents_m=(0.03, 0.03, 0.01), position_m=(x, 0.0, 0.005), orientation_xyzw=(0, 0, 0, 1),
               friction=0.9, restitution=0.0, mass_kg=0.1, **kw)


def _tipping_tower():
    """Two blocks, the top one over the edge (it falls), and a tile 2 m away."""
    return floor_scene(block("b0", 0.0, 0.0, 0.1), block("b1", 0.13, 0.0, 0.3), _tile("tile", 2.0))


def _separated(scene, settings=ISLANDS):
    inputs = draw_sample_inputs(scene, ModelConfig(sigma_m=0.0), np.random.default_rng(0))
    return rollout.separated_world(scene, settings, inputs)


def _groups(scene, horizon_s=2.0, gap_m=0.002):
    world = _separated(scene)
    velocities = np.array([b.linear_velocity_m_s for b in scene.dynamic_objects], float)
    return [[scene.dynamic_objects[i].name for i in g] for g in simulation.islands.partition(world, velocities,
                                                                                               horizon_s, gap_m)]


def test_bodies_that_touch_or_could_fall_or_be_thrown_onto_each_other_are_one_island():
    assert _groups(_tipping_tower()) == [["b0", "b1"], ["tile"]]
    # a block 5 cm above the tile falls onto it: one island
    hovering = floor_scene(_tile("tile", 0.0), block("above", 0.0, 0.0, 0.16, extents=(0.2, 0.2, 0.2)))
    assert _groups(hovering) == [["tile", "above"]]
    # a block thrown at the tile from 1.5 m away reaches it within the horizon; thrown away from it, never
    thrown = floor_scene(_tile("tile", 0.0), block("thrown", 1.5, 0.0, 0.1, extents=(0.2, 0.2, 0.2),
                                                     linear_velocity_m_s=(-1.0, 0.0, 0.0)))
    assert _groups(thrown) == [["tile", "thrown"]]
    away = floor_scene(_tile("tile", 0.0), block("thrown", 1.5, 0.0, 0.1, extents=(0.2, 0.2, 0.2),
                                                   linear_velocity_m_s=(1.0, 0.0, 0.0)))
    assert _groups(away) == [["tile"], ["thrown"]]


def test_each_island_is_answered_as_it_would_be_alone_at_its_own_step():
    """The tower apart from a tile 2 m away: its rollout is, bit for bit, the tower's world alone
    (built from the same start, at 1/180 s), where the whole scene steps at the tile's 2.2 ms. Bit
    for bit because each island sets Bullet's contact distance, one global for every client of the
    process, again before it steps on (``StepControl.reapply``)."""
    scene = _tipping_tower()
    model = ModelConfig(sigma_m=0.01, samples=2)
    p = predict(scene, Request(model=model, settings=ISLANDS, query=FAR, seed=3, check=None, budget_s=None))
    whole = predict(scene,
                    Request(model=model, settings=preset("default"), query=FAR, seed=3, check=None, budget_s=None))
    assert p.fall_fraction == whole.fall_fraction == pytest.approx(1 / 3)  # the top block, in both
    assert _separated(scene).time_step_s < 0.003
    outcome = p.outcomes[0]
    tower = floor_scene(*scene.dynamic_objects[:2])
    world = simulation.build_world(tower, outcome.initial_positions_m[:2], np.ones(2),
                                   ISLANDS, orientations_xyzw=outcome.initial_orientations_xyzw[:2])
    assert world.time_step_s == pytest.approx(1 / 180)
    settings = rollout.query_settings(ISLANDS, FAR)
    alone = simulation.simulate(world, tower, settings, simulation.Push(),
                                collapse_below_z_m=rollout.collapse_heights(tower, ISLANDS,
                                                                            outcome.initial_positions_m[:2]))
    np.testing.assert_array_equal(outcome.rollouts[0].final_positions_m[:2], alone.positions_m)
    # the tile never moved
    np.testing.assert_allclose(outcome.rollouts[0].final_positions_m[2], outcome.initial_positions_m[2], atol=1e-4)


def test_islands_that_could_meet_are_simulated_as_one_world():
    """A domino tilted towards a box 10 cm away starts apart from it and falls onto it: the islands'
    footprints meet, and the sample is simulated as one world, where the domino ends leaning on the
    box (apart, it would have fallen flat through where the box is)."""
    tilt = math.radians(12)
    lowest = 0.2 * math.cos(tilt) + 0.01 * math.sin(tilt)  # of the tilted domino's corners, below its centre
    # 4 cm wide: its 2.6 ms steps are finer than half the box's, so the two are kept apart
    domino = Box(name="domino", extents_m=(0.02, 0.04, 0.4), position_m=(0.0, 0.0, lowest + 0.001),
                 orientation_xyzw=(0.0, math.sin(tilt / 2), 0.0, math.cos(tilt / 2)), friction=0.9, restitution=0.0,
                 mass_kg=1.0, position_sigma_m=0.0)
    box = block("box", 0.2 + 0.1 + 0.1, 0.0, 0.1, extents=(0.2, 0.2, 0.2), mass_kg=5.0, position_sigma_m=0.0)
    scene = floor_scene(domino, box)
    assert _groups(scene) == [["domino"], ["box"]]
    met = []
    original = rollout.Apart.simulate

    def spy(self, *args, **kw):
        try:
            return original(self, *args, **kw)
        except simulation.IslandsMet as exc:
            met.append(str(exc))
            raise

    rollout.Apart.simulate = spy
    try:
        p = predict(scene,
                    Request(model=ModelConfig(sigma_m=0.0, samples=1), settings=ISLANDS, query=FAR, seed=0,
                            check=None, budget_s=None))
    finally:
        rollout.Apart.simulate = original
    assert len(met) == 1 and met[0].startswith("two islands could have met between t = ")
    final = p.outcomes[0].rollouts[0].final_positions_m
    assert final[0, 2] > 0.05  # leaning on the box, not lying on the floor (0.02)
    assert not p.outcomes[0].rollouts[0].penetration_fraction > 0.05


def test_recording_islands_changes_nothing_and_shows_every_body_on_one_clock():
    scene = _tipping_tower()
    model = ModelConfig(sigma_m=0.01, samples=1)
    plain = predict(scene, Request(model=model, settings=ISLANDS, query=FAR, seed=3, check=None, budget_s=None))
    recorded = predict(scene, Request(model=model, settings=ISLANDS, query=FAR, seed=3, check=None, budget_s=None),
                       Context(record_every=5, record_samples=1))
    a, b = plain.outcomes[0].rollouts[0], recorded.outcomes[0].rollouts[0]
    np.testing.assert_array_equal(a.final_positions_m, b.final_positions_m)
    frames = b.trajectory
    times = [t for t, *_ in frames]
    assert times[0] == 0.0 and times == sorted(times) and len(set(times)) == len(times)
    assert all(positions.shape == (3, 3) and orientations.shape == (3, 4) for _, positions, orientations in frames)
    assert times[-1] <= b.simulated_s


def test_questions_about_contacts_and_whether_anything_falls_keep_one_world():
    scene = _tipping_tower()
    world = _separated(scene)
    initial = simulation.read_poses(world)[0]
    any_fall = QuerySpec(queries=frozenset({"any_fall"}))
    decided = rollout.decided_heights(scene, ISLANDS, any_fall, initial)
    assert decided.stop_at_first_fall
    assert rollout.Apart.of(scene, ISLANDS, any_fall, world, decided, 0) is None
    contact = QuerySpec(queries=frozenset({"contact"}), contact_pairs=(("b0", "tile"),))
    assert rollout.Apart.of(scene, ISLANDS, contact, world, None, 0) is None
    assert rollout.Apart.of(scene, ISLANDS, FAR, world, None, 0) is not None
    assert rollout.Apart.of(scene, preset("paper"), FAR, world, None, 0) is None  # off unless asked for


def test_scattered_bodies_make_at_most_eight_groups():
    scene = floor_scene(*(block(f"b{i}", 0.5 * i, 0.0, 0.1, extents=(0.2, 0.2, 0.2)) for i in range(12)))
    groups = _groups(scene)
    assert len(groups) == simulation.islands.MAX_ISLANDS
    assert groups[-1] == [f"b{i}" for i in range(7, 12)] and sum(map(len, groups)) == 12


def test_groups_are_simulated_apart_only_where_they_step_at_least_twice_as_coarse():
    """Twelve scattered blocks of one size would step alike apart: one world, no islands to pay for.
    A tower beside a tile that sets the whole world's 2.2 ms steps takes 1/180 s apart: two."""
    by_step = simulation.islands.by_step
    a, b, c, d = (np.array([i]) for i in range(4))
    assert [g.tolist() for g in by_step([a, b, c, d], [0.0026, 0.0055, 0.0030, 0.0052])] == [[0, 2], [1, 3]]
    assert [g.tolist() for g in by_step([a, b], [0.004, 0.0055])] == [[0, 1]]
    scattered = floor_scene(*(block(f"b{i}", 0.5 * i, 0.0, 0.1, extents=(0.2, 0.2, 0.2)) for i in range(12)))
    assert rollout.Apart.of(scattered, ISLANDS, FAR, _separated(scattered), None, 0) is None
    tower = _tipping_tower()
    apart = rollout.Apart.of(tower, ISLANDS, FAR, _separated(tower), None, 0)
    assert [g.tolist() for g in apart.groups] == [[2], [0, 1]]  # the tile's finer step first


def test_a_footprint_back_in_time_goes_on_from_there():
    """Collapse steps undone take an island back to an earlier read: no stretch runs backwards in
    time, the ones made before stay, and the next stretch starts from the earlier read."""
    tracks = simulation.islands.Tracks(2, 2.0, 0.001)
    box = lambda x: (np.array([[x, 0.0, 0.0]]), np.array([[x + 0.1, 0.1, 0.1]]))  # noqa: E731
    footprint = lambda t, x, v=0.0: simulation.islands.Footprint(t, *box(x), np.array([v]))  # noqa: E731
    tracks.add(1, footprint(0.0, 1.0))
    tracks.add(1, footprint(1.0, 1.0))
    tracks.add(0, footprint(0.0, 0.0))
    tracks.add(0, footprint(0.5, 0.3, v=1.0))  # reached 0.3 + 0.1 + 0.5 m: not the other at 1.0
    tracks.add(0, footprint(0.2, 0.0))  # undone: back to t = 0.2
    with pytest.raises(simulation.IslandsMet, match=r"^two islands could have met between t = 0\.200 s and 0\.400 s$"):
        tracks.add(0, footprint(0.4, 0.9, v=0.5))


def _plank_and_tile(tile_xy):
    """A 1 m plank lying across the diagonal (its bounding box fills the square it spans) and a tile."""
    half = math.sin(math.pi / 8), math.cos(math.pi / 8)
    plank = dataclasses.replace(block("plank", 0.0, 0.0, 0.025, extents=(1.0, 0.05, 0.05)),
                                orientation_xyzw=(0.0, 0.0, *half))
    return floor_scene(plank, dataclasses.replace(_tile("tile", 0.0), position_m=(*tile_xy, 0.005)))


def _tracks_of(scene, gaps: bool):
    """Tracks of the plank (island 0) and the tile (island 1), each footprint read from a world of
    the scene at rest."""
    inputs = draw_sample_inputs(scene, ModelConfig(sigma_m=0.0), np.random.default_rng(0))
    world = simulation.build_world(scene, inputs.positions_m, inputs.masses_kg, ISLANDS)
    boxes = simulation.world.bounding_boxes(world)
    positions, orientations = simulation.world.read_poses(world)
    members = (np.array([0]), np.array([1]))
    shapes = simulation.islands.ShapeGaps(lambda: simulation.build_world(
        scene, inputs.positions_m, inputs.masses_kg, ISLANDS, slot=simulation.islands.MAX_ISLANDS), members) \
        if gaps else None
    tracks = simulation.islands.Tracks(2, 2.0, 0.002, shapes)

    def footprint(island, t_s, speed_m_s=0.0):
        i = members[island]
        return simulation.islands.Footprint(t_s, boxes[i, 0], boxes[i, 1], np.array([speed_m_s]), positions[i],
                                            orientations[i])
    return tracks, footprint, shapes


def test_bodies_whose_boxes_overlap_meet_only_where_their_shapes_could_have():
    """A long body across the diagonal fills a bounding box far larger than itself (a ladle leaning
    over a mug's rim): where the boxes overlap, the islands meet only if the shapes, grown by how
    far each can have moved, come within the clearance."""
    far = _plank_and_tile((0.3, -0.3))  # 0.42 m from the plank's axis, inside its bounding box
    for gaps in (False, True):
        tracks, footprint, shapes = _tracks_of(far, gaps)
        try:
            tracks.add(0, footprint(0, 0.0))
            tracks.add(0, footprint(0, 0.15))
            tracks.add(1, footprint(1, 0.0))
            if not gaps:  # the boxes alone: met
                with pytest.raises(simulation.IslandsMet):
                    tracks.add(1, footprint(1, 0.05))
                continue
            tracks.add(1, footprint(1, 0.05))
            # read at the same place, the tile went out and back on a path of up to twice the faster read's
            # speed: at 5 m/s 0.25 m out at most, short of the plank 0.39 m away
            tracks.add(1, footprint(1, 0.1, speed_m_s=5.0))
            # at 10 m/s it can have gone there and back since the last read
            with pytest.raises(simulation.IslandsMet, match=r"^two islands could have met between t = 0\.100 s and "
                                                             r"0\.150 s$"):
                tracks.add(1, footprint(1, 0.15, speed_m_s=10.0))
        finally:
            if shapes is not None:
                shapes.close()
    # 1 cm beside the plank's side (its centre 5.6 cm from the plank's axis), 0.3 m along it
    along, across = 0.3 / math.sqrt(2), 0.056 / math.sqrt(2)
    near = _plank_and_tile((along + across, along - across))
    # read at the same place twice, the plank went out and back between: at 0.1 m/s 0.5 cm out at most
    # (though the gap, 1 cm, is within the 0.7 cm reaches' 1.4 cm), at 0.3 m/s 1.5 cm
    for plank_speed_m_s, meets in ((0.0, False), (0.1, False), (0.3, True)):
        tracks, footprint, shapes = _tracks_of(near, True)
        try:
            tracks.add(0, footprint(0, 0.0))
            tracks.add(0, footprint(0, 0.05, speed_m_s=plank_speed_m_s))
            tracks.add(1, footprint(1, 0.0))
            if meets:
                with pytest.raises(simulation.IslandsMet):
                    tracks.add(1, footprint(1, 0.05))
            else:
                tracks.add(1, footprint(1, 0.05))
        finally:
            shapes.close()
