"""One sample of every variant of a question: the shared draw (the s-th child seed's noisy,
separated scene), then one rollout per action, an action's own randomness on a second stream."""

from __future__ import annotations

import dataclasses
import math
import time
import zlib
from dataclasses import dataclass

import numpy as np

from .. import simulation
from ..errors import PhysicsError
from ..sampling.perturb import draw_sample, draw_sample_inputs, with_drawn_properties
from ..sampling.rollout import (SampleOutcome, SampleTask, failed, guarded, kept, rollout_result, separated_world,
                               simulate_pushes, simulate_sample)
from ..scene.bodies import Scene
from ..scene.shapes import rotation_matrix
from .kinds import Action, Place, Push, Remove, label_of


# -- one sample of every variant ----------------------------------------------------------------------
@dataclass(frozen=True)
class VariantTask(SampleTask):
    """Sample ``index`` of every variant: a prediction's sample (the same seed, scene, settings,
    queries, budget and recording), whose shared draw is then simulated once per action."""

    actions: tuple[Action, ...] = ()
    #: per action, the dynamic objects worth simulating (None: all); the rest cannot be reached
    regions: tuple[frozenset[str] | None, ...] | None = None


def lost(task: VariantTask, reason: str) -> list[SampleOutcome]:
    """Every variant of a sample whose worker was lost twice (``MonteCarlo``'s ``on_lost``)."""
    return [failed(task, f"WorkerLost: {reason}", worker_lost=True) for _ in task.actions]


def skipped(index: int, why: str) -> SampleOutcome:
    """A variant not run in sample ``index`` (``why``: "the scene fell as it is", "decided")."""
    return SampleOutcome(index=index, ok=False, error=f"skipped: {why}", push_direction_rad=float("nan"),
                         initial_positions_m=None, initial_orientations_xyzw=None, skipped=True)


def _action_rng(task: VariantTask, action: Action) -> np.random.Generator:
    """The second stream: this action's own randomness, independent of the shared draw and keyed
    by what the action is (not where it stands in the list), so asking it among other variants
    gives the same answer."""
    key = zlib.crc32(label_of(action).encode("utf-8", "backslashreplace"))
    return np.random.default_rng(np.random.SeedSequence(task.seed.entropy, spawn_key=task.seed.spawn_key + (1, key)))


def push_velocities(push: Push, rng: np.random.Generator, centre_m: np.ndarray, orientation: np.ndarray,
                    inertia_kg_m2: np.ndarray, mass_kg: float) -> tuple[tuple, tuple]:
    v = np.asarray(push.velocity_m_s, float)
    speed, angle = float(np.linalg.norm(v)), math.atan2(v[1], v[0])
    if push.direction_sigma_rad:
        angle += push.direction_sigma_rad * rng.standard_normal()
    if push.speed_sigma_fraction:
        speed *= max(0.0, 1 + push.speed_sigma_fraction * rng.standard_normal())
    v = np.array([speed * math.cos(angle), speed * math.sin(angle), 0.0])
    if push.point_m is None:
        return tuple(v), (0.0, 0.0, 0.0)
    # an impulse J = m v at r from the centre of mass also spins the body: w = I^-1 (r x J)
    r = np.asarray(push.point_m, float) - centre_m
    rot = rotation_matrix(orientation)
    inertia_world = rot @ np.diag(inertia_kg_m2) @ rot.T
    spin = np.linalg.solve(inertia_world, np.cross(r, mass_kg * v))
    return tuple(v), tuple(spin)


def _simulate_variant(task: VariantTask, scene: Scene, positions, orientations, masses, push_direction: float,
                      separate: bool) -> tuple[np.ndarray, np.ndarray, float, simulation.RolloutEnd]:
    """Build ``scene`` at the given state, optionally separate it, simulate (phi values in turn: the
    last one's end is returned; actions are asked with one phi in practice)."""
    world = simulation.build_world(scene, positions, masses, task.settings, orientations_xyzw=orientations)
    if separate:
        simulation.depenetrate(world, task.settings)
    initial, initial_orn = simulation.read_poses(world)
    ends = simulate_pushes(scene, task.model, task.settings, task.query, world, initial, initial_orn, masses,
                           push_direction, record_every=task.record_every, deadline_unix_s=task.deadline_unix_s)
    phi, end = ends[-1]
    return initial, initial_orn, phi, end


def run_variants(task: VariantTask) -> list[SampleOutcome]:
    """Sample ``task.index`` of every variant (one outcome per action, its rollout's arrays in the
    variant's own objects, ``SampleOutcome.names``); never raises for physics trouble (a failed
    variant carries its error, the others run). The scene as it is (action None, every object in
    reach) simulates on in the separated world, exactly as a prediction's sample does
    (``rollout.simulate_sample``); the other variants start from its separated poses."""
    if task.deadline_unix_s is not None and time.time() >= task.deadline_unix_s:
        return [failed(task, "BudgetExceeded: not started", budget_stopped=True) for _ in task.actions]
    scene, inputs = draw_sample(task.scene, task.model, task.seed)
    sample = task if scene is task.scene else dataclasses.replace(task, scene=scene)  # its drawn properties
    try:
        world = separated_world(scene, task.settings, inputs)
        shared, shared_orn = simulation.read_poses(world)
    except PhysicsError as exc:
        return [failed(sample, f"PhysicsError: {exc}", push_direction_rad=inputs.push_direction_rad)
                for _ in task.actions]
    regions = task.regions or (None,) * len(task.actions)
    out: dict[int, SampleOutcome] = {}
    # the scene as it is first: a process holds one world at a time, and the next variant's replaces it
    for v, (action, region) in enumerate(zip(task.actions, regions)):
        if action is None and region is None:  # a prediction's sample, simulated on in the separated world
            outcome = guarded(sample, inputs.push_direction_rad, lambda: simulate_sample(sample, inputs, world))
            names = tuple(b.name for b in scene.dynamic_objects)
            out[v] = dataclasses.replace(outcome, names=names) if outcome.ok else outcome
            break
    for v, (action, region) in enumerate(zip(task.actions, regions)):
        if v not in out:
            out[v] = guarded(sample, inputs.push_direction_rad,
                             lambda: _one_variant(sample, action, shared, shared_orn, inputs, region))
    return [_refined(task, scene, v, out[v]) for v in range(len(task.actions))]


def _refined(task: VariantTask, scene: Scene, v: int, outcome: SampleOutcome) -> SampleOutcome:
    """Variant ``v``'s outcome as a prediction's sample is kept (``rollout.kept``: its rerun at the
    reference beside it, or in plain rigid bodies in its place), a rerun being the variant alone:
    the very task the self-check would rerun (``task`` as given, so the rerun draws the same
    properties; ``scene`` the sample's, with them drawn, for judging its health)."""

    def alone(settings) -> SampleOutcome:
        (rerun,) = run_variants(dataclasses.replace(task, actions=(task.actions[v],),
                                                    regions=None if task.regions is None else (task.regions[v],))
                                .at(settings))
        return rerun

    return kept(dataclasses.replace(task, scene=scene), outcome, alone)


def _one_variant(task: VariantTask, action: Action, shared, shared_orn, inputs,
                 region: frozenset[str] | None) -> SampleOutcome:
    scene = task.scene
    bodies = scene.dynamic_objects
    positions, orientations, masses = shared, shared_orn, inputs.masses_kg
    if region is not None:  # objects the action cannot reach are left out of the simulation
        keep = np.array([b.name in region for b in bodies])
        scene = dataclasses.replace(scene, objects=tuple(b for b in scene.objects if b.static or b.name in region))
        bodies = scene.dynamic_objects
        positions, orientations, masses = positions[keep], orientations[keep], masses[keep]
        shared, shared_orn = positions, orientations
    separate = False
    properties = inputs.properties
    if isinstance(action, Remove):
        keep = np.array([b.name not in action.names for b in bodies])
        scene = dataclasses.replace(scene, objects=tuple(b for b in scene.objects if b.name not in action.names))
        positions, orientations, masses = shared[keep], shared_orn[keep], masses[keep]
    elif isinstance(action, Place):
        rng = _action_rng(task, action)
        new = action.body
        added = dataclasses.replace(scene, objects=(new,))
        # the new object's own noise on the second stream, its properties on their own as every object's
        added, drawn = with_drawn_properties(added, task.model, task.seed, draw_sample_inputs(added, task.model, rng),
                                             owners=frozenset({new.name}))
        new = added.objects[0]
        properties += drawn.properties
        scene = dataclasses.replace(scene, objects=scene.objects + (new,))
        positions = np.vstack([shared, drawn.positions_m])
        orientations = np.vstack([shared_orn, drawn.orientations_xyzw])
        masses = np.concatenate([masses, drawn.masses_kg])
        separate = True  # the new object may overlap what is there
    elif isinstance(action, Push):
        i = next(k for k, b in enumerate(bodies) if b.name == action.name)
        world = simulation.build_world(scene, shared, masses, task.settings, orientations_xyzw=shared_orn)
        inertia = world.inertia_kg_m2[i]
        velocity, spin = push_velocities(action, _action_rng(task, action), shared[i], shared_orn[i], inertia,
                                          float(masses[i]))
        pushed = dataclasses.replace(bodies[i], linear_velocity_m_s=velocity, angular_velocity_rad_s=spin)
        scene = dataclasses.replace(scene, objects=tuple(pushed if b.name == action.name else b
                                                         for b in scene.objects))
    initial, initial_orn, phi, end = _simulate_variant(task, scene, positions, orientations, masses,
                                                       inputs.push_direction_rad, separate)
    result = rollout_result(scene, task.query, initial, initial_orn, phi, end)  # the queries a prediction reads
    return SampleOutcome(index=task.index, ok=True, error=None, push_direction_rad=inputs.push_direction_rad,
                         initial_positions_m=initial, initial_orientations_xyzw=initial_orn, rollouts=(result,),
                         names=tuple(b.name for b in scene.dynamic_objects), properties=properties)
