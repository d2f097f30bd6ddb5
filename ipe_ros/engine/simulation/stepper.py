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
from typing import Callable, Iterator

import numpy as np

from ..config import SimSettings
from ..errors import BudgetExceeded
from ..scene.bodies import Scene
from . import health
from .collapse import CollapseTrial, CollapseWatch
from .impacts import ImpactWatch
from .islands import Footprint
from .kicks import Kicks
from .probe import NO_PROBE, Probe
from .settling import Settling
from .steps import StepControl, substeps_for, ticks_allowed
from .termination import DecidedHeights, RestWatch
from .bullet import pybullet
from .world import (World, bounding_boxes, mass_ratio, read_poses, read_state, set_initial_velocities, speeds_of,
                    use_sequential_solver)

#: Seconds between health checks (divergence, non-finite speeds), and between looks for rest and collapse.
HEALTH_PERIOD_S = 0.1
LOOK_PERIOD_S = 0.05
#: A collapse trial begins again only at a look where its steps have made at most this share of the
#: energy that undoes them: an anchor keeps what the steps before it did.
ANCHOR_CREATED_SHARE = 0.1


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
    BudgetExceeded once ``time.time()`` passes ``deadline_unix_s``. ``on_footprint``: shown where the
    bodies were (and how fast their corners moved) at every read (``islands.Tracks.add``).
    """
    trials: list[CollapseTrial] = []  # saved world states, freed however the rollout ends
    try:
        return _simulate(world, scene, settings, push, trials, **kw)
    finally:
        for trial in trials:
            trial.close()


def _simulate(world: World, scene: Scene, settings: SimSettings, push: Push, trials: list, **kw) -> RolloutEnd:
    return _Rollout(world, scene, settings, push, trials, **kw).run()


def begin(world: World, scene: Scene, settings: SimSettings, push: Push, trials: list, **kw) -> "_Rollout":
    """A rollout set up as ``simulate`` sets it up, to be run read by read (``reads()``, then
    ``end()``); the saved states it makes go in ``trials``, for the caller to ``close()``."""
    return _Rollout(world, scene, settings, push, trials, **kw)


class _Rollout:
    """One rollout's loop and the state its parts share: ``run`` steps on the tick grid and, at each
    health check or look, reads the world once and hands that reading to each part in turn."""

    def __init__(self, world: World, scene: Scene, settings: SimSettings, push: Push, trials: list, *,
                 record_every: int = 0, decided: DecidedHeights | None = None,
                 collapse_below_z_m: np.ndarray | None = None, probe: Probe = NO_PROBE,
                 deadline_unix_s: float | None = None, watches: dict | None = None,
                 end_when_watched: bool = False, on_footprint: Callable[[Footprint], None] | None = None):
        self.world, self.settings, self.trials, self.probe = world, settings, trials, probe
        #: shown where the bodies were at each read (islands.Footprint), for islands simulated apart
        self.on_footprint = on_footprint
        self.deadline_unix_s, self.end_when_watched = deadline_unix_s, end_when_watched
        self.p = p = pybullet()
        self.cid = world.client
        self.dt = dt = world.time_step_s
        horizon_s = settings.horizon_for(scene.horizon_s)
        self.total_ticks = int(round(horizon_s / dt))
        self.gravity = gravity = np.asarray(scene.gravity_m_s2, float)
        self.g = g = float(np.linalg.norm(gravity))
        set_initial_velocities(world, scene)
        self.energy = health.EnergyWatch(world.masses_kg, world.inertia_kg_m2, gravity)
        positions, orientations, initial_velocities = read_state(world)
        initial_energy = self.energy.energy(positions, orientations, initial_velocities[:, 0], initial_velocities[:, 1])
        self.push_ticks = 0
        if push.acceleration_m_s2 > 0:
            self.push_ticks = int(round(push.duration_s / dt))
            tilt = push.acceleration_m_s2 * np.array([math.cos(push.direction_rad), math.sin(push.direction_rad), 0.0])
            p.setGravity(*(gravity - tilt).tolist(), physicsClientId=self.cid)
        else:
            self.energy.reference(initial_energy)
        fastest_start_m_s = float(np.max(speeds_of(initial_velocities)[0], initial=0.0))
        #: the scene's known pushes after t = 0: (tick, body handle, velocity change), in time order
        self.kicks = Kicks(scene, world, dt)
        fastest_start_m_s += self.kicks.speed_m_s  # a pushed body may move as fast as its start and its pushes
        self.limit = health.speed_limit_m_s(g, horizon_s, push.acceleration_m_s2, push.duration_s) \
            + 2 * fastest_start_m_s
        self.record_every = record_every
        self.trajectory: list | None = [] if record_every > 0 else None
        if self.trajectory is not None:
            self.trajectory.append((0.0, *read_poses(world)))
        self.health_every = max(1, int(round(HEALTH_PERIOD_S / dt)))
        self.end_phase_ticks = int(round(settings.collapse.fine_before_end_s / dt))
        self.fine_from_tick = self.total_ticks - self.end_phase_ticks
        self.ending = False  # at rest early: only the end phase is left
        self.look_every = max(1, int(round(LOOK_PERIOD_S / dt)))

        self.settling = Settling(settings, dt)
        self.half_diagonals_m = np.array([np.linalg.norm(b.extents_m) / 2 for b in scene.dynamic_objects])
        self.smallest = np.array([b.smallest_extent_m for b in scene.dynamic_objects])
        self.collapse = CollapseWatch(settings, collapse_below_z_m, self.smallest)
        self.quiet_m_s = settings.collapse.quiet_sizes_per_s * world.scale_m
        self.created_limit_j = settings.collapse.max_created_energy_fraction * health.energy_scale_j(scene)
        self.trial: CollapseTrial | None = None  # the collapse steps' start, while they are on trial
        self.undone_s = None
        self.full_iterations = settings.iterations_for(mass_ratio(world.masses_kg))  # as the world was built
        self.collapse_iterations = settings.iterations_for(mass_ratio(world.masses_kg),
                                                           settings.collapse.solver_iterations)
        self.steps = StepControl(settings, world)
        self.rest = RestWatch(settings.early_stop, world.scale_m,  # never at rest before the last push
                              max(self.push_ticks * dt, settings.early_stop.min_time_s,
                                  self.kicks.last_tick * dt), decided,
                              len(scene.dynamic_objects), self.half_diagonals_m)
        self.travel_substeps = substeps_for(fastest_start_m_s + g * self.look_every * dt, settings, world) \
            if fastest_start_m_s else 1
        self.fastest_m_s = fastest_start_m_s  # as of the last read: what the end phase's substeps start from
        self.watches = watches or {}
        for watch in self.watches.values():
            watch.start(world)
        start_speeds, start_spins = speeds_of(initial_velocities)
        self._footprint(0.0, start_speeds + start_spins * self.half_diagonals_m, positions, orientations)
        self.tick = 0
        self.pybullet_steps = 0  # taken so far (what a collapse trial's anchors count)
        #: a world that may bounce: the direct solver for its impacts only (simulation/impacts.py), or
        #: for the whole rollout but its end phase (``solver.direct_solver_for_impacts_only`` off)
        self.impacts = ImpactWatch(world, scene, push.acceleration_m_s2) \
            if world.direct_solver and settings.solver.direct_solver_for_impacts_only else None
        self.solver_switch_due = world.direct_solver and self.impacts is None
        self.end_phase_due = settings.collapse.end_substeps > 1 or settings.collapse.end_travel_fraction is not None
        if self.settling.ticks or self.travel_substeps > 1:
            self.steps.set(1, max(self.travel_substeps, self.settling.substeps if self.settling.ticks else 1))

    def run(self) -> RolloutEnd:
        for _ in self.reads():
            pass
        return self.end()

    def reads(self) -> Iterator[float]:
        """The loop, pausing after every read of the world (at the simulated time it yields), so that
        islands can run side by side (``begin``); ``end()`` once it is over."""
        if self.on_footprint is not None:  # other worlds may have been built meanwhile
            self.steps.reapply()
        while self.tick < self.total_ticks:
            previous = self._step()
            if self._watched():
                break
            self._after_step(previous)
            look_due = (self.rest.enabled or self.collapse.active) and _crossed(self.tick, previous, self.look_every)
            health_due = _crossed(self.tick, previous, self.health_every) or self.tick == self.total_ticks
            if look_due or health_due:
                if self._look(look_due, health_due):
                    break
                yield self.tick * self.dt
                if self.on_footprint is not None:  # other worlds may have stepped meanwhile
                    self.steps.reapply()

    # -- between looks ---------------------------------------------------------------------------------
    def _step(self) -> int:
        """One step (of one tick or, coarse, of several) in its substeps; returns the tick it began at."""
        if self.deadline_unix_s is not None and time.time() > self.deadline_unix_s:
            raise BudgetExceeded(f"the compute budget ran out at t = {self.tick * self.dt:.3f} s of the rollout")
        if self.kicks.apply(self.tick):  # the push put energy in, and the bodies may close fast now
            self.energy.reference(self._energy_now_j())
            if self.impacts is not None:
                self.impacts.quiet_s = 0.0
        # the push ends exactly on its tick, and the last step ends exactly on the horizon
        step_ticks = min(self.steps.ticks, self.total_ticks - self.tick)
        if step_ticks != self.steps.ticks:  # a shorter last step (coarse steps only)
            self.p.setTimeStep(self.dt * step_ticks, physicsClientId=self.cid)
        # the end on the sequential-impulse solver: the direct one (for bounces) leaves resting
        # bodies sunk into each other (config.SolverSettings.direct_solver_for_restitution)
        if self.end_phase_due and self.tick >= self.fine_from_tick:
            self.end_phase_due = False
            self.steps.end_phase(self.fastest_m_s)
        if self.solver_switch_due and self.tick >= self.fine_from_tick:
            self.solver_switch_due = False
            use_sequential_solver(self.world)
        settling_now = self.settling.covers(self.tick)
        substeps = self.steps.substeps
        # each pybullet step on the solver it needs (a bouncy world), and shown to the probe when one
        # watches; otherwise pybullet stepped directly, the usual case
        choose = None if self.impacts is None else self.impacts.choose
        phase = None if self.probe is NO_PROBE else \
            "settle" if settling_now else "collapse" if self.collapse.collapsing else "fine"
        step, cid, step_s = self.p.stepSimulation, self.cid, self.dt * step_ticks / substeps
        for _ in range(substeps):
            if choose is not None:
                choose(step_s)
            if phase is None:
                step(physicsClientId=cid)
            else:
                self.probe.step(phase, self._step_simulation)
        self.pybullet_steps += substeps
        if settling_now and self.tick + 1 == self.settling.ticks:
            self.steps.set(1, self.travel_substeps)
        previous, self.tick = self.tick, self.tick + step_ticks
        return previous

    def _energy_now_j(self) -> float:
        positions, orientations, velocities = read_state(self.world)
        return self.energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1])

    def _step_simulation(self) -> None:
        self.p.stepSimulation(physicsClientId=self.cid)

    def _use_iterations(self, iterations: int) -> None:
        self.p.setPhysicsEngineParameter(numSolverIterations=iterations, physicsClientId=self.cid)

    def _watched(self) -> bool:
        """Show the world to the watches; True when they have all decided and the rollout may end there."""
        if not self.watches:
            return False
        for watch in self.watches.values():
            watch.after_step(self.world, self.tick * self.dt)
        if (self.end_when_watched or self.trial is not None) and all(w.decided for w in self.watches.values()):
            if self.trial is not None:
                # what the watches saw stands, and with it the collapse steps that got there:
                # a question that ends at its event and one that runs on must answer it alike
                self.trial.close()
                self.trial = None
            if self.end_when_watched:
                return True
        return False

    def _after_step(self, previous: int) -> None:
        """The push's end (gravity upright again, the energy's reference taken) and the recorded frames."""
        if self.tick == self.push_ticks:
            self.p.setGravity(*self.gravity.tolist(), physicsClientId=self.cid)
            self.energy.reference(self._energy_now_j())
        if self.trajectory is not None and _crossed(self.tick, previous, self.record_every):
            self.trajectory.append((self.tick * self.dt, *read_poses(self.world)))

    # -- at a health check or a look ---------------------------------------------------------------------
    def _look(self, look_due: bool, health_due: bool) -> bool:
        """Read the world once and hand it to each part; True when the rollout ends here (at rest)."""
        positions, orientations, velocities = read_state(self.world)  # one read serves every part
        energy_now_j = self.energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1])
        if self.trial is not None and look_due and not self.ending and self.tick <= self.fine_from_tick:
            created_j = self.energy.created_j(energy_now_j)
            if not created_j <= self.created_limit_j:
                positions, orientations, velocities, energy_now_j = self._undo_trial()
            elif self._anchor_due(created_j):
                self._begin_trial((positions, orientations, velocities, energy_now_j))
        speeds, spins = speeds_of(velocities)
        if health_due:
            health.check_speeds(speeds, self.limit, self.tick * self.dt)
        # the fastest any corner can get until the next read
        period_ticks = self.look_every if look_due else self.health_every
        corner_speeds = speeds + spins * self.half_diagonals_m
        fastest_corner_m_s = float(corner_speeds.max())
        self._footprint(self.tick * self.dt, corner_speeds, positions, orientations)
        fastest_m_s = fastest_corner_m_s + self.g * period_ticks * self.dt
        self.travel_substeps = substeps_for(fastest_m_s, self.settings, self.world)
        self.fastest_m_s = fastest_m_s
        self.steps.end_speed(fastest_m_s)
        self.energy.look(energy_now_j)
        if not look_due:
            if not self.settling.covers(self.tick):
                self.steps.set(self.steps.ticks, self.travel_substeps if self.steps.ticks == 1 else 1)
            self.steps.find_contacts_ahead(fastest_m_s)
            return False
        heights = positions[:, 2]
        self._collapse_look(heights, fastest_corner_m_s > self.quiet_m_s, fastest_m_s,
                            (positions, orientations, velocities, energy_now_j))
        self.steps.find_contacts_ahead(fastest_m_s)
        return self._at_rest(speeds, spins, heights)

    def _footprint(self, t_s: float, corner_speeds_m_s: np.ndarray, positions_m, orientations_xyzw) -> None:
        if self.on_footprint is not None:
            boxes = bounding_boxes(self.world)
            self.on_footprint(Footprint(t_s, boxes[:, 0], boxes[:, 1], np.asarray(corner_speeds_m_s, float),
                                        np.array(positions_m, float), np.array(orientations_xyzw, float)))

    def _undo_trial(self) -> tuple:
        """The collapse steps made energy (NaN: they diverged): back to the look where they began,
        which then goes on as if they had never been taken (config.CollapseSettings)."""
        state, parts = self.trial.restore(self.trajectory)
        self.tick, self.undone_s = self.trial.tick, self.trial.tick * self.dt
        self.energy, self.rest, self.watches = parts["energy"], parts["rest"], parts["watches"]
        self.steps.restore(parts["steps"])
        self.trial.close()
        self.trial = None
        self.collapse.end()
        self._use_iterations(self.full_iterations)  # the step's residual came back with the step
        return state

    def _begin_trial(self, state: tuple) -> None:
        """Collapse steps on trial from this look: everything it read and the loop holds, as it is
        now, to go back to (an earlier trial, whose steps made next to no energy up to here, is closed)."""
        if self.trial is not None:
            self.trial.close()
        positions, orientations, velocities, energy_now_j = state
        self.trial = CollapseTrial(self.world, self.tick, (positions.copy(), orientations.copy(),
                                                           velocities.copy(), energy_now_j),
                                   {"energy": self.energy, "rest": self.rest, "watches": self.watches,
                                    "steps": self.steps.snapshot()},
                                   0 if self.trajectory is None else len(self.trajectory), self.pybullet_steps)
        self.trials.append(self.trial)

    def _anchor_due(self, created_j: float) -> bool:
        """The trial has taken ``collapse.anchor_after_steps`` pybullet steps and made at most
        ``ANCHOR_CREATED_SHARE`` of the energy that would undo it: begin it again here (before the
        end phase, as a trial itself: nothing is undone after it begins)."""
        after = self.settings.collapse.anchor_after_steps
        return after is not None and self.tick < self.fine_from_tick \
            and created_j <= ANCHOR_CREATED_SHARE * self.created_limit_j \
            and self.pybullet_steps - self.trial.pybullet_steps >= after

    def _collapse_look(self, heights: np.ndarray, moving: bool, fastest_m_s: float, state: tuple) -> None:
        """The collapse steps: begun (on trial while the fine steps could still follow) once something
        has clearly fallen, ended once the fall is over; and the step they allow."""
        if self.collapse.collapsing and not moving and self.collapse.still_standing(heights):
            self.collapse.settled(heights)  # the fall is over: fine steps and the full solver again
            if self.trial is not None:
                self.trial.close()
                self.trial = None
            self._use_iterations(self.full_iterations)
            self.steps.solve_to(None)
        if self.collapse.look(self.tick, max(self.push_ticks, self.settling.ticks), heights, moving):
            if self.tick < self.fine_from_tick:
                self._begin_trial(state)
            if self.settings.collapse.solver_iterations is not None:
                self._use_iterations(self.collapse_iterations)
            self.steps.solve_to(self.settings.collapse.residual_threshold)
        if self.collapse.collapsing:
            # coarse, but no body may travel more than the travel limit per step, and none while a
            # body is deep inside another: the solver pushes it out by a fraction per step, so coarse
            # steps leave it there (a heavy body on a light one, a landing at a coarse step)
            ticks = self.collapse.coarse_factor(ticks_allowed(fastest_m_s, self.settings, self.world,
                                                              self.settings.collapse.max_travel_fraction))
            deep = ticks > 1 and self.tick < self.fine_from_tick and health.deeper_than(
                self.world, self.smallest, self.settings.early_stop.max_penetration_fraction, detect=False)
            if ticks > 1 and (self.tick >= self.fine_from_tick or deep):
                ticks = 1
            self.steps.set(ticks, self.travel_substeps if ticks == 1 else 1)
        elif not self.settling.covers(self.tick):
            self.steps.set(1, self.travel_substeps)

    def _at_rest(self, speeds: np.ndarray, spins: np.ndarray, heights: np.ndarray) -> bool:
        """True when everything whose outcome is open has come to rest out of the others."""
        if not (self.rest.enabled and not self.ending and self.rest.should_stop(self.tick * self.dt, speeds, spins,
                                                                                heights)):
            return False
        # only bodies whose outcome is still open must be out of the others
        if not health.deeper_than(self.world, self.smallest, self.settings.early_stop.max_penetration_fraction,
                                  self.rest.undecided):
            if not self.solver_switch_due:
                return True
            # at rest on the direct solver, which leaves resting bodies sunk a little into each
            # other (a bouncy block 3 mm into the one below, read as 8.1 cm fallen against a
            # threshold of 8.0): end as at the horizon, on the sequential solver for the end phase
            # (at full steps: the half steps are for ends in mid-collapse, and nothing moves here)
            self.ending, self.end_phase_due = True, False
            self.fine_from_tick = self.tick
            self.total_ticks = min(self.total_ticks, self.tick + self.end_phase_ticks)
            return False
        self.collapse.end()  # at rest but still inside another body: push it out at the fine step
        self.steps.set(1, self.travel_substeps)
        return False

    def end(self) -> RolloutEnd:
        positions, orientations, velocities = read_state(self.world)
        positions, orientations = positions.copy(), orientations.copy()  # RolloutEnd's own, contiguous
        health.check_final_poses(positions, orientations)
        self.energy.look(self.energy.energy(positions, orientations, velocities[:, 0], velocities[:, 1]))
        # the bodies whose final pose the answer reads: not those already decided by height (a body that
        # has fallen, or can never fall, is answered whatever pose it ends in mid-collapse)
        read = self.rest.undecided if self.rest.needs_heights else None
        speeds, spins = speeds_of(velocities)
        self._footprint(self.tick * self.dt, speeds + spins * self.half_diagonals_m, positions, orientations)
        return RolloutEnd(positions, orientations, self.trajectory, self.tick * self.dt,
                          energy_gain_j=self.energy.max_gain_j,
                          penetration_fraction=health.deepest_penetration_fraction(self.world, self.smallest, read),
                          speeds_m_s=np.array(speeds, float), spins_rad_s=np.array(spins, float),
                          events={name: w.events() for name, w in self.watches.items()},
                          collapse_undone_s=self.undone_s)
