"""Questions about a robot's own next action: remove, place or push an object, and what follows.

Every question is a set of *variants* of one scene (the scene as it is, without object i, with a
new object here, with object j pushed) answered by the same Monte Carlo IPE. Variants share their
random numbers: sample s of every variant starts from the same noisy, separated scene (drawn and
de-penetrated once, from the s-th child seed), so the difference between "remove block 3" and
"remove block 5" is the removal's, not Monte Carlo noise. A variant that adds something draws the
added randomness (where the new object lands, how hard the push is) from a second stream of the same
seed, leaving the shared draw untouched.

``ask`` runs variants; ``remove``, ``support_graph``, ``clear_order``, ``place``, ``best_place`` and
``push`` are the questions built on it. A removal that cannot change anything (nothing else is
within the removed objects' reach, ``groups``) is answered from the scene's own samples without
simulating, and says so (``simulated: False``). Each variant's answer is given twice: over all
samples, and over the samples in which the scene as it is stands (``given_stands``), so that what
an action makes fall is not confused with what falls anyway.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import traceback
import zlib
from dataclasses import dataclass
from typing import Callable, Union

import numpy as np

from . import queries, simulation
from .config import ModelConfig, QuerySpec, SimSettings, SolverSettings
from . import limits
from .errors import BudgetExceeded, ConfigError, PhysicsError, shown
from .decide import Ranking, SafeBelow, Sequential, Supports, Tally
from .estimate import wilson_interval, circular_mean
from .perturb import draw_sample_inputs, is_deterministic, position_sigmas_m
from .query.contact import parse_pair
from .rollout import SampleTask, _decided_heights, collapse_heights, separated_world, watches_for
from .sampler import MapFn, check_budget, rollout_cost
from .scene import Body, Scene, Table, lowest_z_m, validate_body, validate_scene
from .shapes import BoxShape, rotation_matrix

#: P(anything else falls) below this makes an object safe to remove now.
DEFAULT_SAFE_BELOW = 0.05
#: Removing i makes j fall with at least this probability: i supports j.
DEFAULT_SUPPORT_THRESHOLD = 0.5


# -- actions ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Remove:
    """Take these objects away at t = 0 (lifted straight up: deleted before anything moves)."""

    names: tuple[str, ...]

    @property
    def label(self) -> str:
        return "remove/" + "+".join(self.names)


@dataclass(frozen=True)
class Place:
    """Add ``body`` at its pose; its own ``position_sigma_m`` / ``yaw_sigma_rad`` (else the model's
    sigma) say how precisely the robot puts it there."""

    body: Body

    @property
    def label(self) -> str:
        return f"place/{self.body.name}@{','.join(f'{v:.3f}' for v in self.body.position_m)}"


@dataclass(frozen=True)
class Push:
    """Push one object horizontally: at t = 0 it moves at ``velocity_m_s`` (the velocity the push
    gives the point it is pushed at; ``point_m`` in the scene frame, None: its centre of mass, no
    spin). ``direction_sigma_rad`` and ``speed_sigma_fraction``: the push's own uncertainty."""

    name: str
    velocity_m_s: tuple[float, float, float]
    point_m: tuple[float, float, float] | None = None
    direction_sigma_rad: float = 0.0
    speed_sigma_fraction: float = 0.0

    @property
    def label(self) -> str:
        return f"push/{self.name}"


Action = Union[Remove, Place, Push, None]  # None: the scene as it is


def _label(action: Action) -> str:
    return "as_is" if action is None else action.label


def _check_action(scene: Scene, action: Action, path: str) -> None:
    names = {b.name for b in scene.objects}
    if isinstance(action, Remove):
        if not action.names:
            raise ConfigError(f"{path}.names", "name at least one object to remove")
        for name in action.names:
            if name not in names:
                raise ConfigError(f"{path}.names", f"no object named {name!r} in {scene.name!r}")
            if next(b for b in scene.objects if b.name == name).static:
                raise ConfigError(f"{path}.names", f"{name!r} is static (fixed geometry) and cannot be removed")
        if not [b for b in scene.dynamic_objects if b.name not in action.names]:
            raise ConfigError(f"{path}.names", "removing these leaves nothing that could fall")
    elif isinstance(action, Place):
        if action.body.name in names:
            raise ConfigError(f"{path}.body.name", f"{action.body.name!r} is already in the scene; give the new object "
                                                   "a name of its own")
        if action.body.static:
            raise ConfigError(f"{path}.body.static", "a placed object must be dynamic")
        validate_scene(dataclasses.replace(scene, objects=scene.objects + (action.body,)))
    elif isinstance(action, Push):
        if action.name not in {b.name for b in scene.dynamic_objects}:
            raise ConfigError(f"{path}.name", f"no dynamic object named {action.name!r} in {scene.name!r}")
        v = np.asarray(action.velocity_m_s, float)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or abs(v[2]) > 0 or not np.any(v):
            raise ConfigError(f"{path}.velocity_m_s", f"must be a finite horizontal velocity (vz = 0), not zero, "
                                                      f"got {list(action.velocity_m_s)}")
        if np.linalg.norm(v) > 100:
            raise ConfigError(f"{path}.velocity_m_s", "a push faster than 100 m/s is a projectile, not a push")
        if action.point_m is not None:
            _check_push_point(scene, action, f"{path}.point_m")
        if not (0 <= action.direction_sigma_rad <= math.pi) or not (0 <= action.speed_sigma_fraction <= 1):
            raise ConfigError(f"{path}", "direction_sigma_rad must be in [0, pi] and speed_sigma_fraction in [0, 1]")
    elif action is not None:
        raise ConfigError(path, f"not an action: {type(action).__name__}")


def _check_push_point(scene: Scene, push: Push, path: str) -> None:
    """The point pushed lies on the object (within its bounding sphere, 1 mm of slack), and the spin
    the push implies there stays within what a scene may start with (limits.MAX_SPIN_RAD_S)."""
    point = np.asarray(push.point_m, float)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ConfigError(path, "must be 3 finite numbers (metres, scene frame) or null")
    i, body = next((i, b) for i, b in enumerate(scene.dynamic_objects) if b.name == push.name)
    centre = np.asarray(body.centre_of_mass_m, float)
    reach = 0.5 * float(np.linalg.norm(body.extents_m)) + 1e-3
    distance = float(np.linalg.norm(point - centre))
    if distance > reach:
        raise ConfigError(path, f"{list(push.point_m)} is {distance:.3g} m from the centre of mass of {push.name!r}, "
                                f"outside its reach of {reach:.3g} m; push a point on the object")
    inertia = _geometry_world(scene).inertia_kg_m2[i]  # pybullet's own, as the rollout will use
    _, spin = _push_velocities(push, np.random.default_rng(0), centre, np.asarray(body.orientation_xyzw, float),
                               inertia, body.resolved_mass_kg)
    worst = float(np.linalg.norm(spin)) * (1 + push.speed_sigma_fraction * 4)  # the push's own noise, to 4 SD
    if worst > limits.MAX_SPIN_RAD_S:
        raise ConfigError(path, f"pushed there at this speed {push.name!r} would spin at up to {worst:.4g} rad/s, more "
                                f"than the {limits.MAX_SPIN_RAD_S:g} rad/s a scene may start with; push nearer its "
                                "centre of mass or slower")


# -- one sample of every variant ----------------------------------------------------------------------
@dataclass(frozen=True)
class VariantTask:
    """Sample ``index`` of every variant: the shared draw, then one rollout per action."""

    scene: Scene
    model: ModelConfig
    settings: SimSettings
    query: QuerySpec
    index: int
    seed: np.random.SeedSequence
    actions: tuple[Action, ...]
    deadline_unix_s: float | None = None
    #: per action, the dynamic objects worth simulating (None: all); the rest cannot be reached
    regions: tuple[frozenset[str] | None, ...] | None = None
    record_every: int = 0  # record trajectories every N ticks (rerun), 0: none


@dataclass(frozen=True)
class VariantResult:
    """One variant of one sample: which objects fell (names in the variant's order), the direction."""

    names: tuple[str, ...]
    fallen: np.ndarray | None
    direction_rad: float | None
    error: str | None = None
    budget_stopped: bool = False
    worker_lost: bool = False  # its worker process died twice
    trajectory: list | None = None  # (t, positions, orientations) frames when recorded
    fell_off: np.ndarray | None = None  # ended off the table (asked with fell_off)
    skipped: bool = False  # not run: the scene fell as it is, or the variant was already decided
    contact: dict | None = None  # the contact query's first-contact times, by pair (asked with contact)


def _action_rng(task: VariantTask, action: Action) -> np.random.Generator:
    """The second stream: this action's own randomness, independent of the shared draw and keyed
    by what the action is (not where it stands in the list), so asking it among other variants
    gives the same answer."""
    key = zlib.crc32(_label(action).encode("utf-8", "backslashreplace"))
    return np.random.default_rng(np.random.SeedSequence(task.seed.entropy, spawn_key=task.seed.spawn_key + (1, key)))


def _push_velocities(push: Push, rng: np.random.Generator, centre_m: np.ndarray, orientation: np.ndarray,
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
                      separate: bool) -> tuple[np.ndarray, np.ndarray, simulation.RolloutEnd]:
    """Build ``scene`` at the given state, optionally separate it, simulate (phi values in turn: the
    last one's end is returned; actions are asked with one phi in practice)."""
    sub = SampleTask(scene=scene, model=task.model, settings=task.settings, query=task.query, index=task.index,
                     seed=task.seed, deadline_unix_s=task.deadline_unix_s)
    world = simulation.build_world(scene, positions, masses, task.settings, orientations_xyzw=orientations)
    if separate:
        simulation.depenetrate(world, task.settings)
    initial, initial_orn = simulation.read_poses(world)
    decided = _decided_heights(sub, initial)
    collapse_below = collapse_heights(sub, initial)
    end = None
    for i, phi in enumerate(task.model.phi_m_s2):
        if i > 0:
            world = simulation.build_world(scene, initial, masses, task.settings, orientations_xyzw=initial_orn)
        watches, end_when_watched = watches_for(scene, task.query, world)
        end = simulation.simulate(world, scene, task.settings, simulation.Push(phi, push_direction,
                                                                              task.model.push_duration_s),
                                  decided=decided, collapse_below_z_m=collapse_below,
                                  deadline_unix_s=task.deadline_unix_s, record_every=task.record_every,
                                  watches=watches, end_when_watched=end_when_watched)
    return initial, initial_orn, end


def run_variants(task: VariantTask) -> list[VariantResult]:
    """Sample ``task.index`` of every variant; never raises for physics trouble (a failed variant
    carries its error)."""
    names = tuple(b.name for b in task.scene.dynamic_objects)
    if task.deadline_unix_s is not None and time.time() >= task.deadline_unix_s:
        return [VariantResult(names, None, None, "BudgetExceeded: not started", True) for _ in task.actions]
    rng = np.random.default_rng(task.seed)
    inputs = draw_sample_inputs(task.scene, task.model, rng)
    try:
        shared, shared_orn = simulation.read_poses(separated_world(task.scene, task.settings, inputs))
    except PhysicsError as exc:
        return [VariantResult(names, None, None, f"PhysicsError: {exc}") for _ in task.actions]
    return [_run_one(task, action, v, shared, shared_orn, inputs, names) for v, action in enumerate(task.actions)]


def _run_one(task: VariantTask, action: Action, v: int, shared, shared_orn, inputs, names) -> VariantResult:
    """One variant of the sample; its physics trouble is its own result, never the others'."""
    region = None if task.regions is None else task.regions[v]
    try:
        return _one_variant(task, action, shared, shared_orn, inputs, region)
    except BudgetExceeded as exc:
        return VariantResult(names, None, None, f"BudgetExceeded: {exc}", True)
    except PhysicsError as exc:
        return VariantResult(names, None, None, f"PhysicsError: {exc}")
    except Exception as exc:  # noqa: BLE001 - one variant's trouble must not end the others
        return VariantResult(names, None, None, traceback.format_exception_only(type(exc), exc)[-1].strip())


def _one_variant(task: VariantTask, action: Action, shared, shared_orn, inputs,
                 region: frozenset[str] | None) -> VariantResult:
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
    if isinstance(action, Remove):
        keep = np.array([b.name not in action.names for b in bodies])
        scene = dataclasses.replace(scene, objects=tuple(b for b in scene.objects if b.name not in action.names))
        positions, orientations, masses = shared[keep], shared_orn[keep], masses[keep]
    elif isinstance(action, Place):
        rng = _action_rng(task, action)
        new = action.body
        added = dataclasses.replace(scene, objects=(new,))
        drawn = draw_sample_inputs(added, task.model, rng)  # the new object's own noise, second stream
        scene = dataclasses.replace(scene, objects=scene.objects + (new,))
        positions = np.vstack([shared, drawn.positions_m])
        orientations = np.vstack([shared_orn, drawn.orientations_xyzw])
        masses = np.concatenate([masses, drawn.masses_kg])
        separate = True  # the new object may overlap what is there
    elif isinstance(action, Push):
        i = next(k for k, b in enumerate(bodies) if b.name == action.name)
        world = simulation.build_world(scene, shared, masses, task.settings, orientations_xyzw=shared_orn)
        inertia = world.inertia_kg_m2[i]
        velocity, spin = _push_velocities(action, _action_rng(task, action), shared[i], shared_orn[i], inertia,
                                          float(masses[i]))
        pushed = dataclasses.replace(bodies[i], linear_velocity_m_s=velocity, angular_velocity_rad_s=spin)
        scene = dataclasses.replace(scene, objects=tuple(pushed if b.name == action.name else b
                                                         for b in scene.objects))
    initial, _, end = _simulate_variant(task, scene, positions, orientations, masses, inputs.push_direction_rad,
                                        separate)
    variant_bodies = scene.dynamic_objects
    smallest = np.array([b.smallest_extent_m for b in variant_bodies])
    fallen = queries.fallen_mask(initial, end.positions_m, smallest, task.query.fall_threshold_fraction)
    direction = queries.fall_direction_rad(initial, end.positions_m, fallen) if task.query.wants("direction") else None
    fell_off = None
    if task.query.wants("bump"):  # started above the table top, ended below it: beside or under the table
        top = scene.support.top_height_m
        fell_off = (initial[:, 2] >= top) & queries.fell_off_mask(end.positions_m, top)
    contact = end.events["contact"]["first_s"] if task.query.wants("contact") else None
    return VariantResult(tuple(b.name for b in variant_bodies), fallen, direction, trajectory=end.trajectory,
                         fell_off=fell_off, contact=contact)


# -- the answers ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VariantAnswer:
    """What one variant of a question does to the scene.

    any_fall_probability: P(at least one object falls), objects the action removed not counted;
        with its 95% Wilson interval.
    object_fall_probability: per remaining (or added) object.
    simulated: False when the answer was read from the scene's own samples because the action
        cannot change anything (a removal that nothing rests on).
    samples / failed_samples: samples used / samples whose rollout failed (budget cuts are neither).
    """

    label: str
    action: Action
    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    object_fall_probability: dict[str, float]
    direction_rad: float | None
    samples: int
    failed_samples: int
    simulated: bool = True
    not_simulated: tuple[str, ...] = ()  # objects the action cannot reach, left out of its rollouts
    #: per object, P(it falls with the action and would not have without): sample s of the variant
    #: against sample s of the scene as is (common random numbers make this pairing meaningful)
    caused_fall_probability: dict[str, float] | None = None
    #: the same answer over only the samples in which the scene as it is stands (nothing falls without
    #: the action): what the action does, apart from what falls anyway; None without an "as is" variant
    given_stands: "GivenStands | None" = None
    #: per object, P(it ends off the table: its centre below the top); asked with fell_off
    fell_off_probability: dict[str, float] | None = None
    any_fell_off_probability: float | None = None
    #: answered sequentially (``decide.Sequential``): what the rule decided ("safe", "unsafe",
    #: "ranked out", "best"; None: undecided) and why sampling stopped ("decided", "cap", "budget");
    #: the variant was then simulated only in samples where the scene as it is stands, so its
    #: probabilities are over those (equal to ``given_stands``)
    decision: str | None = None
    stopped_by: str | None = None
    samples_drawn: int | None = None  # samples 0..n-1 were drawn for it (it ran in those that stood)
    #: asked with contact pairs: per pair "A:B", P(they touch within the horizon), its 95% interval,
    #: and the median first-contact time over the samples in which they touch (engine/query/contact.py)
    contact_probability: dict[str, float] | None = None
    contact_probability_ci95: dict[str, list[float]] | None = None
    contact_time_s: dict[str, float | None] | None = None

    def to_dict(self) -> dict:
        off = {} if self.fell_off_probability is None else {
            "fell_off_probability": self.fell_off_probability, "any_fell_off_probability": self.any_fell_off_probability}
        return {"label": self.label, "any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "object_fall_probability": self.object_fall_probability, "direction_rad": self.direction_rad,
                "samples": self.samples, "failed_samples": self.failed_samples, "simulated": self.simulated,
                "not_simulated": list(self.not_simulated), "caused_fall_probability": self.caused_fall_probability,
                "given_stands": None if self.given_stands is None else self.given_stands.to_dict(), **off,
                **({} if self.stopped_by is None else {"decision": self.decision, "stopped_by": self.stopped_by,
                                                       "samples_drawn": self.samples_drawn}),
                **({} if self.contact_probability is None else {
                    "contact_probability": self.contact_probability,
                    "contact_probability_ci95": self.contact_probability_ci95, "contact_time_s": self.contact_time_s})}


@dataclass(frozen=True)
class GivenStands:
    """A variant's answer conditioned on the scene standing as it is: over the ``samples`` samples in
    which nothing fell without the action (common random numbers pair sample s of every variant),
    P(anything falls with the action) with its 95% Wilson interval, and per object. None values when
    no sample stood (the scene falls by itself whatever is done)."""

    samples: int
    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    object_fall_probability: dict[str, float]

    def to_dict(self) -> dict:
        return {"samples": self.samples, "any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "object_fall_probability": self.object_fall_probability}


def _listed(interval: tuple[float, float] | None) -> list[float] | None:
    """An interval as JSON writes it."""
    return None if interval is None else list(interval)


def _draws_noise(scene: Scene, action: Action, model: ModelConfig) -> bool:
    """The action has randomness of its own: a push's uncertainty, a placed object's noise."""
    if isinstance(action, Push):
        return bool(action.direction_sigma_rad or action.speed_sigma_fraction)
    if isinstance(action, Place):
        return not is_deterministic(dataclasses.replace(scene, objects=(action.body,)), model)
    return False


def _aggregate(label: str, action: Action, results: list[VariantResult], simulated: bool = True, *,
               deterministic: bool = False) -> VariantAnswer:
    """``deterministic``: nothing was drawn, so the one sample's answer is exact (a point, not an interval)."""
    ok = [r for r in results if r.error is None]
    failed = [r for r in results if r.error is not None and not r.budget_stopped and not r.skipped]
    if not ok:
        return VariantAnswer(label, action, None, None, {}, None, 0, len(failed), simulated)
    names = ok[0].names
    fallen = np.array([r.fallen for r in ok], bool)
    anything = float(fallen.any(axis=1).mean())
    directions = np.array([r.direction_rad for r in ok if r.direction_rad is not None])
    interval = (anything, anything) if deterministic else wilson_interval(anything, len(ok))
    off = {}
    if ok[0].fell_off is not None:
        fell_off = np.array([r.fell_off for r in ok], bool)
        off = dict(fell_off_probability={n: float(p) for n, p in zip(names, fell_off.mean(axis=0))},
                   any_fell_off_probability=float(fell_off.any(axis=1).mean()))
    if ok[0].contact is not None:
        off.update(_contact_answer(ok, deterministic))
    return VariantAnswer(label, action, anything, interval,
                         {n: float(p) for n, p in zip(names, fallen.mean(axis=0))},
                         circular_mean(directions), len(ok), len(failed), simulated, **off)


def _contact_answer(ok: list[VariantResult], deterministic: bool) -> dict:
    probability, interval, time_s = {}, {}, {}
    for key in ok[0].contact:
        times = [r.contact[key] for r in ok]
        touched = [t for t in times if t is not None]
        p = len(touched) / len(ok)
        probability[key] = p
        interval[key] = [p, p] if deterministic else list(wilson_interval(p, len(ok)))
        time_s[key] = float(np.median(touched)) if touched else None
    return dict(contact_probability=probability, contact_probability_ci95=interval, contact_time_s=time_s)


def _stood(alone: VariantResult) -> bool:
    """The scene as it is ran without failing and nothing in it fell."""
    return alone.error is None and not bool(np.any(alone.fallen))


def _aggregate_given(results: list[VariantResult], *, deterministic: bool) -> GivenStands:
    """A variant's results over the samples in which the scene stands as it is."""
    answer = _aggregate("", None, results, deterministic=deterministic)
    return GivenStands(answer.samples, answer.any_fall_probability, answer.any_fall_probability_ci95,
                       answer.object_fall_probability)


#: A world built only to look at the scene's geometry (contacts, rays, bounds): never stepped.
_GEOMETRY_SETTINGS = SimSettings(name="geometry", time_step_s=1 / 240, horizon_s=1.0,
                                 solver=SolverSettings(iterations=10))


def _geometry_world(scene: Scene):
    bodies = scene.dynamic_objects
    return simulation.build_world(scene, np.array([b.centre_of_mass_m for b in bodies]),
                                  np.array([max(b.resolved_mass_kg, 1e-6) for b in bodies]), _GEOMETRY_SETTINGS)


@dataclass(frozen=True)
class Contacts:
    """Which dynamic objects of a scene touch (within a margin), and their bounding boxes: one
    geometry pass that ``resting_on`` and ``groups`` both read."""

    bodies: tuple[Body, ...]
    pairs: tuple[tuple[int, int], ...]  # indices into bodies
    boxes: tuple[np.ndarray, ...]  # (2, 3) axis-aligned bounds per body


def contacts(scene: Scene, margin_m: float = 0.0) -> Contacts:
    bodies = scene.dynamic_objects
    world = _geometry_world(scene)
    p = simulation.world.pybullet()
    reach = margin_m + 0.01 * world.scale_m
    pairs = tuple((i, j) for (i, a), (j, b) in itertools.combinations(enumerate(world.dynamic_ids), 2)
                  if p.getClosestPoints(a, b, reach, physicsClientId=world.client))
    boxes = tuple(np.array(p.getAABB(h, physicsClientId=world.client)) for h in world.dynamic_ids)
    return Contacts(bodies, pairs, boxes)


def resting_on(scene: Scene, margin_m: float = 0.0, touching: Contacts | None = None) -> dict[str, set[str]]:
    """name -> the dynamic objects that may rest or lean on it, in the scene as given (no noise):
    they touch it (within ``margin_m``) and their centre of mass is above its lowest point (a plank
    leaning on a post's side counts). What a clearing order takes away before its target.
    ``touching``: the scene's contacts, when already found."""
    touching = touching or contacts(scene, margin_m)
    bodies = touching.bodies
    out: dict[str, set[str]] = {b.name: set() for b in bodies}
    for i, j in touching.pairs:
        body_a, body_b = bodies[i], bodies[j]
        if body_a.centre_of_mass_m[2] > lowest_z_m(body_b):
            out[body_b.name].add(body_a.name)
        if body_b.centre_of_mass_m[2] > lowest_z_m(body_a):
            out[body_a.name].add(body_b.name)
    return out


def groups(scene: Scene, margin_m: float = 0.0, touching: Contacts | None = None) -> list[frozenset[str]]:
    """The dynamic objects in groups that cannot affect each other within a rollout: objects that
    touch (within ``margin_m``) are one group, and groups that anything of one could reach the other
    (``reach_m``) are merged. A scene with something moving at t = 0 is one group."""
    touching = touching or contacts(scene, margin_m)
    bodies = touching.bodies
    names = [b.name for b in bodies]
    if any(b.moving for b in bodies):
        return [frozenset(names)]
    parent = list(range(len(names)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in touching.pairs:
        parent[root(i)] = root(j)
    boxes = touching.boxes
    while True:
        members: dict[int, list[int]] = {}
        for i in range(len(names)):
            members.setdefault(root(i), []).append(i)
        bounds = {r: (np.min([boxes[i][0] for i in m], axis=0), np.max([boxes[i][1] for i in m], axis=0))
                  for r, m in members.items()}
        reach = {r: reach_m(scene, [bodies[i] for i in m], bounds[r]) for r, m in members.items()}
        for r, q in itertools.combinations(bounds, 2):
            (lo_r, hi_r), (lo_q, hi_q) = bounds[r], bounds[q]
            gap = np.maximum(0.0, np.maximum(lo_r[:2] - hi_q[:2], lo_q[:2] - hi_r[:2]))
            if float(np.linalg.norm(gap)) < max(reach[r], reach[q]) + margin_m:
                parent[root(r)] = root(q)
                break
        else:
            return [frozenset(names[i] for i in m) for m in members.values()]


def reach_m(scene: Scene, bodies: list[Body], bounds: tuple[np.ndarray, np.ndarray]) -> float:
    """How far beyond its bounding box anything of a group of touching objects, starting at rest,
    can get: the group toppling about its base edge (its top corner sweeps the box's diagonal), then
    what falls sliding on with at most the speed of a free fall from the group's top (v^2 / 2 mu g
    = H / mu) and bouncing (restitution r: 4 r H / (1 - r^2) over all bounces). A body that can roll
    (any shape but a box) or bounce without loss has no bound (inf): such groups join every other.
    """
    if any(not isinstance(b.shape, BoxShape) for b in bodies):
        return math.inf
    support = scene.support
    lowest = support.top_m if not isinstance(support, Table) or support.floor_z_m is None else support.floor_z_m
    drop = max(0.0, float(bounds[1][2]) - lowest)
    width = float(np.linalg.norm(bounds[1][:2] - bounds[0][:2]))
    # pybullet multiplies the two surfaces' friction and restitution coefficients
    friction = min(b.friction for b in bodies) * min([support.friction] + [b.friction for b in bodies])
    bounce = max(b.restitution for b in bodies) * max([support.restitution] + [b.restitution for b in bodies])
    if friction <= 0 or bounce >= 1:
        return math.inf
    return math.hypot(drop, width) + drop / friction + 4 * bounce * drop / (1 - bounce * bounce)


def dependents(resting: dict[str, set[str]], name: str) -> set[str]:
    """Everything that rests on ``name``, directly or through others."""
    found, todo = set(), [name]
    while todo:
        for above in resting.get(todo.pop(), ()):
            if above not in found:
                found.add(above)
                todo.append(above)
    return found


@dataclass(frozen=True)
class Answers:
    """The variants of one question, in the order asked, and what they cost."""

    scene: str
    variants: tuple[VariantAnswer, ...]
    samples_requested: int
    wall_s: float
    stopped_by: str = "samples"
    #: label -> [(sample index, the variant's result with its trajectory)] for recorded samples
    recorded: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)
    #: the scene left alone (None when no variant is "as is")
    alone: "Alone | None" = None

    def to_dict(self) -> dict:
        return {"scene": self.scene, "variants": [v.to_dict() for v in self.variants],
                "samples_requested": self.samples_requested, "wall_s": self.wall_s, "stopped_by": self.stopped_by,
                "alone": None if self.alone is None else self.alone.to_dict()}


@dataclass(frozen=True)
class Alone:
    """The scene left alone: P(anything falls by itself) with its 95% interval, the samples in which
    it stands (those every ``given_stands`` answer is over), and ``unstable``: it falls by itself
    more often than ``safe_below`` even at the low end of the interval. Whatever the robot does
    then, things may fall that its action did not make fall."""

    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    samples_standing: int
    unstable: bool

    def to_dict(self) -> dict:
        return {"any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "samples_standing": self.samples_standing, "unstable": self.unstable}


def ask(scene: Scene, actions: list[Action], model: ModelConfig, settings: SimSettings, seed: int = 0,
        map_fn: MapFn | None = None, budget_s: float | None = None,
        fall_threshold_fraction: float = 0.125, record_every: int = 0, record_samples: int = 0,
        directions: bool = False, fell_off: bool = False, sequential: Sequential | None = None,
        on_progress: Callable[[dict], None] | None = None, contact: tuple[tuple[str, str], ...] = ()) -> Answers:
    """Answer every variant with common random numbers (see the module docstring). Removals that
    cannot change anything are answered from the scene's own samples (a variant "as is" is added
    for them when it is not asked). ``record_every`` / ``record_samples``: keep the trajectories of
    the first samples of every simulated variant (for rerun), in ``Answers.recorded``.
    ``directions``: also where things fall (rollouts then run until everything rests; without it a
    rollout ends as soon as what falls is decided). ``fell_off``: also which objects end off the
    table (their centre below its top; the scene must stand on a table). ``sequential``: answer
    in batches until its rule decides each variant, simulating variants only in samples where the
    scene as it is stands (``decide``); needs an "as is" variant, ignored without noise.
    ``on_progress``: called after each batch of a sequential answer with what is decided so far
    (``progress_dict``); whatever it raises ends the question there (a cancellation). ``contact``:
    also, per variant, P(A touches B) for these (A, B) pairs (B may be "support"); every variant is
    then simulated (none is read from the scene as it is)."""
    validate_scene(scene)
    check_budget(budget_s)
    for i, action in enumerate(actions):
        _check_action(scene, action, f"actions[{i}]")
    if fell_off and not isinstance(scene.support, Table):
        raise ConfigError("fell_off", f"{scene.name!r} stands on a floor: nothing can fall off it (ask it of a "
                                      "scene on a table)")
    _check_contact(scene, actions, contact)
    margin = 3 * float(position_sigmas_m(scene, model).max(initial=0.0))  # noise can close gaps this wide
    everything = frozenset(b.name for b in scene.dynamic_objects)
    # a pushed support can slide every group into every other
    scene_groups = [everything] if model.pushes else groups(scene, margin)
    # a removal that nothing else is within reach of cannot change anything: the rest of the scene does
    # what it does anyway (read from "as is"). Touching is not enough to be left out: a counterweight
    # with nothing on it still holds down what it rests on, and a gap closes when the object above drops.
    trivial = [isinstance(a, Remove) and _reached(scene_groups, a.names) <= set(a.names) and not contact
               for a in actions]
    simulated_actions = [a for a, t in zip(actions, trivial) if not t]
    if any(trivial) and None not in simulated_actions:
        simulated_actions.append(None)
    if budget_s is not None:
        cost = rollout_cost(scene, model, settings)
        if cost.seconds * max(1, len(simulated_actions)) > budget_s:
            raise ConfigError("budget_s", f"one sample of these {len(simulated_actions)} variants takes up to "
                                          f"~{cost.seconds * len(simulated_actions):.3g} s, more than the budget of "
                                          f"{budget_s:g} s; ask fewer variants or raise the budget")
    regions = _regions(scene, simulated_actions, margin, scene_groups, model.pushes)
    asked = {"fall"} | ({"direction"} if directions else set()) | ({"bump"} if fell_off else set()) \
        | ({"contact"} if contact else set())
    query = QuerySpec(queries=frozenset(asked), fall_threshold_fraction=fall_threshold_fraction,
                      contact_pairs=tuple(contact))
    # no noise anywhere (scene, model, nor an action's own): one rollout per variant says everything
    deterministic = is_deterministic(scene, model) and not any(_draws_noise(scene, a, model)
                                                               for a in simulated_actions)
    k = 1 if deterministic else model.samples
    deadline = None if budget_s is None else time.time() + budget_s
    seeds = np.random.SeedSequence(seed).spawn(k)

    def tasks(indices, variants: list[int]) -> list[VariantTask]:
        return [VariantTask(scene=scene, model=model, settings=settings, query=query, index=i, seed=seeds[i],
                            actions=tuple(simulated_actions[j] for j in variants), deadline_unix_s=deadline,
                            regions=tuple(regions[j] for j in variants),
                            record_every=record_every if i < record_samples else 0)
                for i in indices]

    start = time.perf_counter()
    as_is = simulated_actions.index(None) if None in simulated_actions else None
    decisions: dict[str, tuple[str | None, str, int]] = {}
    if sequential is None or deterministic or as_is is None:
        per_sample = _run(tasks(range(k), list(range(len(simulated_actions)))), map_fn, scene)
    else:
        per_sample, decisions = _run_sequentially(tasks, simulated_actions, as_is, k, sequential, map_fn, scene,
                                                  on_progress)
    by_variant = {_label(a): dataclasses.replace(
        _aggregate(_label(a), a, [s[j] for s in per_sample], deterministic=deterministic),
        not_simulated=() if regions[j] is None else tuple(sorted(everything - regions[j])))
        for j, a in enumerate(simulated_actions)}
    if as_is is not None:
        stands = [_stood(s[as_is]) for s in per_sample]
        for j, a in enumerate(simulated_actions):
            by_variant[_label(a)] = dataclasses.replace(
                by_variant[_label(a)], caused_fall_probability=_caused(per_sample, j, as_is),
                given_stands=_aggregate_given(
                    [s[j] for s, ok in zip(per_sample, stands) if ok], deterministic=deterministic))
    for label, (decision, why, drawn) in decisions.items():
        by_variant[label] = dataclasses.replace(by_variant[label], decision=decision, stopped_by=why,
                                                samples_drawn=drawn)
    answers = []
    for action, is_trivial in zip(actions, trivial):
        if not is_trivial:
            answers.append(by_variant[_label(action)])
            continue
        # nothing rests on it: the rest of the scene does what it does anyway, read from "as is"
        others = [j for j, n in enumerate(b.name for b in scene.dynamic_objects) if n not in action.names]
        results = [VariantResult(tuple(r.names[j] for j in others), None if r.fallen is None else r.fallen[others],
                                 r.direction_rad, r.error, r.budget_stopped,
                                 fell_off=None if r.fell_off is None else r.fell_off[others])
                   for r in (s[as_is] for s in per_sample)]
        answers.append(dataclasses.replace(
            _aggregate(_label(action), action, results, deterministic=deterministic), simulated=False,
            caused_fall_probability={n: 0.0 for n in results[0].names},
            given_stands=_aggregate_given([r for r, ok in zip(results, stands) if ok], deterministic=deterministic)))
    stopped = "budget" if any(r.budget_stopped for s in per_sample for r in s) else "samples"
    recorded = {_label(a): [(i, s[j]) for i, s in enumerate(per_sample) if s[j].trajectory is not None]
                for j, a in enumerate(simulated_actions)} if record_every else {}
    scene_alone = None
    if as_is is not None:
        alone = by_variant["as_is"]
        scene_alone = Alone(alone.any_fall_probability, alone.any_fall_probability_ci95, sum(stands),
                           alone.any_fall_probability_ci95 is not None
                           and alone.any_fall_probability_ci95[0] > DEFAULT_SAFE_BELOW)
    return Answers(scene.name, tuple(answers), k, time.perf_counter() - start, stopped, recorded, scene_alone)


def _check_contact(scene: Scene, actions: list[Action], pairs) -> None:
    """Contact pairs name objects of the scene, placed objects, or the support."""
    known = {b.name for b in scene.objects} | {a.body.name for a in actions if isinstance(a, Place)} | {"support"}
    for a, b in pairs:
        for name in (a, b):
            if name not in known:
                raise ConfigError("contact", f"{a}:{b}: no object {shown(name)} in scene {shown(scene.name)} or "
                                             f"placed by the question; objects: {', '.join(sorted(known))}")
        if a == b:
            raise ConfigError("contact", f"{a}:{b}: an object always touches itself; name two")


def _run(tasks: list[VariantTask], map_fn: MapFn | None, scene: Scene) -> list[list[VariantResult]]:
    if map_fn is None:
        return [run_variants(t) for t in tasks]
    names = tuple(b.name for b in scene.dynamic_objects)
    lost = lambda task, reason: [  # noqa: E731
        VariantResult(names, None, None, f"WorkerLost: {reason}", worker_lost=True) for _ in task.actions]
    return map_fn(run_variants, tasks, on_lost=lost)


#: variants per task in a sequential batch: enough to amortise the shared draw and separation each
#: task redoes, few enough that standing samples' variants spread over the workers
VARIANTS_PER_TASK = 4


def _run_sequentially(tasks, actions: list[Action], as_is: int, k: int, sequential: Sequential, map_fn: MapFn | None,
                      scene: Scene, on_progress: Callable[[dict], None] | None = None
                      ) -> tuple[list[list[VariantResult]], dict[str, tuple[str | None, str, int]]]:
    """Batches of samples until the rule has decided every variant or k samples are drawn. Each
    batch runs the scene as it is first, then the undecided variants of the samples in which it
    stood, a few variants per task (the work of one sample varies too much - one rollout or all of
    them - to spread by samples); a variant not run in a sample is a skipped result. Returns every
    sample's results (in ``actions`` order) and, per variant label, (decision, why it stopped,
    samples drawn for it)."""
    names = tuple(b.name for b in scene.dynamic_objects)
    others = [j for j in range(len(actions)) if j != as_is]
    active = set(others)
    decisions: dict[str, tuple[str | None, str, int]] = {}
    per_sample: list[list[VariantResult]] = []
    # counted as the batches come (recounting every sample at every look would grow with k x looks)
    counts = {_label(actions[j]): _Counts() for j in others}
    while len(per_sample) < k and active:
        batch = range(len(per_sample), min(k, len(per_sample) + sequential.batch_samples))
        rows = {}
        for i, (alone,) in zip(batch, _run(tasks(batch, [as_is]), map_fn, scene)):
            rows[i] = [VariantResult(names, None, None, "skipped: the scene fell as it is" if j in active
                                     else "skipped: decided", skipped=True) for j in range(len(actions))]
            rows[i][as_is] = alone
        standing = [i for i in batch if _stood(rows[i][as_is])]
        running = sorted(active)
        chunks = [running[c:c + VARIANTS_PER_TASK] for c in range(0, len(running), VARIANTS_PER_TASK)]
        jobs = [(i, chunk) for i in standing for chunk in chunks]
        work = [task for i, chunk in jobs for task in tasks([i], chunk)]
        for (i, chunk), results in zip(jobs, _run(work, map_fn, scene) if work else []):
            for j, result in zip(chunk, results):
                rows[i][j] = result
        for i in batch:
            per_sample.append(rows[i])
            for j in running:
                counts[_label(actions[j])].add(rows[i][j])
        if any(r.budget_stopped for i in batch for r in rows[i]):
            break
        tallies = {label: c.tally() for label, c in counts.items()}
        labels = {_label(actions[j]): j for j in active}
        for label, decision in sequential.rule.decide(tallies, set(labels)).items():
            decisions[label] = (decision, "decided", len(per_sample))
            active.discard(labels[label])
        if on_progress is not None:
            on_progress(progress_dict(scene.name, k, len(per_sample), decisions,
                                      [_label(actions[j]) for j in sorted(active)], tallies))
    budget = any(r.budget_stopped for row in per_sample for r in row)
    for j in active:
        decisions[_label(actions[j])] = (None, "budget" if budget else "cap", len(per_sample))
    return per_sample, decisions


def progress_dict(scene: str, k: int, drawn: int, decisions: dict, undecided: list[str],
                  tallies: dict[str, Tally]) -> dict:
    """A partial answer: the samples drawn so far (of at most k), each decided variant's decision and
    the samples it used, and the variants still sampling with their running P(anything falls)."""
    def running(label):
        t = tallies[label]
        return {"label": label, "samples": t.samples,
                "any_fall_probability": None if t.samples == 0 else t.any_falls / t.samples}
    return {"scene": scene, "samples_requested": k, "samples_drawn": drawn,
            "decided": [{"label": label, "decision": d, "samples_drawn": n, "samples": tallies[label].samples}
                        for label, (d, _, n) in decisions.items()],
            "undecided": [running(label) for label in undecided]}


class _Counts:
    """A variant's outcomes so far (skipped and failed samples left out), as a decide.Tally."""

    def __init__(self):
        self.samples, self.any_falls, self.object_falls = 0, 0, {}

    def add(self, result: VariantResult) -> None:
        if result.error is not None:
            return
        self.samples += 1
        self.any_falls += bool(np.any(result.fallen))
        for name, fell in zip(result.names, result.fallen):
            self.object_falls[name] = self.object_falls.get(name, 0) + bool(fell)

    def tally(self) -> Tally:
        return Tally(self.samples, self.any_falls, dict(self.object_falls))


def _caused(per_sample: list[list[VariantResult]], variant: int, as_is: int) -> dict[str, float] | None:
    """Per object of the variant: the fraction of paired samples in which it fell with the action
    and not in the scene as is."""
    pairs = [(s[variant], s[as_is]) for s in per_sample if s[variant].error is None and s[as_is].error is None]
    if not pairs:
        return None
    names = pairs[0][0].names
    counts = dict.fromkeys(names, 0)
    for with_action, without in pairs:
        before = dict(zip(without.names, without.fallen))
        for name, fell in zip(with_action.names, with_action.fallen):
            counts[name] += bool(fell) and not before.get(name, False)
    return {n: c / len(pairs) for n, c in counts.items()}


def _reached(scene_groups: list[frozenset[str]], names) -> frozenset[str]:
    """Every object in a group with one of ``names``: all that removing them could affect."""
    return frozenset().union(*(g for g in scene_groups if g & set(names)))


def _regions(scene: Scene, actions: list[Action], margin_m: float, scene_groups: list[frozenset[str]],
             pushes: bool) -> tuple[frozenset[str] | None, ...]:
    """Per action, the groups of objects it can affect (None: the whole scene)."""
    everything = frozenset(b.name for b in scene.dynamic_objects)
    out = []
    for action in actions:
        region = None
        if isinstance(action, Remove):
            region = _reached(scene_groups, action.names)
        elif isinstance(action, Place) and not pushes:
            with_it = dataclasses.replace(scene, objects=scene.objects + (action.body,))
            region = next(g for g in groups(with_it, margin_m) if action.body.name in g)
        out.append(None if region is None or region >= everything else region)
    return tuple(out)


# -- the questions ----------------------------------------------------------------------------------------
_NO_OBJECTS = "names no object; name at least one, or leave it out to ask about every one"


def remove(scene: Scene, names: list[str] | None, model: ModelConfig, settings: SimSettings,
           safe_below: float | None = None, sequential: bool = True, **kw) -> Answers:
    """P(anything else falls) and per-object probabilities if each named object (None: every
    dynamic object, one at a time) is taken away; the scene as it is comes first. ``safe_below``:
    "is it safe to take?" - each removal decided safe or unsafe at this level, sampled until decided
    (``sequential``; False: the full k for every removal)."""
    rule = None
    if safe_below is not None:
        _check_level("safe_below", safe_below)
        rule = Sequential(SafeBelow(safe_below)) if sequential else None
    return ask(scene, _removals(scene, names), model, settings, sequential=rule, **kw)


def _removals(scene: Scene, names: list[str] | None) -> list[Action]:
    """The scene as it is, then each named object (None: every dynamic one) taken away on its own."""
    if names is not None and not names:
        raise ConfigError("objects", _NO_OBJECTS)
    names = [b.name for b in scene.dynamic_objects] if names is None else list(names)
    return [None] + [Remove((n,)) for n in names]


def _check_level(name: str, value) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 1:
        raise ConfigError(name, f"must be in (0, 1], got {value!r}")


#: Estimated seconds to lower one candidate placement onto what is below it (measured 2-8 ms).
PLACEMENT_GEOMETRY_S = 0.01


class _Deadline:
    """A question's wall-clock budget, started when it is asked: everything before the simulation
    (geometry for placements, earlier steps of a clearing order) spends from it too."""

    def __init__(self, budget_s: float | None):
        check_budget(budget_s)
        self.budget_s = budget_s
        self.at_unix_s = None if budget_s is None else time.time() + budget_s

    def remaining_s(self) -> float | None:
        return None if self.at_unix_s is None else self.at_unix_s - time.time()

    def passed(self) -> bool:
        return self.at_unix_s is not None and time.time() >= self.at_unix_s


def _check_variants(scene: Scene, variants: int, model: ModelConfig, settings: SimSettings, budget_s: float | None,
                    what: str, field: str, placements: int = 0) -> None:
    """Refuse up front, before any geometry or simulation: more variants than a question may ask,
    or one sample of each (plus lowering the placements) estimated beyond the budget."""
    if variants > limits.MAX_QUESTION_VARIANTS:
        raise ConfigError(field, f"{what} make {variants} variants, more than the {limits.MAX_QUESTION_VARIANTS} one "
                                 "question may ask about; split the search into several questions")
    if budget_s is not None:
        seconds = rollout_cost(scene, model, settings).seconds * (variants + 1) + placements * PLACEMENT_GEOMETRY_S
        if seconds > budget_s:
            raise ConfigError("budget_s", f"one sample of these {variants + 1} variants takes up to ~{seconds:.3g} s, "
                                          f"more than the budget of {budget_s:g} s; ask fewer variants or raise the "
                                          "budget")


@dataclass(frozen=True)
class SupportGraph:
    """What holds what, apart from what falls anyway: every P below is over the samples in which the
    scene as it is stands (``answers.alone.samples_standing`` of them; common random numbers pair
    the samples). ``edges``: (supporter, supported, P) where P, at or above ``threshold``, is the
    probability that the supported object falls without the supporter; ``safe``: objects whose
    removal leaves P(anything else falls) below ``safe_below`` (the upper end of its 95% interval
    reported with it). ``answers.alone.unstable``: the scene falls by itself too often to leave
    alone; with no sample standing, there are no edges and nothing is safe."""

    scene: str
    edges: tuple[tuple[str, str, float], ...]
    safe: tuple[tuple[str, float, float], ...]
    threshold: float
    safe_below: float
    answers: Answers

    def to_dict(self) -> dict:
        return {"scene": self.scene, "edges": [list(e) for e in self.edges],
                "safe_to_remove": [{"name": n, "p_anything_falls": p, "ci95_high": hi} for n, p, hi in self.safe],
                "threshold": self.threshold, "safe_below": self.safe_below, "answers": self.answers.to_dict()}


def support_graph(scene: Scene, model: ModelConfig, settings: SimSettings, threshold: float = DEFAULT_SUPPORT_THRESHOLD,
                  safe_below: float = DEFAULT_SAFE_BELOW, sequential: bool = True, **kw) -> SupportGraph:
    """``sequential``: sample each removal until its edges and its safety are decided (False: the
    full k for every removal)."""
    for name, value in (("threshold", threshold), ("safe_below", safe_below)):
        _check_level(name, value)
    answers = ask(scene, _removals(scene, None), model, settings,
                  sequential=Sequential(Supports(threshold, safe_below)) if sequential else None, **kw)
    edges, safe = [], []
    for variant in answers.variants[1:]:
        (removed,) = variant.action.names
        given = variant.given_stands
        if given is None or given.any_fall_probability is None:
            continue
        # "removing i makes j fall": j falls without i in the samples where nothing falls with it
        for name, p in given.object_fall_probability.items():
            if p >= threshold:
                edges.append((removed, name, p))
        if given.any_fall_probability < safe_below:
            safe.append((removed, given.any_fall_probability, given.any_fall_probability_ci95[1]))
    return SupportGraph(scene.name, tuple(edges), tuple(safe), threshold, safe_below, answers)


@dataclass(frozen=True)
class ClearStep:
    name: str
    p_anything_falls: float
    ci95: tuple[float, float]


@dataclass(frozen=True)
class ClearOrder:
    """Objects in the order to take them away, each step's risk, and the total
    1 - prod(1 - risk): the chance that some step makes something fall."""

    scene: str
    steps: tuple[ClearStep, ...]
    total_risk: float
    target: str | None
    stopped_by: str = "done"  # "budget": the steps so far are all the budget held (the order is incomplete)

    def to_dict(self) -> dict:
        return {"scene": self.scene, "target": self.target, "total_risk": self.total_risk, "stopped_by": self.stopped_by,
                "steps": [{"remove": s.name, "p_anything_falls": s.p_anything_falls, "ci95": list(s.ci95)}
                          for s in self.steps]}


def clear_order(scene: Scene, model: ModelConfig, settings: SimSettings, target: str | None = None,
                sequential: bool = True, **kw) -> ClearOrder:
    """Greedy disassembly: at each step take away the object whose removal is least likely to make
    anything else fall (ties: the highest first). With ``target``, only the target and what rests
    on it (directly or through others) are candidates, and the sequence ends when the target is gone.
    ``sequential``: each step samples its candidates until all but the least risky are ranked out."""
    if target is not None and target not in {b.name for b in scene.dynamic_objects}:
        raise ConfigError("target", f"no dynamic object named {target!r} in {scene.name!r}")
    deadline = _Deadline(kw.pop("budget_s", None))  # one budget for every step, not one each
    steps: list[ClearStep] = []
    current = scene
    stopped_by = "done"
    while True:
        candidates = [b.name for b in current.dynamic_objects]
        if target is not None:
            resting = resting_on(current)
            candidates = [target] + sorted(dependents(resting, target))
        if len(current.dynamic_objects) == 1:
            only = current.dynamic_objects[0].name
            steps.append(ClearStep(only, 0.0, (0.0, 0.0)))
            break
        if deadline.passed():
            stopped_by = "budget"
            break
        try:
            answers = ask(current, _removals(current, candidates), model, settings, budget_s=deadline.remaining_s(),
                          sequential=Sequential(Ranking()) if sequential else None, **kw)
        except ConfigError as exc:
            if exc.field != "budget_s" or not steps:  # the first step must fit: refused as any question
                raise
            stopped_by = "budget"  # what is left of the budget does not hold the next step
            break
        if answers.stopped_by == "budget":  # a step decided on fewer samples than asked is not decided
            stopped_by = "budget"
            break
        heights = {b.name: b.centre_of_mass_m[2] for b in current.dynamic_objects}
        best = min(answers.variants[1:], key=lambda v: (_rank_key(v), -heights[v.action.names[0]]))
        (name,) = best.action.names
        steps.append(ClearStep(name, best.any_fall_probability or 0.0, best.any_fall_probability_ci95 or (0.0, 1.0)))
        current = dataclasses.replace(current, objects=tuple(b for b in current.objects if b.name != name))
        if name == target or not current.dynamic_objects:
            break
    total = 1 - float(np.prod([1 - s.p_anything_falls for s in steps]))
    return ClearOrder(scene.name, tuple(steps), total, target, stopped_by)


def place(scene: Scene, bodies: list[Body], model: ModelConfig, settings: SimSettings, sequential: bool = True,
          **kw) -> Answers:
    """P(anything falls, the new object included) for each candidate placement (one object each);
    the scene as it is comes first. ``sequential``: sample the candidates until all but the least
    risky are ranked out (ties run to k)."""
    return ask(scene, [None] + [Place(b) for b in bodies], model, settings,
               sequential=Sequential(Ranking()) if sequential else None, **kw)


def resting_height_m(scene: Scene, body: Body, x_m: float, y_m: float, orientation_xyzw) -> float:
    """z of ``body``'s frame when it is lowered at (x, y) with this orientation until it touches
    what is below (the support or an object), found by bisection on its distance to everything
    else: exact for any shape, a ball's top included."""
    return _Lowering(scene, body).height_m(x_m, y_m, orientation_xyzw)


class _Lowering:
    """One geometry world of the scene with ``body`` in it, moved from spot to spot (building the
    world is most of the cost of one spot)."""

    def __init__(self, scene: Scene, body: Body):
        from .simulation import world as world_module

        self._world_module, self.scene, self.body = world_module, scene, body
        self.world = _geometry_world(scene)
        self.size = max(body.extents_m)
        self.top = max([scene.support.top_m] + [float(b.position_m[2]) + max(b.extents_m)
                                                for b in scene.objects]) + self.size
        self.handle = world_module.add_fixed_body(self.world, dataclasses.replace(body, static=True),
                                                  (0.0, 0.0, self.top), (0.0, 0.0, 0.0, 1.0))
        self.touch = 1e-3 * min(body.extents_m)  # rest this close above the surface

    def height_m(self, x_m: float, y_m: float, orientation_xyzw) -> float:
        def clear_at(z: float) -> bool:
            self._world_module.move_body(self.world, self.handle, (x_m, y_m, z), orientation_xyzw)
            return self._world_module.gap_to_others_m(self.world, self.handle, 2 * self.size) >= self.touch

        low, high = self.scene.support.top_m - 2 * self.size, self.top
        if clear_at(low):  # nothing below at all (off a table's edge with no floor): not a place
            raise ConfigError("position_m", f"nothing under ({x_m:g}, {y_m:g}) to rest {self.body.name!r} on")
        for _ in range(50):
            middle = (low + high) / 2
            if clear_at(middle):
                high = middle
            else:
                low = middle
        return float(high)


def _lowered(scene: Scene, body: Body, spots, deadline: _Deadline) -> list[Body]:
    """``body`` at each (x, y, yaw_rad) spot, lowered onto what is below; the question's budget
    checked between spots."""
    validate_body(body, "object")  # before pybullet sees its shape (the scene check comes after lowering)
    lowering = _Lowering(scene, body)
    bodies = []
    for x, y, yaw in spots:
        if deadline.passed():
            raise ConfigError("budget_s", f"lowering {len(spots)} candidate placements onto the scene took the whole "
                                          f"budget of {deadline.budget_s:g} s ({len(bodies)} done); ask fewer "
                                          "candidates or raise the budget")
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        bodies.append(dataclasses.replace(body, position_m=(x, y, lowering.height_m(x, y, q)), orientation_xyzw=q))
    return bodies


@dataclass(frozen=True)
class Region:
    """Where to look for a place: x and y ranges in the scene frame (metres), yaws (radians)."""

    x_m: tuple[float, float]
    y_m: tuple[float, float]
    yaw_rad: tuple[float, float] = (0.0, 0.0)


def best_place(scene: Scene, body: Body, region: Region, model: ModelConfig, settings: SimSettings,
               candidates: int = 16, yaws: int = 1, **kw) -> tuple[list[tuple[Body, VariantAnswer]], Answers]:
    """Candidate poses on a grid over ``region`` (about ``candidates`` of them, times ``yaws``
    orientations), each lowered onto what is below; returned most stable first."""
    for name, value in (("candidates", candidates), ("yaws", yaws)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(name, f"must be an integer >= 1, got {value!r}")
    n = max(1, int(round(math.sqrt(candidates))))
    deadline = _Deadline(kw.pop("budget_s", None))
    _check_variants(scene, n * n * yaws, model, settings, deadline.budget_s,
                    f"{n} x {n} candidates x {yaws} yaws", "candidates", placements=n * n * yaws)
    xs = np.linspace(*region.x_m, n)
    ys = np.linspace(*region.y_m, n)
    yaw_values = np.linspace(*region.yaw_rad, yaws) if yaws > 1 else [region.yaw_rad[0]]
    bodies = _lowered(scene, body, [(float(x), float(y), float(yaw))
                                    for x, y, yaw in itertools.product(xs, ys, yaw_values)], deadline)
    answers = place(scene, bodies, model, settings, budget_s=deadline.remaining_s(), **kw)
    ranked = sorted(zip(bodies, answers.variants[1:]), key=lambda bv: _rank_key(bv[1]))
    return ranked, answers


def _rank_key(variant: VariantAnswer) -> tuple:
    """Least likely to make anything fall first; a sequential answer's ranked-out ones last."""
    return (variant.decision == "ranked out",
            1.0 if variant.any_fall_probability is None else variant.any_fall_probability)


def push(scene: Scene, pushes: list[Push], model: ModelConfig, settings: SimSettings, **kw) -> Answers:
    """What falls, and in which direction, when each push is made; the scene as it is comes first."""
    return ask(scene, [None] + list(pushes), model, settings, directions=True, **kw)


# -- questions as data (the node's ~/ask, scripts) ------------------------------------------------------
QUESTIONS = ("remove", "support", "clear", "place", "push")


@dataclass(frozen=True)
class Question:
    """One question as a robot sends it (see ``question_from_dict`` for the JSON)."""

    kind: str
    request_id: str = ""
    objects: tuple[str, ...] | None = None  # remove: which (None: every object)
    threshold: float = DEFAULT_SUPPORT_THRESHOLD  # support
    safe_below: float | None = DEFAULT_SAFE_BELOW  # support; remove: None (no decision) unless asked
    target: str | None = None  # clear
    body: Body | None = None  # place
    spots: tuple[tuple[float, float, float], ...] = ()  # place: (x, y, yaw_rad), lowered onto what is below
    region: Region | None = None  # place: search here instead
    candidates: int = 16
    yaws: int = 1
    push: Push | None = None
    samples: int | None = None  # None: the asker's default
    fell_off: bool = False  # also: which objects end off the table (a scene on a table)
    sequential: bool = True  # decision questions sample until decided; False: the full k
    cancel_older: bool = False  # the node drops older questions about the same scene for this one
    contact: tuple[tuple[str, str], ...] = ()  # remove, place, push: also P(A touches B) per variant


def _field(data: dict, key: str, kind, default=None, *, path: str = ""):
    value = data.get(key, default)
    if value is default:
        return value
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        raise ConfigError(f"{path}{key}", f"must be {kind.__name__ if kind is not float else 'a number'}")
    return value


#: The fields each kind of question reads, besides id, question, samples and scene.
_QUESTION_FIELDS = {"remove": {"objects", "safe_below", "contact"}, "support": {"threshold", "safe_below"},
                    "clear": {"target"}, "place": {"object", "at", "region", "contact"},
                    "push": {"object", "velocity_m_s", "point_m", "direction_sigma_deg", "speed_sigma", "contact"}}


def question_from_dict(data) -> Question:
    """A question from parsed JSON::

        {"id": "r1", "question": "remove", "objects": ["block3"], "safe_below": 0.05}
                                     (objects: default every one; safe_below: decide safe/unsafe)
        {"id": "r2", "question": "support", "threshold": 0.5, "safe_below": 0.05}
        {"id": "r3", "question": "clear", "target": "block7"}                (target optional)
        {"id": "r4", "question": "place", "object": {...scene-format object...},
         "at": [[x, y, yaw_deg], ...]}  or  "region": {"x_m": [x0, x1], "y_m": [y0, y1],
         "yaw_deg": [a0, a1], "candidates": 16, "yaws": 1}
        {"id": "r5", "question": "push", "object": "block2", "velocity_m_s": [vx, vy],
         "point_m": [x, y, z], "direction_sigma_deg": 0, "speed_sigma": 0}
        remove, place, push: "contact": ["A:B", ...] (also P(A touches B) per variant; B may be "support")
        any of them: "samples": k, "fell_off": true (also which objects end off the table),
        "sequential": false (the full k for every variant), "cancel_older": true (the node drops the
        older questions about the same scene, waiting or running)
    """
    if not isinstance(data, dict):
        raise ConfigError("question", "must be a JSON object with a \"question\" field")
    kind = data.get("question")
    if kind not in QUESTIONS:
        raise ConfigError("question", f"must be one of {', '.join(QUESTIONS)}, got {kind!r}"[:300])
    common_fields = {"id", "question", "samples", "scene", "fell_off", "sequential", "cancel_older"}
    unknown = sorted(set(data) - _QUESTION_FIELDS[kind] - common_fields, key=str)
    if unknown:
        key = unknown[0]
        allowed = ", ".join(sorted(_QUESTION_FIELDS[kind] | common_fields - {"question"}))
        raise ConfigError(key if key.isidentifier() and len(key) <= 64 else f"[{shown(key)}]",
                          f"unknown field of a {kind} question; allowed: {allowed}")
    request_id = data.get("id", "")
    if not isinstance(request_id, str) or len(request_id) > 128:
        raise ConfigError("id", "must be a string of at most 128 characters")
    samples = data.get("samples")
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= 1000):
        raise ConfigError("samples", "must be an integer in [1, 1000]")
    flags = {}
    for name, default in (("fell_off", False), ("sequential", True), ("cancel_older", False)):
        flags[name] = data.get(name, default)
        if not isinstance(flags[name], bool):
            raise ConfigError(name, "must be true or false")
    common = dict(kind=kind, request_id=request_id, samples=samples, **flags)
    if "contact" in data:
        pairs = data["contact"]
        if not isinstance(pairs, list) or not pairs or len(pairs) > 32:
            raise ConfigError("contact", "must be a list of 1-32 \"A:B\" pairs (B may be \"support\")")
        common["contact"] = tuple(parse_pair(pair, "contact") for pair in pairs)
        if len(set(common["contact"])) != len(common["contact"]):
            raise ConfigError("contact", "a pair is asked twice; ask each once")
    if kind == "remove":
        objects = data.get("objects")
        if objects is not None and (not isinstance(objects, list) or not all(isinstance(o, str) for o in objects)):
            raise ConfigError("objects", "must be a list of object names")
        if objects == []:  # refused when read, before the question waits its turn (remove() refuses it too)
            raise ConfigError("objects", _NO_OBJECTS)
        safe_below = _field(data, "safe_below", float, None)
        if safe_below is not None:
            _check_level("safe_below", safe_below)
        return Question(objects=None if objects is None else tuple(objects), safe_below=safe_below, **common)
    if kind == "support":
        question = Question(threshold=_field(data, "threshold", float, DEFAULT_SUPPORT_THRESHOLD),
                            safe_below=_field(data, "safe_below", float, DEFAULT_SAFE_BELOW), **common)
        _check_level("threshold", question.threshold)
        _check_level("safe_below", question.safe_below)
        return question
    if kind == "clear":
        return Question(target=_field(data, "target", str), **common)
    if kind == "push":
        velocity = data.get("velocity_m_s")
        if not isinstance(velocity, list) or len(velocity) != 2:
            raise ConfigError("velocity_m_s", "must be [vx, vy] in m/s")
        point = data.get("point_m")
        if point is not None and (not isinstance(point, list) or len(point) != 3):
            raise ConfigError("point_m", "must be [x, y, z] in metres or absent")
        try:
            push = Push(_field(data, "object", str, path=""), (float(velocity[0]), float(velocity[1]), 0.0),
                        None if point is None else tuple(float(v) for v in point),
                        math.radians(_field(data, "direction_sigma_deg", float, 0.0)),
                        _field(data, "speed_sigma", float, 0.0))
        except (TypeError, ValueError):
            raise ConfigError("velocity_m_s", "must hold numbers") from None
        if push.name is None:
            raise ConfigError("object", "name the object to push")
        return Question(push=push, **common)
    body = new_object_from_dict(data.get("object"), "object")
    at, region = data.get("at"), data.get("region")
    if (at is None) == (region is None):
        raise ConfigError("at", "give candidate spots in \"at\" or a \"region\" to search (one of them)")
    if at is not None:
        if isinstance(at, list) and len(at) > limits.MAX_QUESTION_VARIANTS:
            raise ConfigError("at", f"{len(at)} spots are more than the {limits.MAX_QUESTION_VARIANTS} one question may "
                                    "ask about; split them into several questions")
        if not isinstance(at, list) or not at or not all(
                isinstance(s, list) and len(s) in (2, 3) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                                 and math.isfinite(v) for v in s) for s in at):
            raise ConfigError("at", "must be a list of [x, y] or [x, y, yaw_deg] spots")
        spots = tuple((float(s[0]), float(s[1]), math.radians(s[2]) if len(s) == 3 else 0.0) for s in at)
        return Question(body=body, spots=spots, **common)
    if not isinstance(region, dict):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg, candidates, yaws)")
    try:
        xs, ys = tuple(map(float, region["x_m"])), tuple(map(float, region["y_m"]))
        yaw = tuple(math.radians(float(v)) for v in region.get("yaw_deg", [0.0, 0.0]))
    except (KeyError, TypeError, ValueError):
        xs = ys = yaw = ()
    if not (len(xs) == len(ys) == len(yaw) == 2 and all(map(math.isfinite, xs + ys + yaw))):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg: [a0, a1])")
    candidates, yaws = region.get("candidates", 16), region.get("yaws", 1)
    if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 400 for v in (candidates, yaws)):
        raise ConfigError("region.candidates", "candidates and yaws must be integers in [1, 400]")
    if candidates * yaws > limits.MAX_QUESTION_VARIANTS:
        raise ConfigError("region.candidates", f"{candidates} candidates x {yaws} yaws are {candidates * yaws} "
                                               f"placements, more than the {limits.MAX_QUESTION_VARIANTS} one question "
                                               "may ask about; search a smaller region or fewer yaws")
    return Question(body=body, region=Region(xs, ys, yaw), candidates=candidates, yaws=yaws, **common)


def answer_question(scene: Scene, question: Question, model: ModelConfig, settings: SimSettings,
                    **kw) -> tuple[dict, Answers | None]:
    """Answer a Question: the JSON-ready answer, and the variants' Answers (None for ``clear``,
    which asks once per step) for a recording."""
    if question.samples is not None:
        model = dataclasses.replace(model, samples=question.samples)
    if question.fell_off:
        kw["fell_off"] = True
    if question.contact:
        kw["contact"] = question.contact
    kind = question.kind
    if kind == "push":  # no decision to reach: the full k
        answers = push(scene, [question.push], model, settings, **kw)
        return answers.to_dict(), answers
    kw["sequential"] = question.sequential
    if kind == "remove":
        answers = remove(scene, None if question.objects is None else list(question.objects), model, settings,
                         safe_below=question.safe_below, **kw)
        return answers.to_dict(), answers
    if kind == "support":
        graph = support_graph(scene, model, settings, threshold=question.threshold, safe_below=question.safe_below,
                              **kw)
        return graph.to_dict(), graph.answers
    if kind == "clear":
        kw = {k: v for k, v in kw.items() if k not in ("record_every", "record_samples")}
        return clear_order(scene, model, settings, target=question.target, **kw).to_dict(), None
    if question.region is not None:
        rows, answers = best_place(scene, question.body, question.region, model, settings,
                                   candidates=question.candidates, yaws=question.yaws, **kw)
    else:
        rows, answers = place_at(scene, question.body, question.spots, model, settings, **kw)
    return placements_to_dict(scene, rows, answers), answers


def place_at(scene: Scene, body: Body, spots, model: ModelConfig, settings: SimSettings,
             **kw) -> tuple[list[tuple[Body, VariantAnswer]], Answers]:
    """``place`` at each (x, y, yaw_rad) spot, the body lowered onto what is below it there."""
    spots = list(spots)
    deadline = _Deadline(kw.pop("budget_s", None))
    _check_variants(scene, len(spots), model, settings, deadline.budget_s, f"{len(spots)} spots", "at",
                    placements=len(spots))
    bodies = _lowered(scene, body, spots, deadline)
    answers = place(scene, bodies, model, settings, budget_s=deadline.remaining_s(), **kw)
    return list(zip(bodies, answers.variants[1:])), answers


def placements_to_dict(scene: Scene, rows: list[tuple[Body, VariantAnswer]], answers: Answers) -> dict:
    """A placement question's JSON answer: the scene as is, then each candidate pose with its answer."""
    return {"scene": scene.name, "as_is": answers.variants[0].to_dict(), "wall_s": answers.wall_s,
            "alone": None if answers.alone is None else answers.alone.to_dict(),
            "stopped_by": answers.stopped_by,
            "candidates": [{"position_m": list(b.position_m), "orientation_xyzw": list(b.orientation_xyzw),
                            **v.to_dict()} for b, v in rows]}


def new_object_from_dict(data, path: str) -> Body:
    """An object to place, in the scene format; its pose may be left out (the spot gives it)."""
    from .scene_io import object_from_dict

    if not isinstance(data, dict):
        raise ConfigError(path, "must be the new object in the scene format (/2)")
    body = object_from_dict({"position_m": [0.0, 0.0, 0.0], "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], **data}, path)
    validate_body(body, path)  # its own fields now: the geometry that lowers it comes before the scene check
    return body
