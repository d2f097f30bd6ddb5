"""The rollout loop: steps on a grid of ticks and hands each look to its part.

Time runs on a grid of ticks of the world's step dt. A coarse (collapse) step spans several ticks,
so every look, every recorded frame and the end of the push fall on the same times whatever the
step. The parts, each in its own module:

- settling.py: the first ticks in finer substeps;
- collapse.py: coarser steps once something has clearly fallen;
- termination.py: ending the rollout once nothing can change any more;
- health.py: divergence and non-finite states as a PhysicsError.

The push (phi) is simulated in the support's own frame: while the support accelerates at ``a`` every
free body feels the inertial force ``-m a``, which is exactly a tilt of gravity by ``-a`` for the
push's duration. Static geometry (table, walls) moves with the support and so stays put in its frame,
and all outputs are in that frame. After the push the support moves uniformly, and its frame is
inertial again. With phi = 0 nothing about the push is simulated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import SimSettings
from ..scene import Scene
from . import health
from .collapse import CollapseSteps
from .probe import NO_PROBE, Probe
from .settling import Settling
from .termination import DecidedHeights, RestWatch
from .world import World, pybullet, read_poses, read_velocities

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
    """Final poses of the dynamic boxes, the recorded trajectory (if asked) and the simulated time.

    trajectory: (time_s, positions, orientations) every ``record_every`` ticks, or None.
    simulated_s: below the horizon when early termination ended the rollout.
    """

    positions_m: np.ndarray
    orientations_xyzw: np.ndarray
    trajectory: list | None
    simulated_s: float


def _crossed(tick: int, previous: int, period: int) -> bool:
    """This step crossed a multiple of ``period`` ticks."""
    return tick // period > previous // period


def simulate(world: World, scene: Scene, settings: SimSettings, push: Push, *, record_every: int = 0,
             decided: DecidedHeights | None = None, collapse_below_z_m: np.ndarray | None = None,
             probe: Probe = NO_PROBE) -> RolloutEnd:
    """Run a built world to the horizon or until early termination ends it.

    ``decided``: outcomes already settled by height (only fall / any_fall asked); ``collapse_below_z_m``:
    heights that start the collapse steps (when ``settings.collapse`` is enabled). Raises
    PhysicsError on non-finite states or speeds above ``health.speed_limit_m_s``.
    """
    p = pybullet()
    cid = world.client
    dt = world.time_step_s
    total_ticks = int(round(settings.horizon_s / dt))
    gravity = np.asarray(scene.gravity_m_s2, float)
    g = float(np.linalg.norm(gravity))
    push_ticks = 0
    if push.acceleration_m_s2 > 0:
        push_ticks = int(round(push.duration_s / dt))
        tilt = push.acceleration_m_s2 * np.array([math.cos(push.direction_rad), math.sin(push.direction_rad), 0.0])
        p.setGravity(*(gravity - tilt).tolist(), physicsClientId=cid)
    limit = health.speed_limit_m_s(g, settings.horizon_s, push.acceleration_m_s2, push.duration_s)
    trajectory: list | None = [] if record_every > 0 else None
    if trajectory is not None:
        trajectory.append((0.0, *read_poses(world)))
    health_every = max(1, int(round(HEALTH_PERIOD_S / dt)))
    look_every = max(1, int(round(LOOK_PERIOD_S / dt)))

    settling = Settling(settings, world)
    half_diagonals_m = np.array([np.linalg.norm(b.extents_m) / 2 for b in scene.dynamic_boxes])
    collapse = CollapseSteps(settings, world, collapse_below_z_m, half_diagonals_m, g, look_every)
    rest = RestWatch(settings.early_stop, world.scale_m, max(push_ticks * dt, settings.early_stop.min_time_s),
                     decided, len(scene.dynamic_boxes))

    def step() -> None:
        p.stepSimulation(physicsClientId=cid)

    tick = 0
    settling.begin()
    while tick < total_ticks:
        # the push ends exactly on its tick, and the last step ends exactly on the horizon
        step_ticks = min(collapse.ticks_per_step, total_ticks - tick)
        if step_ticks != collapse.ticks_per_step:  # a shorter last step (coarse steps only)
            p.setTimeStep(dt * step_ticks, physicsClientId=cid)
        if settling.covers(tick):
            for _ in range(settling.substeps):
                probe.step("settle", step)
            if tick + 1 == settling.ticks:
                settling.end()
        else:
            probe.step("collapse" if collapse.collapsing else "fine", step)
        previous, tick = tick, tick + step_ticks
        if tick == push_ticks:
            p.setGravity(*gravity.tolist(), physicsClientId=cid)
        if trajectory is not None and _crossed(tick, previous, record_every):
            trajectory.append((tick * dt, *read_poses(world)))
        look_due = (rest.enabled or collapse.active) and _crossed(tick, previous, look_every)
        health_due = _crossed(tick, previous, health_every) or tick == total_ticks
        if not (look_due or health_due):
            continue
        speeds, spins = read_velocities(world)  # one read serves every part
        if health_due:
            health.check_speeds(speeds, limit, tick * dt)
        if not look_due:
            continue
        heights = read_poses(world)[0][:, 2] if (rest.needs_heights or collapse.watching) else None
        collapse.look(tick, max(push_ticks, settling.ticks), heights, speeds, spins)
        if rest.enabled and rest.should_stop(tick * dt, speeds, spins, heights):
            break
    positions, orientations = read_poses(world)
    health.check_final_poses(positions, orientations)
    return RolloutEnd(positions, orientations, trajectory, tick * dt)
