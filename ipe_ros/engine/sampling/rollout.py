"""One Monte Carlo sample end to end: draw inputs, build, depenetrate, simulate, query.

``run_sample`` is module-level and takes one picklable :class:`SampleTask`, so worker processes can
run it. It never raises for physics trouble: a failed or diverged rollout comes back as an outcome
with ``ok=False`` and the reason, and the sampler counts it.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import os
import time
import traceback
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..scene import shapes
from .. import simulation
from ..query import QUERIES, QuerySpec, Reading
from ..query.base import smallest_extents_m
from ..config import ModelConfig, SimSettings
from ..errors import BudgetExceeded, ConfigError, PhysicsError
from ..results.outcome import (HEALTHY_END_PENETRATION_FRACTION, HEALTHY_ENERGY_GAIN_FRACTION, RolloutResult, SampleOutcome,
                      energy_scale_of)
from .perturb import draw_sample
from ..scene.bodies import Floor, Scene
from ..simulation import NO_PROBE, DecidedHeights, Probe


@dataclass(frozen=True)
class Refine:
    """A fast sample whose rollout ends unhealthy (``SampleOutcome.unhealthy``) is rerun at ``settings``
    (the self-check's reference) in the same task, its rerun in ``SampleOutcome.refined``: the
    self-check's refinement without a round of its own after the fast samples, in which one worker
    runs the rerun and the others wait (``checking.self_check``)."""

    settings: SimSettings
    max_end_penetration_fraction: float
    max_energy_gain_fraction: float

    def why(self, outcome: SampleOutcome, scene: Scene) -> str | None:
        """Why ``outcome`` (a sample of ``scene``) is rerun, or None when it ended healthy."""
        return outcome.unhealthy(energy_scale_of(scene), self.max_end_penetration_fraction,
                                 self.max_energy_gain_fraction)


@dataclass(frozen=True)
class SampleTask:
    """Everything one sample needs; ``seed`` is this sample's own child of SeedSequence(seed)."""

    scene: Scene
    model: ModelConfig
    settings: SimSettings
    query: QuerySpec
    index: int
    seed: np.random.SeedSequence
    record_every: int = 0  # record a trajectory every N steps (0: none; only rerun logging asks)
    #: the prediction's compute budget ends at this time.time(); a sample still running then (or not
    #: yet started) is cut off and left out of the answer. Wall-clock time, so that worker processes
    #: share it; None: no budget.
    deadline_unix_s: float | None = None
    #: rerun at once where the rollout ends unhealthy (None: never; part of a stored result's key
    #: only when set, so that runs stored before it keep their keys)
    refine: Refine | None = dataclasses.field(default=None, metadata={"keyed": "when set"})

    def at(self, settings: SimSettings) -> "SampleTask":
        """The same sample (same seed, hence the same noisy scene) at other settings, not refined; a
        recorded sample keeps its frames the same simulated time apart."""
        every = self.record_every
        if every:
            every = max(1, round(every * self.settings.time_step_s / settings.time_step_s))
        return dataclasses.replace(self, settings=settings, record_every=every, refine=None)


def read_rollout(scene: Scene, spec: QuerySpec, initial: np.ndarray, end: simulation.RolloutEnd,
                 initial_orientations_xyzw: np.ndarray | None = None) -> dict:
    """Every asked query's values for one rollout, in the registry's order (the same in every
    process: ``spec.queries`` is a set)."""
    reading = Reading(scene=scene, spec=spec, initial_m=initial, final_m=end.positions_m,
                      final_orientations_xyzw=end.orientations_xyzw, final_speeds_m_s=end.speeds_m_s,
                      final_spins_rad_s=end.spins_rad_s, events=end.events or {}, ended_s=end.simulated_s,
                      initial_orientations_xyzw=initial_orientations_xyzw)
    values: dict = {}
    for name, query in QUERIES.items():
        if name in spec.queries:
            values.update(query.read(reading))
    return values


def rollout_result(scene: Scene, spec: QuerySpec, initial: np.ndarray, initial_orientations_xyzw: np.ndarray,
                   phi: float, end: simulation.RolloutEnd) -> RolloutResult:
    """One rollout's result: every asked query's values, the end state and its health."""
    return RolloutResult(phi_m_s2=phi, final_positions_m=end.positions_m, final_orientations_xyzw=end.orientations_xyzw,
                         values=read_rollout(scene, spec, initial, end, initial_orientations_xyzw),
                         trajectory=end.trajectory,
                         simulated_s=end.simulated_s, energy_gain_j=end.energy_gain_j,
                         penetration_fraction=end.penetration_fraction,
                         collapse_undone=end.collapse_undone_s is not None)


def decided_heights(scene: Scene, settings: SimSettings, spec: QuerySpec, initial: np.ndarray) -> DecidedHeights | None:
    """Early termination by heights, built from the queries asked: when every one of them says
    below which height each body's outcome is decided (fall, any_fall: its centre dropped by the fall
    threshold; bump: below the table top, beside or under it), a body is decided below the lowest
    of those heights. A query that reads where bodies end up (direction, far, rest, final_pose,
    contact) waits for rest instead: None.
    """
    if not settings.early_stop.enabled:
        return None
    asked = [QUERIES[name] for name in sorted(spec.queries)]
    heights = [q.decided_below_z(scene, spec, initial) for q in asked]
    if any(h is None for h in heights):
        return None
    fallen_below_z = np.minimum.reduce(heights)
    # "will anything fall?" is decided by the first box that falls
    first_fall = all(q.decided_by_first_fall for q in asked)
    return DecidedHeights(fallen_below_z_m=fallen_below_z, never_falls=_never_falls(scene, fallen_below_z),
                          stop_at_first_fall=first_fall)


def query_settings(settings: SimSettings, spec: QuerySpec) -> SimSettings:
    """The settings a rollout runs at for these queries: the reading of rest each asks for."""
    early_stop = settings.early_stop
    for name in sorted(spec.queries):
        early_stop = QUERIES[name].early_stop(early_stop, spec)
    return settings if early_stop == settings.early_stop else dataclasses.replace(settings, early_stop=early_stop)


def watches_for(scene: Scene, spec: QuerySpec, world) -> tuple[dict, bool]:
    """The asked queries' step watches (name -> watch), and whether the rollout may end once they
    have all decided (only when every asked query is decided by its watch)."""
    watches = {}
    for name in sorted(spec.queries):
        watch = QUERIES[name].watch(scene, spec, world)
        if watch is not None:
            watches[name] = watch
    return watches, bool(watches) and len(watches) == len(spec.queries)


def _never_falls(scene: Scene, decided_below_z: np.ndarray) -> np.ndarray | None:
    """Bodies that cannot end below their fallen height whatever happens: even resting in their
    lowest way on the lowest surface there is (the floor, also under a table) their centre stays
    above it, with 5% of the smallest extent to spare for contact penetration. A tower's bottom
    blocks are such bodies; without this, early termination waited for them to stop being shoved
    around by a collapse although their outcome (not fallen) was never in doubt.
    """
    support = scene.support
    lowest_surface_z = support.height_m if isinstance(support, Floor) else support.floor_z_m
    if lowest_surface_z is None:  # a table with nothing under it: boxes can drop without limit
        return None
    smallest = smallest_extents_m(scene)
    lowest_rest = np.array([shapes.min_rest_height_m(b.shape) for b in scene.dynamic_objects])
    return decided_below_z < lowest_surface_z + lowest_rest - 0.05 * smallest


def separated_world(scene: Scene, settings, inputs, probe: Probe = NO_PROBE) -> simulation.World:
    """A sample's noisy scene built and de-penetrated (and its objects set down onto their supports
    where the scene's heights are estimates: ``Scene.set_down_m``). Separated in the same body representation
    whatever the preset, so that every preset starts from bit-identical initial scenes (the two
    representations round differently); plain rigid bodies are the default's own, so it simulates
    on in this world."""
    separation = settings.changed(solver={"maximal_coordinates": True, "multibodies_from_aspect": None})
    with probe.part("build"):
        world = simulation.build_world(scene, inputs.positions_m, inputs.masses_kg, separation,
                                       orientations_xyzw=inputs.orientations_xyzw)
    with probe.part("depenetrate"):
        simulation.depenetrate(world, separation)
        simulation.set_down(world, scene.set_down_m)
    return world


def collapse_heights(scene: Scene, settings: SimSettings, initial: np.ndarray) -> np.ndarray | None:
    """Per body, the height below which the collapse steps start (None: the preset has none)."""
    if not settings.collapse.enabled:
        return None
    return initial[:, 2] - settings.collapse.drop_fraction * smallest_extents_m(scene)


def simulate_pushes(scene: Scene, model: ModelConfig, settings: SimSettings, spec: QuerySpec, world: simulation.World,
                    initial: np.ndarray, initial_orn: np.ndarray, masses_kg: np.ndarray, push_direction_rad: float, *,
                    fresh_first: bool = False, record_every: int = 0, deadline_unix_s: float | None = None,
                    probe: Probe = NO_PROBE) -> list[tuple[float, simulation.RolloutEnd]]:
    """One sample's rollouts, one per phi value, from its separated state (``world`` holds it; each
    later phi value, and the first with ``fresh_first``, gets a fresh world built from ``initial``).
    When each rollout may end is built from the queries asked (``decided_heights``, their step
    watches, the reading of rest they need). The one rollout path of predictions and of robot
    questions' variants."""
    decided = decided_heights(scene, settings, spec, initial)
    collapse_below_z = collapse_heights(scene, settings, initial)
    run_settings = query_settings(settings, spec)
    apart = Apart.of(scene, settings, spec, world, decided, record_every)
    ends = []
    for i, phi in enumerate(model.phi_m_s2):
        push = simulation.Push(phi, push_direction_rad, model.push_duration_s)
        if apart is not None:
            try:
                ends.append((phi, apart.simulate(initial, initial_orn, masses_kg, run_settings, push, collapse_below_z,
                                                 probe, deadline_unix_s)))
                continue
            except simulation.IslandsMet:
                pass  # the whole scene, as one world
        if i > 0 or fresh_first or apart is not None:
            with probe.part("build"):
                world = simulation.build_world(scene, initial, masses_kg, settings, orientations_xyzw=initial_orn)
        watches, end_when_watched = watches_for(scene, spec, world)
        ends.append((phi, simulation.simulate(world, scene, run_settings, push, record_every=record_every,
                                              decided=decided, collapse_below_z_m=collapse_below_z, probe=probe,
                                              deadline_unix_s=deadline_unix_s, watches=watches,
                                              end_when_watched=end_when_watched)))
    return ends


@dataclass(frozen=True)
class Apart:
    """A sample's islands (``simulation.islands``), each simulated in a world of its own, the answer
    merged; the whole scene as one world once two of them could have met."""

    scene: Scene
    groups: tuple[np.ndarray, ...]
    decided: DecidedHeights | None
    record_every: int
    whole_step_s: float
    clearance_m: float

    @classmethod
    def of(cls, scene: Scene, settings: SimSettings, spec: QuerySpec, world: simulation.World,
           decided: DecidedHeights | None, record_every: int) -> "Apart | None":
        """The separated ``world``'s islands, or None where the settings keep one world, where there
        is one island (groups that would not step at least twice as coarse apart share one:
        ``islands.by_step``), or where the rollout needs the whole world: step watches (contacts, events:
        any pair may be asked about) and "will anything fall?" (one world ends at the first fall)."""
        if not settings.islands or len(world.dynamic_ids) < 2 or (decided is not None and decided.stop_at_first_fall):
            return None
        if scene.pushes:  # a body pushed later may leave its island
            return None
        if watches_for(scene, spec, world)[0]:
            return None
        velocities = np.array([b.linear_velocity_m_s for b in scene.dynamic_objects], float)
        # the whole world finds contacts this far ahead: islands closer than twice that are one
        clearance = 2 * world.contact_distance_m
        groups = simulation.islands.partition(world, velocities, settings.horizon_for(scene.horizon_s), 2 * clearance)
        if len(groups) < 2:
            return None
        steps = [simulation.time_step_of(_island(scene, group), settings) for group in groups]
        groups = simulation.islands.by_step(groups, steps)
        if len(groups) < 2:
            return None
        return cls(scene, tuple(groups), decided, record_every, world.time_step_s, clearance)

    def simulate(self, initial: np.ndarray, initial_orn: np.ndarray, masses_kg: np.ndarray, settings: SimSettings,
                 push: simulation.Push, collapse_below_z: np.ndarray | None, probe: Probe,
                 deadline_unix_s: float | None) -> simulation.RolloutEnd:
        """The islands side by side, each in a client of its own, the one furthest behind stepped on
        to its next read; raises ``simulation.IslandsMet`` once two could have met."""
        # the whole scene's shapes, in a client beside the islands', for the pairs whose boxes overlap
        gaps = simulation.islands.ShapeGaps(functools.partial(
            simulation.build_world, self.scene, initial, masses_kg, settings, orientations_xyzw=initial_orn,
            slot=simulation.islands.MAX_ISLANDS), self.groups)
        tracks = simulation.islands.Tracks(len(self.groups), settings.horizon_for(self.scene.horizon_s),
                                           self.clearance_m, gaps)
        trials: list = []
        rollouts: list = []
        try:
            for slot, group in enumerate(self.groups):
                island = _island(self.scene, group)
                with probe.part("build"):
                    world = simulation.build_world(island, initial[group], masses_kg[group], settings,
                                                   orientations_xyzw=initial_orn[group], slot=slot)
                every = max(1, round(self.record_every * self.whole_step_s / world.time_step_s)) \
                    if self.record_every else 0
                rollouts.append(simulation.begin(
                    world, island, settings, push, trials, record_every=every, decided=_subset(self.decided, group),
                    collapse_below_z_m=None if collapse_below_z is None else collapse_below_z[group], probe=probe,
                    deadline_unix_s=deadline_unix_s, watches={},
                    on_footprint=functools.partial(tracks.add, slot)))
            ends: list = [None] * len(rollouts)
            reads = [r.reads() for r in rollouts]
            now = [0.0] * len(rollouts)
            while any(end is None for end in ends):
                behind = min((i for i, end in enumerate(ends) if end is None), key=now.__getitem__)
                try:
                    now[behind] = next(reads[behind])
                except StopIteration:
                    ends[behind] = rollouts[behind].end()
                    tracks.ended(behind)
            return _merged(ends, self.groups, len(initial))
        finally:
            gaps.close()
            for trial in trials:
                trial.close()
            for slot in range(1, len(rollouts)):  # slot 0's world is replaced by the next one built
                simulation.pybullet().resetSimulation(physicsClientId=simulation.client(slot))


def _island(scene: Scene, group: np.ndarray) -> Scene:
    """The scene with only the dynamic bodies of ``group`` (and every static one)."""
    statics = tuple(b for b in scene.objects if b.static)
    return dataclasses.replace(scene, objects=statics + tuple(scene.dynamic_objects[i] for i in group))


def _subset(decided: DecidedHeights | None, group: np.ndarray) -> DecidedHeights | None:
    if decided is None:
        return None
    return dataclasses.replace(decided, fallen_below_z_m=decided.fallen_below_z_m[group],
                               never_falls=None if decided.never_falls is None else decided.never_falls[group])


def _merged(ends: list[simulation.RolloutEnd], groups: tuple[np.ndarray, ...], n: int) -> simulation.RolloutEnd:
    """The islands' ends as one rollout's: every body where its island left it; the energy gained
    summed, the deepest penetration, the longest simulated time."""
    positions, orientations, speeds, spins = np.empty((n, 3)), np.empty((n, 4)), np.empty(n), np.empty(n)
    for group, end in zip(groups, ends):
        positions[group], orientations[group] = end.positions_m, end.orientations_xyzw
        speeds[group], spins[group] = end.speeds_m_s, end.spins_rad_s
    undone = [end.collapse_undone_s for end in ends if end.collapse_undone_s is not None]
    return simulation.RolloutEnd(positions, orientations, _merged_trajectory(ends, groups, n),
                                 max(end.simulated_s for end in ends),
                                 energy_gain_j=sum(end.energy_gain_j for end in ends),
                                 penetration_fraction=max(end.penetration_fraction for end in ends),
                                 speeds_m_s=speeds, spins_rad_s=spins, events={},
                                 collapse_undone_s=min(undone) if undone else None)


def _merged_trajectory(ends: list[simulation.RolloutEnd], groups: tuple[np.ndarray, ...], n: int) -> list | None:
    """One frame at every time some island recorded one, each island as its latest frame then."""
    if ends[0].trajectory is None:
        return None
    times = sorted({frame[0] for end in ends for frame in end.trajectory})
    recorded = [[frame[0] for frame in end.trajectory] for end in ends]  # each island's, in order
    frames = []
    for t in times:
        positions, orientations = np.empty((n, 3)), np.empty((n, 4))
        for group, end, at in zip(groups, ends, recorded):
            latest = end.trajectory[bisect.bisect_right(at, t) - 1]  # every island has a frame at t = 0
            positions[group], orientations[group] = latest[1], latest[2]
        frames.append((t, positions, orientations))
    return frames


def lost(task: SampleTask, reason: str) -> SampleOutcome:
    """A sample whose worker was lost twice (``MonteCarlo``'s ``on_lost``)."""
    return failed(task, f"WorkerLost: {reason}", worker_lost=True)


def failed(task: SampleTask, error: str, *, budget_stopped: bool = False, worker_lost: bool = False,
           push_direction_rad: float = float("nan")) -> SampleOutcome:
    """A sample (or a question's variant) that did not run to its end: physics trouble, the budget
    (``budget_stopped``), a worker lost twice (``worker_lost``)."""
    return SampleOutcome(index=task.index, ok=False, error=error, push_direction_rad=push_direction_rad,
                         initial_positions_m=None, initial_orientations_xyzw=None, budget_stopped=budget_stopped,
                         worker_lost=worker_lost)


def _cut_off(task: SampleTask, push_direction_rad: float, why: str) -> SampleOutcome:
    return failed(task, f"BudgetExceeded: {why}", budget_stopped=True, push_direction_rad=push_direction_rad)


def run_sample(task: SampleTask, probe: Probe = NO_PROBE) -> SampleOutcome:
    """Draw, separate and simulate one sample for every phi value; never raises for physics errors.

    ``probe`` watches the parts (benchmarks/time_budget.py); it never changes the outcome.
    """
    if task.deadline_unix_s is not None and time.time() >= task.deadline_unix_s:
        return _cut_off(task, float("nan"), "the budget was spent before this sample started")
    scene, inputs = draw_sample(task.scene, task.model, task.seed)
    sample = task if scene is task.scene else dataclasses.replace(task, scene=scene)  # its drawn properties
    outcome = guarded(sample, inputs.push_direction_rad,
                      lambda: simulate_sample(sample, inputs, separated_world(scene, task.settings, inputs, probe),
                                              probe))
    return kept(sample, outcome, lambda settings: run_sample(task.at(settings), probe))


def kept(task: SampleTask, outcome: SampleOutcome, rerun: Callable[[SimSettings], SampleOutcome]) -> SampleOutcome:
    """What a task returns for its rollout (a prediction's sample, a question's variant): with its
    rerun at the reference beside it when it ended unhealthy and the task asks for that (``Refine``),
    or else its rerun in plain rigid bodies in its place where the settings ask for that
    (``rigid_rerun``). ``rerun(settings)``: the same rollout at other settings."""
    if task.refine is not None and task.refine.why(outcome, task.scene):
        return dataclasses.replace(outcome, refined=rerun(task.refine.settings))
    rigid = rigid_rerun(task.settings, outcome, task.scene)
    if rigid is None:
        return outcome
    return dataclasses.replace(rerun(rigid[0]), rerun_rigid=rigid[1])


def take_refined(keys, outcomes: list[SampleOutcome]) -> tuple[list[SampleOutcome], dict]:
    """The outcomes without the reruns made in their tasks (``Refine``), and those reruns by the
    outcomes' ``keys``: the self-check takes them as its own."""
    reruns = {key: o.refined for key, o in zip(keys, outcomes) if o.refined is not None}
    return [dataclasses.replace(o, refined=None) if o.refined is not None else o for o in outcomes], reruns


def rigid_rerun(settings: SimSettings, outcome: SampleOutcome, scene: Scene) -> tuple[SimSettings, str] | None:
    """Where ``settings`` rerun a multibody rollout that ended unhealthy in plain rigid bodies
    (``SimSettings.rigid_when_unhealthy``): the settings to rerun it at, and why; else None."""
    if not settings.rigid_when_unhealthy or settings.solver.maximal_coordinates:
        return None
    why = outcome.unhealthy(energy_scale_of(scene), HEALTHY_END_PENETRATION_FRACTION, HEALTHY_ENERGY_GAIN_FRACTION)
    if why is None:
        return None
    return settings.changed(f"{settings.name}+rigid", solver={"maximal_coordinates": True},
                            rigid_when_unhealthy=False), why


def simulate_sample(task: SampleTask, inputs, world: simulation.World, probe: Probe = NO_PROBE) -> SampleOutcome:
    """The sample's rollouts, one per phi value, from its separated ``world`` (the scene as it is:
    a prediction's sample, and a robot question's "as is" variant, which is therefore exactly the
    prediction's sample). Raises for physics trouble (``guarded`` turns that into the outcome)."""
    initial, initial_orn = simulation.read_poses(world)
    # the separation's world is in plain rigid bodies: another representation needs a fresh one
    plain = simulation.in_plain_rigid_bodies(task.scene, task.settings, inputs.masses_kg)
    ends = simulate_pushes(task.scene, task.model, task.settings, task.query, world, initial, initial_orn,
                           inputs.masses_kg, inputs.push_direction_rad, fresh_first=not plain,
                           record_every=task.record_every, deadline_unix_s=task.deadline_unix_s, probe=probe)
    results = [rollout_result(task.scene, task.query, initial, initial_orn, phi, end) for phi, end in ends]
    return SampleOutcome(index=task.index, ok=True, error=None, push_direction_rad=inputs.push_direction_rad,
                         initial_positions_m=initial, initial_orientations_xyzw=initial_orn,
                         rollouts=tuple(results), properties=inputs.properties)


def _check_registered(spec: QuerySpec) -> None:
    """Every asked query is known here: one asked in the parent but never registered in this worker
    would otherwise be missing from the answer, or fail somewhere less clear."""
    unknown = sorted(spec.queries - set(QUERIES))
    if unknown:
        raise ConfigError("queries", f"query {unknown[0]!r} is not registered in this process ({os.getpid()}); "
                                     "register it in a module that worker processes import (the pool and Dask "
                                     "import every registered query's module: not one defined in __main__)")


def guarded(task: SampleTask, push_direction_rad: float, simulate) -> SampleOutcome:
    """``simulate()``'s outcome, or the sample's failure as an outcome: the budget (cut off), a
    physics error, or any other exception (one sample's bug must not end the prediction)."""
    try:
        _check_registered(task.query)
        return simulate()
    except BudgetExceeded as exc:
        return _cut_off(task, push_direction_rad, str(exc))
    except PhysicsError as exc:
        error = f"PhysicsError: {exc}"
    except Exception as exc:  # noqa: BLE001 - one sample's bug must not end the prediction
        error = traceback.format_exception_only(type(exc), exc)[-1].strip()
    return failed(task, error, push_direction_rad=push_direction_rad)
