"""A named catalogue of hard scenes that must stay numerically stable (issue 4).

Every case runs with the `default`, `fine` and `paper` presets and records its trajectories. Each
trajectory must hold:
* only finite numbers, and no failed (diverged) samples;
* no box faster than free fall over the horizon plus what the push can add;
* no box through the floor or the table top, none at rest more than a contact slop inside them,
  and none overshooting into them by more than one step's travel (at the step in use, fine or
  collapse-coarse);
* potential energy never above the initial one plus the most work the push can have done
  (kinetic energy is never negative, so this bounds the total).
Clear-cut cases also state the outcome physics dictates (stays / falls), and every preset must
reach it. The presets' own physics, unchecked (``check=None``): the self-check would repair what
these tests must see (tests/test_fidelity.py tests the check).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from ipe_ros.engine import Box, Floor, ModelConfig, QuerySpec, Scene, Table, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.scene.generators import generate_tables
from ipe_ros.engine.scene.bodies import half_heights_m
from tests.helpers import IDENTITY

G = 9.81
#: how far a resting box may sink into the floor or table, as a fraction of its smallest extent
#: (pybullet's contacts are soft: they let bodies overlap slightly while pushing them apart)
SLOP_FRACTION = 0.1


def cube_stack(name: str, size: tuple[float, float, float], count: int, *, masses=None, offset_x: float = 0.0,
               friction: float = 0.8) -> Scene:
    """``count`` boxes straight up (each shifted ``offset_x`` from the one below) on a floor at z = 0."""
    boxes = []
    for i in range(count):
        mass = None if masses is None else masses[i]
        boxes.append(Box(name=f"b{i}", extents_m=size, position_m=(i * offset_x, 0.0, size[2] * (i + 0.5)),
                         orientation_xyzw=IDENTITY, friction=friction, restitution=0.0,
                         mass_kg=mass, density_kg_m3=None if mass is not None else 500.0))
    return Scene(name=name, objects=tuple(boxes), support=Floor(friction=1.0, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -G))


def overhang(name: str, size: float, beyond: float) -> Scene:
    """A cube on a cube, its centre ``beyond`` x its width past the lower one's edge: it must tip."""
    s = (size, size, size)
    boxes = (Box(name="base", extents_m=s, position_m=(0, 0, size / 2), orientation_xyzw=IDENTITY,
                 friction=0.8, restitution=0.0, density_kg_m3=500.0),
             Box(name="top", extents_m=s, position_m=(size * (0.5 + beyond), 0, 1.5 * size), orientation_xyzw=IDENTITY,
                 friction=0.8, restitution=0.0, density_kg_m3=500.0))
    return Scene(name=name, objects=boxes, support=Floor(friction=1.0, restitution=0.0), gravity_m_s2=(0, 0, -G))


def heavy_on_light(ratio: float) -> Scene:
    light, heavy = 1.0, ratio
    size = (0.2, 0.6, 0.2)
    return cube_stack(f"heavy_on_light_{ratio:g}_to_1", size, 3, masses=[light, light, heavy])


@dataclass(frozen=True)
class Case:
    scene: Scene
    expected: str | None  # "stays", "falls", or None when physics does not say
    model: ModelConfig = ModelConfig()
    horizon_s: float | None = None


def _bumped_table() -> Scene:
    table = next(s for s in generate_tables(seed=4, configurations=1) if s.name.endswith("T1"))
    return table


CATALOGUE: dict[str, Case] = {
    "delicately_balanced_tower": Case(load_scenes("ipe_ros/data/example_tower.json")[0], "stays"),
    "heavy_on_light_10_to_1": Case(heavy_on_light(10), "stays"),
    "heavy_on_light_16_to_1": Case(heavy_on_light(16), "stays"),
    "tower_of_30_blocks": Case(cube_stack("tower30", (0.2, 0.6, 0.2), 30), "stays"),
    "blocks_of_1_cm": Case(cube_stack("cm_blocks", (0.01, 0.01, 0.01), 5), "stays"),
    "blocks_of_3_mm": Case(cube_stack("mm_blocks", (0.003, 0.003, 0.003), 5), "stays"),
    "thin_plates": Case(cube_stack("plates", (0.2, 0.2, 0.004), 8), "stays"),
    "overhang_of_1_cm_blocks": Case(overhang("cm_overhang", 0.01, 0.2), "falls"),
    "overhang_of_20_cm_blocks": Case(overhang("overhang", 0.2, 0.2), "falls"),
    "deep_interpenetration_after_noise": Case(cube_stack("noisy", (0.2, 0.6, 0.2), 10),
                                              None, ModelConfig(sigma_m=0.3, samples=4)),
    "strong_bump_off_a_walled_table": Case(_bumped_table(), None,
                                           ModelConfig(phi_m_s2=(60.0,), samples=4, force_direction_rad=0.0)),
    "long_horizon_stack": Case(cube_stack("long", (0.2, 0.6, 0.2), 6), "stays", horizon_s=10.0),
}


def _masses(scene: Scene) -> np.ndarray:
    return np.array([b.resolved_mass_kg for b in scene.dynamic_objects])


def check_trajectory(case: Case, settings, outcome, phi: float, trajectory: list) -> None:
    scene = case.scene
    boxes = scene.dynamic_objects
    extents = np.array([b.extents_m for b in boxes])
    smallest = extents.min(axis=1)
    times = np.array([f[0] for f in trajectory])
    positions = np.stack([f[1] for f in trajectory])       # (frames, boxes, 3)
    orientations = np.stack([f[2] for f in trajectory])
    assert np.all(np.isfinite(positions)) and np.all(np.isfinite(orientations))

    # speed: free fall over the horizon plus the push's delta-v (finite differences of positions)
    dt = np.diff(times)[:, None]
    speeds = np.linalg.norm(np.diff(positions, axis=0), axis=2) / dt
    push_s = case.model.push_duration_s if phi > 0 else 0.0
    bound = G * settings.horizon_s + phi * push_s
    assert speeds.max() <= bound, f"a box moved at {speeds.max():.3g} m/s, above the bound {bound:.3g}"

    # floor and table. At rest (boxes that no longer move in the last frame; a fallen box may still
    # tumble when the rollout ends) a box may sink by the contact slop only. While moving, a box may
    # overshoot into a surface by the distance it travels in one step at the speed bound (the solver
    # resolves contacts at the end of the step; every frame here is one step, fine or collapse-coarse),
    # but its centre never goes through.
    lowest = np.stack([positions[f, :, 2] - half_heights_m(scene.dynamic_objects, orientations[f]) for f in range(len(times))])
    slop = SLOP_FRACTION * smallest
    step_s = np.concatenate([[dt[0, 0]], dt[:, 0]])[:, None]  # the step that reached each frame
    overshoot = slop + bound * step_s
    resting = speeds[-1] < 0.05 * smallest  # at rest: slower than 0.05 sizes per second (`fine`'s rest threshold)
    support = scene.support
    floor_z = support.height_m if isinstance(support, Floor) else support.floor_z_m
    if floor_z is not None:
        assert np.all(positions[:, :, 2] > floor_z), "a box's centre went through the floor"
        assert np.all(lowest[-1][resting] >= floor_z - slop[resting]), \
            f"a box rests {float((floor_z - lowest[-1][resting]).max()):.3g} m in the floor"
        assert np.all(lowest >= floor_z - overshoot), f"a box sank {float((floor_z - lowest).max()):.3g} m into the floor"
    if isinstance(support, Table):
        half = extents.max(axis=1) / 2
        cx, cy = support.center_xy_m
        inside = ((np.abs(positions[:, :, 0] - cx) < support.size_m[0] / 2 - half)
                  & (np.abs(positions[:, :, 1] - cy) < support.size_m[1] / 2 - half))
        assert np.all(positions[:, :, 2][inside] > support.top_height_m), "a box's centre went through the table top"
        assert np.all(lowest[inside] >= support.top_height_m - np.broadcast_to(overshoot, lowest.shape)[inside]), \
            "a box sank into the table top"

    # energy: potential never above the initial total plus the push's work (|F| x path length)
    masses = outcome_masses(scene, case.model)
    potential = (positions[:, :, 2] * masses).sum(axis=1) * G
    during_push = times <= push_s + 1e-9
    path = np.linalg.norm(np.diff(positions[:, :, :2], axis=0), axis=2)[during_push[1:]].sum(axis=0)
    work = float((masses * phi * path).sum())
    tolerance = 1e-6 * max(1.0, abs(potential[0])) + float((masses * G * slop).sum())
    assert potential.max() <= potential[0] + work + tolerance, \
        f"energy grew by {potential.max() - potential[0]:.3g} J (push work bound {work:.3g} J)"


def outcome_masses(scene: Scene, model: ModelConfig) -> np.ndarray:
    if model.mu is None:
        return _masses(scene)
    from ipe_ros.engine.sampling.perturb import MODEL_LIGHT_DENSITY_KG_M3
    return np.array([MODEL_LIGHT_DENSITY_KG_M3 * (model.mu if b.is_heavy else 1.0) * b.volume_m3
                     for b in scene.dynamic_objects])


def assert_still_standing_at_the_horizon(case: Case, settings, query: QuerySpec, prediction) -> None:
    """A scene that stays must stand for the whole horizon, not only until early termination
    judged it at rest: simulated to the end, no box may have sunk more than a quarter of the
    fall threshold. (Without settling, `default` had the delicately balanced tower 2 cm down, 80%
    of the way to "fallen", at 2 s, and toppled it at 3 s, while `paper` keeps it within 0.1 mm.)"""
    if settings.early_stop.enabled:
        prediction = predict(case.scene,
                             Request(model=case.model, settings=settings.changed(early_stop={"enabled": False}),
                                     query=query, seed=11, check=None, budget_s=None))
    smallest = np.array([min(b.extents_m) for b in case.scene.dynamic_objects])
    allowed = 0.25 * query.fall_threshold_fraction * smallest
    for outcome in prediction.outcomes:
        for rollout in outcome.rollouts:
            assert rollout.simulated_s == pytest.approx(settings.horizon_s, abs=settings.time_step_s)  # to within a step
            sunk = outcome.initial_positions_m[:, 2] - rollout.final_positions_m[:, 2]
            worst = int(np.argmax(sunk / allowed))
            assert sunk[worst] <= allowed[worst], \
                f"box {worst} sank {sunk[worst]:.3g} m by {settings.horizon_s:g} s (allowed {allowed[worst]:.3g} m)"


@pytest.mark.parametrize("preset_name", ["default", "fine", "paper"])
@pytest.mark.parametrize("name", list(CATALOGUE))
def test_hard_case_stays_numerically_stable(name, preset_name, pool):
    case = CATALOGUE[name]
    settings = preset(preset_name)
    if case.horizon_s is not None:
        settings = settings.changed(horizon_s=case.horizon_s)
    query = QuerySpec(queries=frozenset({"fall", "bump"} if isinstance(case.scene.support, Table) else {"fall"}))
    prediction = predict(case.scene,
                         Request(model=case.model, settings=settings, query=query, seed=11, check=None, budget_s=None),
                         Context(map_fn=pool.map, record_every=1))
    assert prediction.failed_samples == 0, prediction.failure_reasons
    for outcome in prediction.outcomes:
        for rollout in outcome.rollouts:
            check_trajectory(case, settings, outcome, rollout.phi_m_s2, rollout.trajectory)
    if case.expected == "stays":
        assert prediction.fall_fraction == 0.0, prediction.object_fall_probability
        assert_still_standing_at_the_horizon(case, settings, query, prediction)
    elif case.expected == "falls":
        assert prediction.fall_fraction > 0.0


def column_with_a_gap(count: int, gap: int) -> Scene:
    """``count`` 10 cm cubes straight up with cube ``gap`` left out: the cubes above it drop 10 cm
    onto the cubes below as one stack (what removing a cube from a column asks)."""
    boxes = tuple(Box(name=f"c{i}", extents_m=(0.1, 0.1, 0.1), position_m=(0.0, 0.0, 0.1 * (i + 0.5)),
                      orientation_xyzw=IDENTITY, friction=0.6, restitution=0.0, mass_kg=1.0)
                  for i in range(count) if i != gap)
    return Scene(name=f"column_{count}_without_c{gap}", objects=boxes, support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -G))


@pytest.mark.parametrize("preset_name", ["default", "fine"])
@pytest.mark.parametrize("count, gap", [(20, 10), (10, 8)])
def test_a_stack_landing_on_a_column_leaves_the_column_standing(preset_name, count, gap, pool):
    """The cubes above a gap land on the column below it: every physics leaves the column standing
    (`paper` in 8 of 8 samples). `default` knocked it over in up to 8 of 8 samples, two ways.
    Ten cubes landing as one stack on ten: at collapse steps the solver could not carry the impact
    down the stack, and pushing the cubes out of each other made energy; those collapse steps are
    now undone. One cube landing on eight: nothing made energy, but the column, still after the
    landing, rocked ever more at collapse steps until it fell; a collapse now ends once nothing
    moves fast (config.CollapseSettings). Either way the answer is the one without collapse steps."""
    scene = column_with_a_gap(count, gap)
    model = ModelConfig(sigma_m=0.005, samples=8)
    query = QuerySpec(queries=frozenset({"fall"}))
    settings = preset(preset_name)
    prediction = predict(scene,
                         Request(model=model, settings=settings, query=query, seed=0, check=None, budget_s=None),
                         Context(map_fn=pool.map))
    assert prediction.failed_samples == 0, prediction.failure_reasons
    falls = prediction.object_fall_probability
    assert {name: p for name, p in falls.items() if int(name[1:]) < gap and p > 0} == {}
    assert all(falls[f"c{i}"] == 1.0 for i in range(gap + 1, count))  # what was above the gap dropped
    if settings.collapse.enabled:
        # a stack landing makes half the scene's energy scale at collapse steps and is undone; one cube
        # landing makes none (not even 0.1%, measured) and is ended at quiet instead
        assert (prediction.collapse_undone_rollouts > 0) == (count - gap > 2)
        without = predict(scene,
                          Request(model=model, settings=settings.changed(collapse={"step_factor": 1}), query=query,
                                  seed=0, check=None, budget_s=None),
                          Context(map_fn=pool.map))
        assert without.collapse_undone_rollouts == 0
        assert falls == without.object_fall_probability


#: the zoo's stacks 2026/0 as the family drew its masses until 2026-11-30: a 72 g box under 108-216 g ones
STACKS_2026_0_MASSES_KG = {"s0b0": 0.10268195458749249, "s0b1": 0.07209322833033603, "s0b2": 0.1077147308804724,
                           "s0b3": 0.1616678925185023, "s0b4": 0.2162796849910081, "s0b5": 0.14769166947466844}


def test_the_collapse_steps_do_not_throw_a_small_box_out_from_under_larger_ones(pool):
    """The zoo's stacks 2026/0: six boxes that collapse in every sample, the second a 3 cm box under
    larger, up to 3x heavier ones. At collapse steps that let a body travel half the smallest extent
    per step, a falling box lands deep in what it hits and the solver's push-out throws the small box
    aside: `default` knocked it out in 31-44% of samples, `paper` in 9-16%, `default` without collapse
    steps in 13-16%. With the collapse steps' own travel limit (a quarter: config.CollapseSettings)
    the collapse steps answer as the fine steps do. So does their own solver residual
    (``collapse.residual_threshold``): solved only to the fine steps' looser one, the landings throw the
    small box out more often again (25% of the samples against 9%). The masses are pinned as the family
    drew them then (within 3x in any order; it now holds each box to 3x the lightest one under it)."""
    from ipe_ros.engine.scene.zoo import zoo_scene, zoo_sigma_m

    drawn = zoo_scene("stacks", 2026, 0)
    scene = dataclasses.replace(drawn, objects=tuple(dataclasses.replace(b, mass_kg=STACKS_2026_0_MASSES_KG[b.name])
                                                     for b in drawn.objects))
    model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=32)
    query = QuerySpec(queries=frozenset({"fall"}))
    settings = preset("default")
    coarse = predict(scene, Request(model=model, settings=settings, query=query, seed=0, check=None, budget_s=None),
                     Context(map_fn=pool.map))
    fine = predict(scene,
                   Request(model=model, settings=settings.changed(collapse={"step_factor": 1}), query=query, seed=0,
                           check=None, budget_s=None),
                   Context(map_fn=pool.map))
    assert abs(coarse.object_fall_probability["s0b1"] - fine.object_fall_probability["s0b1"]) <= 0.1
    loose = predict(scene,
                    Request(model=model, settings=settings.changed(collapse={"max_travel_fraction": 0.5}),
                            query=query, seed=0, check=None, budget_s=None),
                    Context(map_fn=pool.map))
    assert loose.object_fall_probability["s0b1"] - fine.object_fall_probability["s0b1"] > 0.15  # the case bites
    loosely_solved = predict(scene,
                             Request(model=model, settings=settings.changed(collapse={"residual_threshold": None}),
                                     query=query, seed=0, check=None, budget_s=None),
                             Context(map_fn=pool.map))
    assert loosely_solved.object_fall_probability["s0b1"] - fine.object_fall_probability["s0b1"] > 0.1
