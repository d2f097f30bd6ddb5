"""The rollout loop: steps on a grid of ticks and hands each look to its part.

Time runs on a grid of ticks of the world's step dt. A coarse (collapse) step spans several ticks,
so every look, every recorded frame and the end of the push fall on the same times whatever the
step. The parts, each in its own module:

- settling.py: the first ticks in finer substeps;
- collapse.py: coarser steps once something has clearly fallen;
- steps.py: the step in force, within the travel limit (fast bodies get substeps);
- termination.py: ending the rollout once nothing can change any more;
- health.py: divergence and non-finite states as a PhysicsError, and the rollout's numerical health
  (energy gained after the inputs stopped, penetration left at the end).

The push (phi) is simulated in the support's own frame: while the support accelerates at ``a`` every
free body feels the inertial force ``-m a``, which is exactly a tilt of gravity by ``-a`` for the
push's duration. Static geometry (table, walls) moves with the support and so stays put in its frame,
and all outputs are in that frame. After the push the support moves uniformly, and its frame is
inertial again. With phi = 0 nothing about the push is simulated.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..config import SimSettings
from ..errors import BudgetExceeded
from ..scene import Scene
from . import health
from .collapse import CollapseTrial, CollapseWatch
from .probe import NO_PROBE, Probe
from .settling import Settling
from .steps import StepControl, substeps_for, ticks_allowed
from .termination import DecidedHeights, RestWatch
from .world import (World, mass_ratio, pybullet, read_poses, read_state, set_initial_velocities, speeds_of,
                    use_sequential_solver)

#: Seconds between health checks (divergence, non-finite speeds), and between looks for rest and collapse.
HEALTH_PERIOD_S = 0.1
LOOK_PERIOD_S = 0.05


@dataclass(frozen=True)
class Push:
    """The latent push: the support's horizontal acceleration for a while (phi, direction, duration)."""

    acceleration_m_s2: float = 0.0
    direction_rad: float = 0.0
    duration_s: float = 0.2


@dataclass(frozen=True)
class RolloutEnd:
    """Final poses of the dynamic bodies (centres of mass), the recorded trajectory (if asked), the
    simulated time and the rollout's numerical health.

    trajectory: (time_s, positions, orientations) every ``record_every`` ticks, or None.
    simulated_s: below the horizon when early termination ended the rollout.
    energy_gain_j: the most energy gained beyond what the push and the initial velocities put in.
    penetration_fraction: the deepest any body whose final pose the answer reads ends inside another
        or the support, as a fraction of its smallest extent (bodies already decided by height, when
        only fall / any_fall / bump are asked, are answered whatever pose they end in).
    """

    positions_m: np.ndarray
    orientations_xyzw: np.ndarray
    trajectory: list | None
    simulated_s: float
    energy_gain_j: float = 0.0
    penetration_fraction: float = 0.0
    speeds_m_s: np.ndarray | None = None  # (n,) linear speeds at the end
    spins_rad_s: np.ndarray | None = None  # (n,) angular speeds at the end
    events: dict | None = None  # what each watch recorded, by the name it was given under
    #: collapse steps made energy and were undone: the rollout went back to where they began, at this
    #: time, and ran on without them (None: they were kept, or never taken)
    collapse_undone_s: float | None = None


def _crossed(tick: int, previous: int, period: int) -> bool:
    """This step crossed a multiple of ``period`` ticks."""
    return tick // period > previous // period


def simulate(world: World, scene: Scene, settings: SimSettings, push: Push, **kw) -> RolloutEnd:
    """Run a built world (bodies at rest; the scene's initial velocities are given here) to the
    horizon, or until early termination ends it.

    ``decided``: outcomes already settled by height (only fall / any_fall asked); ``collapse_below_z_m``:
    heights that start the collapse steps (when ``settings.collapse`` is enabled). ``watches``:
    name -> query.StepWatch, each shown the world at t = 0 and after every step; with
    ``end_when_watched`` the rollout ends once every watch has decided. Raises
    PhysicsError on non-finite states or speeds above ``health.speed_limit_m_s``, and
    BudgetExceeded once ``time.time()`` passes ``deadline_unix_s``.
    """
    trials: list[CollapseTrial] = []  # saved world states, freed however the rollout ends
    try:
        return _simulate(world, scene, settings, push, trials, **kw)
    finally:
        for trial in trials:
            trial.close()


def _simulate(world: World, scene: Scene, settings: SimSettings, push: Push, trials: list, *,
              record_every: int = 0, decided: DecidedHeights | None = None,
              collapse_below_z_m: np.ndarray | None = None, probe: Probe = NO_PROBE,
              deadline_unix_s: float | None = None, watches: dict | None = None,
              end_when_watched: bool = False) -> RolloutEnd:
    p = pybullet()
    cid = world.client
    dt = world.time_step_s
    horizon_s = settings.horizon_for(scene.horizon_s)
    total_ticks = int(round(horizon_s / dt))
    gravity = np.asarray(scene.gravity_m_s2, float)
    g = float(np.linalg.norm(gravity))
    set_initial_velocities(world, scene)
    energy = health.EnergyWatch(world.masses_kg, world.inertia_kg_m2, gravity)
    positions, orientations, initial_velocities = read_state(world)
    initial_energy = energy.energy(positions, orientations, initial_velocities[:, 0], initial_velocities[:, 1])
    push_ticks = 0
    if push.acceleration_m_s2 > 0:
        push_ticks = int(round(push.duration_s / dt))
        tilt = push.acceleration_m_s2 * np.array([math.cos(push.direction_rad), math.sin(push.direction_rad), 0.0])
        p.setGravity(*(gravity - tilt).tolist(), physicsClientId=cid)
    else:
        energy.reference(initial_energy)
    fastest_start_m_s = float(np.max(speeds_of(initial_velocities)[0], initial=0.0))
    limit = health.speed_limit_m_s(g, horizon_s, push.acceleration_m_s2, push.duration_s) + 2 * fastest_start_m_s
    trajectory: list | None = [] if record_every > 0 else None
    if trajectory is not None:
        trajectory.append((0.0, *read_poses(world)))
    health_every = max(1, int(round(HEALTH_PERIOD_S / dt)))
    end_phase_ticks = int(round(settings.collapse.fine_before_end_s / dt))
    fine_from_tick = total_ticks - end_phase_ticks
    ending = False  # at rest early: only the end phase is left
    look_every = max(1, int(round(LOOK_PERIOD_S / dt)))

    settling = Settling(settings, dt)
    half_diagonals_m = np.array([np.linalg.norm(b.extents_m) / 2 for b in scene.dynamic_objects])
    smallest = np.array([b.smallest_extent_m for b in scene.dynamic_objects])
    collapse = CollapseWatch(settings, collapse_below_z_m, smallest)
    quiet_m_s = settings.collapse.quiet_sizes_per_s * world.scale_m
    created_limit_j = settings.collapse.max_created_energy_fraction * health.energy_scale_j(scene)
    trial: CollapseTrial | None = None  # the collapse steps' start, while they are on trial
    undone_s = None
    full_iterations = settings.iterations_for(mass_ratio(world.masses_kg))  # as the world was built
    collapse_iterations = settings.iterations_for(mass_ratio(world.masses_kg), settings.collapse.solver_iterations)

    def use_iterations(iterations: int) -> None:
        p.setPhysicsEngineParameter(numSolverIterations=iterations, physicsClientId=cid)

    steps = StepControl(settings, world)
    rest = RestWatch(settings.early_stop, world.scale_m, max(push_ticks * dt, settings.early_stop.min_time_s),
                     decided, len(scene.dynamic_objects))
    travel_substeps = substeps_for(fastest_start_m_s + g * look_every * dt, settings, world) if fastest_start_m_s else 1

    def step() -> None:
        p.stepSimulation(physicsClientId=cid)

    watches = watches or {}
    for watch in watches.values():
        watch.start(world)
    tick = 0
    solver_switch_due = world.direct_solver
    end_phase_due = settings.collapse.end_substeps > 1
    if settling.ticks or travel_substeps > 1:
        steps.set(1, max(travel_substeps, settling.substeps if settling.ticks else 1))
    while tick < total_ticks:
        if deadline_unix_s is not None and time.time() > deadline_unix_s:
            raise BudgetExceeded(f"the compute budget ran out at t = {tick * dt:.3f} s of the rollout")
        # the push ends exactly on its tick, and the last step ends exactly on the horizon
        step_ticks = min(steps.ticks, total_ticks - tick)
        if step_ticks != steps.ticks:  # a shorter last step (coarse steps only)
            p.setTimeStep(dt * step_ticks, physicsClientId=cid)
        # the end on the sequential-impulse solver: the direct one (for bounces) leaves resting
        # bodies sunk into each other (config.SolverSettings.direct_solver_for_restitution)
        if end_phase_due and tick >= fine_from_tick:
            end_phase_due = False
            steps.end_phase()
        if solver_switch_due and tick >= fine_from_tick:
            solver_switch_due = False
            use_sequential_solver(world)
        settling_now = settling.covers(tick)
        phase = "settle" if settling_now else "collapse" if collapse.collapsing else "fine"
        for _ in range(steps.substeps):
            probe.step(phase, step)
        if settling_now and tick + 1 == settling.ticks:
            steps.set(1, travel_substeps)
        previous, tick = tick, tick + step_ticks
        if watches:
            for watch in watches.values():
                watch.after_step(world, tick * dt)
            if (end_when_watched or trial is not None) and all(w.decided for w in watches.values()):
                if trial is not None:
                    # what the watches saw stands, and with it the collapse steps that got there:
                    # a question that ends at its event and one that runs on must answer it alike
                    trial.close()
                    trial = None
                if end_when_watched:
                    break
        if tick == push_ticks:
            p.setGravity(*gravity.tolist(), physicsClientId=cid)
            positions, orientations, velocities = read_state(world)
            energy.reference(energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1]))
        if trajectory is not None and _crossed(tick, previous, record_every):
            trajectory.append((tick * dt, *read_poses(world)))
        look_due = (rest.enabled or collapse.active) and _crossed(tick, previous, look_every)
        health_due = _crossed(tick, previous, health_every) or tick == total_ticks
        if not (look_due or health_due):
            continue
        positions, orientations, velocities = read_state(world)  # one read serves every part
        energy_now_j = energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1])
        if trial is not None and look_due and not ending and tick <= fine_from_tick \
                and not energy.created_j(energy_now_j) <= created_limit_j:
            # the collapse steps made energy (NaN: they diverged): back to the look where they
            # began, which then goes on as if they had never been taken (config.CollapseSettings)
            (positions, orientations, velocities, energy_now_j), parts = trial.restore(trajectory)
            tick, undone_s = trial.tick, trial.tick * dt
            energy, rest, watches = parts["energy"], parts["rest"], parts["watches"]
            steps.restore(parts["steps"])
            trial.close()
            trial = None
            collapse.end()
            use_iterations(full_iterations)
        speeds, spins = speeds_of(velocities)
        if health_due:
            health.check_speeds(speeds, limit, tick * dt)
        # the fastest any corner can get until the next read
        period_ticks = look_every if look_due else health_every
        fastest_corner_m_s = float((speeds + spins * half_diagonals_m).max())
        fastest_m_s = fastest_corner_m_s + g * period_ticks * dt
        travel_substeps = substeps_for(fastest_m_s, settings, world)
        energy.look(energy_now_j)
        if not look_due:
            if not settling.covers(tick):
                steps.set(steps.ticks, travel_substeps if steps.ticks == 1 else 1)
            steps.find_contacts_ahead(fastest_m_s)
            continue
        heights = positions[:, 2]
        moving = fastest_corner_m_s > quiet_m_s
        if collapse.collapsing and not moving and collapse.still_standing(heights):
            collapse.settled(heights)  # the fall is over: fine steps and the full solver again
            if trial is not None:
                trial.close()
                trial = None
            use_iterations(full_iterations)
        if collapse.look(tick, max(push_ticks, settling.ticks), heights, moving):
            if tick < fine_from_tick:  # on trial: everything this look read and holds, as it is now
                trial = CollapseTrial(world, tick, (positions.copy(), orientations.copy(), velocities.copy(),
                                                    energy_now_j),
                                      {"energy": energy, "rest": rest, "watches": watches, "steps": steps.snapshot()},
                                      0 if trajectory is None else len(trajectory))
                trials.append(trial)
            if settings.collapse.solver_iterations is not None:
                use_iterations(collapse_iterations)
        if collapse.collapsing:
            # coarse, but no body may travel more than the travel limit per step, and none while a
            # body is deep inside another: the solver pushes it out by a fraction per step, so coarse
            # steps leave it there (a heavy body on a light one, a landing at a coarse step)
            ticks = collapse.coarse_factor(ticks_allowed(fastest_m_s, settings, world))
            deep = ticks > 1 and tick < fine_from_tick and health.deeper_than(
                world, smallest, settings.early_stop.max_penetration_fraction, detect=False)
            if ticks > 1 and (tick >= fine_from_tick or deep):
                ticks = 1
            steps.set(ticks, travel_substeps if ticks == 1 else 1)
        elif not settling.covers(tick):
            steps.set(1, travel_substeps)
        steps.find_contacts_ahead(fastest_m_s)
        if rest.enabled and not ending and rest.should_stop(tick * dt, speeds, spins, heights):
            # only bodies whose outcome is still open must be out of the others
            if not health.deeper_than(world, smallest, settings.early_stop.max_penetration_fraction, rest.undecided):
                if not solver_switch_due:
                    break
                # at rest on the direct solver, which leaves resting bodies sunk a little into each
                # other (a bouncy block 3 mm into the one below, read as 8.1 cm fallen against a
                # threshold of 8.0): end as at the horizon, on the sequential solver for the end phase
                # (at full steps: the half steps are for ends in mid-collapse, and nothing moves here)
                ending, end_phase_due = True, False
                fine_from_tick = tick
                total_ticks = min(total_ticks, tick + end_phase_ticks)
                continue
            collapse.end()  # at rest but still inside another body: push it out at the fine step
            steps.set(1, travel_substeps)
    positions, orientations, velocities = read_state(world)
    positions, orientations = positions.copy(), orientations.copy()  # RolloutEnd's own, contiguous
    health.check_final_poses(positions, orientations)
    energy.look(energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1]))
    # the bodies whose final pose the answer reads: not those already decided by height (a body that
    # has fallen, or can never fall, is answered whatever pose it ends in mid-collapse)
    read = rest.undecided if rest.needs_heights else None
    speeds, spins = speeds_of(velocities)
    return RolloutEnd(positions, orientations, trajectory, tick * dt, energy_gain_j=energy.max_gain_j,
                      penetration_fraction=health.deepest_penetration_fraction(world, smallest, read),
                      speeds_m_s=np.array(speeds, float), spins_rad_s=np.array(spins, float),
                      events={name: w.events() for name, w in watches.items()}, collapse_undone_s=undone_s)
