"""pybullet, and only pybullet: build a world for one sample, step it, read its states.

One DIRECT client per process (``client()``), created on first use. Every sample gets a fresh world
(``resetSimulation`` and re-created bodies): resetting poses in a reused world made outcomes depend
on which samples ran before, re-creating does not.

The push (phi) is simulated in the support's own frame: while the support accelerates at ``a`` every
free body feels the inertial force ``-m a``, which is exactly a tilt of gravity by ``-a`` for the
push's duration. Static geometry (table, walls) moves with the support and so stays put in its frame,
and all outputs are in that frame. After the push the support moves uniformly, and its frame is
inertial again. With phi = 0 nothing about the push is simulated.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

from .config import SimSettings
from .errors import PhysicsError
from .scene import Box, Floor, Scene

_PYBULLET = None
#: Motion (linear speed in box sizes per second, or angular speed in rad/s, whichever is larger)
#: below which a box's growth over the rest window counts as contact jitter, not a tip starting.
#: Boxes of the paper's stable towers still show a median 0.0025 /s (90th percentile 0.0075 /s)
#: after 1 s; the slow tip that the per-box test catches was at 0.007 -> 0.008 /s over its window.
#: Absolute, not a fraction of the rest thresholds: loosening those must not blind this check.
REST_NOISE_FLOOR_PER_S = 0.0025
_CLIENT: int | None = None
_CLIENT_PID: int | None = None


@contextlib.contextmanager
def _quiet_c_output():
    """Send fds 1 and 2 to /dev/null for the block: pybullet's C code prints a build banner on
    connect, which would clutter the CLI's output and logs."""
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no stdout/stderr at all: nothing to protect
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    try:
        yield
    finally:
        try:
            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


def _pybullet():
    global _PYBULLET
    if _PYBULLET is None:
        with _quiet_c_output():
            import pybullet
        _PYBULLET = pybullet
    return _PYBULLET


def client() -> int:
    """This process's pybullet DIRECT client (re-created after a fork or a disconnect)."""
    global _CLIENT, _CLIENT_PID
    p = _pybullet()
    if _CLIENT is None or _CLIENT_PID != os.getpid() or not p.isConnected(_CLIENT):
        with _quiet_c_output():
            _CLIENT = p.connect(p.DIRECT)
        _CLIENT_PID = os.getpid()
    return _CLIENT


@dataclass
class World:
    """Handles of one built world. ``dynamic_ids`` follow ``scene.dynamic_boxes`` order."""

    client: int
    dynamic_ids: list[int]
    static_ids: list[int]
    support_ids: list[int]
    scale_m: float  # smallest extent of any dynamic box: the scene's length scale
    time_step_s: float = 0.0  # the step actually used (finer than the preset's for small boxes)


def _add_box(p, cid: int, box: Box, position, mass_kg: float, maximal: bool = False, orientation=None,
             shapes: dict | None = None) -> int:
    """One box body; ``shapes`` caches collision shapes by extents within one world (towers of
    identical blocks share one shape)."""
    shape = None if shapes is None else shapes.get(box.extents_m)
    if shape is None:
        half = [e / 2 for e in box.extents_m]
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        if shapes is not None:
            shapes[box.extents_m] = shape
    quat = np.asarray(box.orientation_xyzw if orientation is None else orientation, float)
    quat = quat / np.linalg.norm(quat)
    body = p.createMultiBody(baseMass=mass_kg, baseCollisionShapeIndex=shape,
                             basePosition=list(map(float, position)),
                             baseOrientation=list(map(float, quat)), useMaximalCoordinates=maximal,
                             physicsClientId=cid)
    p.changeDynamics(body, -1, lateralFriction=box.friction, restitution=box.restitution,
                     physicsClientId=cid)
    return body


def _residual_threshold(settings: SimSettings, scale_m: float, step_factor: float = 1) -> float:
    """pybullet's solver stops once the largest squared impulse change of an iteration is below this.

    The threshold is absolute: scale it with the scene so small blocks converge too, and with the
    square of the step, since impulses grow with the step (steps ``step_factor`` times longer are
    solved to the same relative precision).
    """
    return settings.solver_residual_threshold * scale_m / 0.2 * step_factor ** 2


def build_world(scene: Scene, positions_m: np.ndarray, masses_kg: np.ndarray,
                settings: SimSettings, orientations_xyzw: np.ndarray | None = None) -> World:
    """A fresh world: support, static boxes, and the dynamic boxes at ``positions_m`` (and
    ``orientations_xyzw``, default: the scene's), at rest."""
    p = _pybullet()
    cid = client()
    p.resetSimulation(physicsClientId=cid)
    p.setGravity(*scene.gravity_m_s2, physicsClientId=cid)
    scale = min(min(b.extents_m) for b in scene.dynamic_boxes)
    time_step = settings.time_step_for(scale, float(np.linalg.norm(scene.gravity_m_s2)))
    p.setTimeStep(time_step, physicsClientId=cid)
    p.setPhysicsEngineParameter(
        numSolverIterations=settings.solver_iterations,
        solverResidualThreshold=_residual_threshold(settings, scale),
        warmStartingFactor=settings.warm_start_factor,
        deterministicOverlappingPairs=1,
        physicsClientId=cid)

    support_ids = []
    support = scene.support
    if isinstance(support, Floor):
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        body = p.createMultiBody(0, plane, basePosition=[0, 0, support.height_m], physicsClientId=cid)
        p.changeDynamics(body, -1, lateralFriction=support.friction, restitution=support.restitution,
                         physicsClientId=cid)
        support_ids.append(body)
    else:
        top = Box(name="__table__", extents_m=(support.size_m[0], support.size_m[1], support.thickness_m),
                  position_m=(support.center_xy_m[0], support.center_xy_m[1],
                              support.top_height_m - support.thickness_m / 2),
                  orientation_xyzw=(0.0, 0.0, 0.0, 1.0), friction=support.friction,
                  restitution=support.restitution, static=True)
        support_ids.append(_add_box(p, cid, top, top.position_m, 0.0))
        if support.floor_z_m is not None:
            plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
            body = p.createMultiBody(0, plane, basePosition=[0, 0, support.floor_z_m], physicsClientId=cid)
            p.changeDynamics(body, -1, lateralFriction=support.friction, restitution=support.restitution,
                             physicsClientId=cid)
            support_ids.append(body)
    static_ids = [_add_box(p, cid, b, b.position_m, 0.0) for b in scene.static_boxes]
    orientations = [None] * len(positions_m) if orientations_xyzw is None else orientations_xyzw
    shapes: dict = {}
    dynamic_ids = [_add_box(p, cid, b, pos, float(m), settings.maximal_coordinates, orn, shapes)
                   for b, pos, m, orn in zip(scene.dynamic_boxes, positions_m, masses_kg, orientations)]
    return World(client=cid, dynamic_ids=dynamic_ids, static_ids=static_ids, support_ids=support_ids,
                 scale_m=scale, time_step_s=time_step)


def read_poses(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) positions in metres and (n, 4) xyzw orientations of the dynamic boxes."""
    p = _pybullet()
    pos = np.empty((len(world.dynamic_ids), 3))
    orn = np.empty((len(world.dynamic_ids), 4))
    for i, body in enumerate(world.dynamic_ids):
        pos[i], orn[i] = p.getBasePositionAndOrientation(body, physicsClientId=world.client)
    return pos, orn


def read_speeds(world: World) -> np.ndarray:
    """(n,) linear speeds of the dynamic boxes in m/s."""
    return read_velocities(world)[0]


def read_velocities(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n,) linear speeds in m/s and (n,) angular speeds in rad/s of the dynamic boxes."""
    p = _pybullet()
    pairs = np.array([p.getBaseVelocity(b, physicsClientId=world.client) for b in world.dynamic_ids])
    pairs = pairs.reshape(len(world.dynamic_ids), 2, 3)
    speeds = np.sqrt(np.einsum("nkj,nkj->nk", pairs, pairs))
    return speeds[:, 0], speeds[:, 1]


def depenetrate(world: World, settings: SimSettings) -> int:
    """Move dynamic boxes apart until none overlaps another box or the support; return iterations.

    A geometric projection, not a simulation: each round finds every overlapping pair (its deepest
    contact), and moves the pair apart along the contact normal by the overlap depth, split evenly
    between two dynamic boxes or taken wholly by the dynamic one against static geometry. Velocities
    are never involved, so however deep the initial overlap, no energy enters the rollout: every box
    starts from rest at the separated pose.
    """
    p = _pybullet()
    cid = world.client
    tolerance = settings.depenetration_tolerance_fraction * world.scale_m
    index = {body: i for i, body in enumerate(world.dynamic_ids)}
    for iteration in range(settings.depenetration_max_iterations):
        p.performCollisionDetection(physicsClientId=cid)
        deepest: dict[tuple[int, int], tuple[float, np.ndarray]] = {}
        for contact in p.getContactPoints(physicsClientId=cid):
            body_a, body_b, distance = contact[1], contact[2], contact[8]
            if distance >= -tolerance or (body_a not in index and body_b not in index):
                continue
            key = (body_a, body_b)
            if key not in deepest or -distance > deepest[key][0]:
                deepest[key] = (-distance, np.asarray(contact[7], float))  # normal points from B to A
        if not deepest:
            return iteration
        shift = np.zeros((len(world.dynamic_ids), 3))
        for (body_a, body_b), (depth, normal_b_to_a) in deepest.items():
            a_free, b_free = body_a in index, body_b in index
            share = 0.5 if (a_free and b_free) else 1.0
            # Slight over-correction (1%) so touching pairs end separated rather than grazing.
            step = 1.01 * depth * share * normal_b_to_a
            if a_free:
                shift[index[body_a]] += step
            if b_free:
                shift[index[body_b]] -= step
        for i, body in enumerate(world.dynamic_ids):
            if shift[i].any():
                pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=cid)
                p.resetBasePositionAndOrientation(body, (np.asarray(pos) + shift[i]).tolist(), orn,
                                                  physicsClientId=cid)
    raise PhysicsError(f"boxes still overlap after {settings.depenetration_max_iterations} "
                       "depenetration rounds; lower sigma or raise depenetration_max_iterations")


def speed_limit_m_s(scene: Scene, push_m_s2: float, settings: SimSettings, push_duration_s: float) -> float:
    """The fastest any box can honestly move: free fall for the whole horizon plus the push's dv.

    Anything faster means the solver injected energy (diverged).
    """
    g = float(np.linalg.norm(scene.gravity_m_s2))
    return 2.0 * (g * settings.horizon_s + push_m_s2 * min(push_duration_s, settings.horizon_s)) + 1.0


def simulate(world: World, scene: Scene, settings: SimSettings, push_m_s2: float, push_direction_rad: float,
             push_duration_s: float, record_every: int = 0,
             fallen_below_z_m: np.ndarray | None = None,
             stop_at_first_fall: bool = False,
             collapse_below_z_m: np.ndarray | None = None,
             never_falls: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, list | None, float]:
    """Run the horizon; return final positions, orientations, (if asked) a trajectory, and the
    simulated time in seconds (shorter than the horizon when early termination ended the rollout).

    ``fallen_below_z_m`` (per dynamic box, only when nothing but ``fall`` / ``any_fall`` is asked): a box whose
    centre is below this height has fallen, its outcome is decided, so early termination no longer
    waits for it to come to rest. With ``stop_at_first_fall`` (a yes/no question: will anything
    fall?) the rollout ends as soon as any box is below its height, checked every 0.05 s.

    ``never_falls`` (per dynamic box, with ``fallen_below_z_m``): boxes that cannot drop that far
    whatever happens (a block lying on the floor), so their outcome is decided from the start and
    early termination does not wait for them either.

    ``collapse_below_z_m`` (per dynamic box, when ``settings.collapse_step_factor > 1``): once any box
    is below its height (checked every 0.05 s, after the push), the scene is collapsing and the rest
    of the rollout runs up to ``collapse_step_factor`` times coarser steps (as coarse as
    ``collapse_max_travel_fraction`` allows, chosen every 0.05 s) with
    ``settings.collapse_solver_iterations`` (see SimSettings).

    The trajectory, recorded every ``record_every`` steps of the initial step size when > 0, is a
    list of (time_s, positions, orientations). Raises PhysicsError on non-finite states or speeds
    above ``speed_limit_m_s``.
    """
    p = _pybullet()
    cid = world.client
    # Time runs on a grid of ticks of the initial step dt; a coarse (collapse) step spans several
    # ticks, so every check, recording and the end of the push stay on the same times.
    dt = world.time_step_s
    total_ticks = int(round(settings.horizon_s / dt))
    gravity = np.asarray(scene.gravity_m_s2, float)
    push_ticks = 0
    if push_m_s2 > 0:
        push_ticks = int(round(push_duration_s / dt))
        tilted = gravity - push_m_s2 * np.array([math.cos(push_direction_rad), math.sin(push_direction_rad), 0.0])
        p.setGravity(*tilted.tolist(), physicsClientId=cid)
    limit = speed_limit_m_s(scene, push_m_s2, settings, push_duration_s)
    trajectory: list | None = [] if record_every > 0 else None
    if trajectory is not None:
        trajectory.append((0.0, *read_poses(world)))
    check_every = max(1, int(round(0.1 / dt)))
    # Early termination: look every 0.05 s whether everything has been at rest for rest_duration_s.
    rest_every = max(1, int(round(0.05 / dt)))
    rest_speed = settings.rest_speed_sizes_per_s * world.scale_m
    earliest_stop = max(push_ticks * dt, settings.rest_min_time_s)
    resting_since: float | None = None
    motion_at_start = np.zeros(len(scene.dynamic_boxes))
    watch_collapse = collapse_below_z_m is not None and settings.collapse_step_factor > 1
    collapsing = False
    g = float(np.linalg.norm(gravity))
    half_diagonals_m = np.array([np.linalg.norm(b.extents_m) / 2 for b in scene.dynamic_boxes])
    ticks_per_step = 1
    tick = 0
    # Settling (see SimSettings.settle_s): the first ticks in substeps, solved to the same relative
    # precision (the residual threshold is absolute and impulses shrink with the step).
    settle_ticks = int(round(settings.settle_s / dt)) if settings.settle_substeps > 1 else 0
    if settle_ticks:
        p.setTimeStep(dt / settings.settle_substeps, physicsClientId=cid)
        p.setPhysicsEngineParameter(
            solverResidualThreshold=_residual_threshold(settings, world.scale_m, 1 / settings.settle_substeps),
            physicsClientId=cid)
    while tick < total_ticks:
        # the push ends exactly on its tick, and the last step ends exactly on the horizon
        step_ticks = min(ticks_per_step, total_ticks - tick)
        if step_ticks != ticks_per_step:  # a shorter last step (coarse steps only)
            p.setTimeStep(dt * step_ticks, physicsClientId=cid)
        if tick < settle_ticks:  # settling: this tick in finer substeps
            for _ in range(settings.settle_substeps):
                p.stepSimulation(physicsClientId=cid)
            if tick + 1 == settle_ticks:
                p.setTimeStep(dt, physicsClientId=cid)
                p.setPhysicsEngineParameter(solverResidualThreshold=_residual_threshold(settings, world.scale_m),
                                            physicsClientId=cid)
        else:
            p.stepSimulation(physicsClientId=cid)
        previous, tick = tick, tick + step_ticks
        if tick == push_ticks:
            p.setGravity(*gravity.tolist(), physicsClientId=cid)
        # a check is due when this step crossed a multiple of its period (in ticks)
        if trajectory is not None and tick // record_every > previous // record_every:
            trajectory.append((tick * dt, *read_poses(world)))
        rest_due = (settings.early_stop or watch_collapse or collapsing) and tick // rest_every > previous // rest_every
        check_due = tick // check_every > previous // check_every or tick == total_ticks
        if not (rest_due or check_due):
            continue
        speeds, spins = read_velocities(world)  # one read serves both checks
        if check_due:
            if not np.all(np.isfinite(speeds)):
                raise PhysicsError(f"non-finite velocity at t = {tick * dt:.3f} s; "
                                   "use a smaller time step or more solver iterations")
            if speeds.max() > limit:
                raise PhysicsError(f"a box reached {speeds.max():.3g} m/s at t = {tick * dt:.3f} s,"
                                   f" above the physical bound {limit:.3g} m/s (solver divergence); "
                                   "use a smaller time step or more solver iterations")
        if not rest_due:
            continue
        heights = read_poses(world)[0][:, 2] if (fallen_below_z_m is not None or watch_collapse) else None
        if watch_collapse and tick >= max(push_ticks, settle_ticks) and np.any(heights < collapse_below_z_m):
            # Something fell: what follows is a collapse, chaotic at any step size, so only its
            # statistics matter and coarser steps reproduce them (benchmarks/accuracy_vs_time.py).
            watch_collapse, collapsing = False, True
            if settings.collapse_solver_iterations is not None:
                p.setPhysicsEngineParameter(numSolverIterations=settings.collapse_solver_iterations,
                                            physicsClientId=cid)
        if collapsing:
            # Coarse, but no box may travel more than a fraction of the smallest box per step (else
            # fast blocks sink deep into what they hit): bound the speed until the next look.
            fastest_m_s = float((speeds + spins * half_diagonals_m).max()) + g * rest_every * dt  # corners
            allowed = int(settings.collapse_max_travel_fraction * world.scale_m / (fastest_m_s * dt))
            factor = max(1, min(settings.collapse_step_factor, allowed))
            if factor != ticks_per_step:
                ticks_per_step = factor
                p.setTimeStep(dt * factor, physicsClientId=cid)
                p.setPhysicsEngineParameter(solverResidualThreshold=_residual_threshold(settings, world.scale_m, factor),
                                            physicsClientId=cid)
        if not settings.early_stop:
            continue
        t = tick * dt
        settled = (speeds < rest_speed) & (spins < settings.rest_angular_rad_s)
        # how much each box still moves, in 1/s (box sizes per second or rad/s)
        motion = np.maximum(speeds / world.scale_m, spins)
        if fallen_below_z_m is not None:
            fallen_now = heights < fallen_below_z_m
            if stop_at_first_fall and fallen_now.any():
                break
            # a fallen box, or one that cannot fall, is decided: its motion no longer matters
            decided = fallen_now if never_falls is None else fallen_now | never_falls
            settled |= decided
            motion = np.where(decided, 0.0, motion)
        if np.all(settled) and t >= earliest_stop:
            if resting_since is None:
                resting_since, motion_at_start = t, motion
            elif t - resting_since >= settings.rest_duration_s - 1e-9:
                # A block that is just starting to tip moves slowly but faster and faster; a
                # settling one slows down. Only the latter has come to rest. Box by box: another
                # block still settling from the start masked a slow tip when only the liveliest
                # box was compared. Below REST_NOISE_FLOOR_PER_S growth is solver noise, not tipping.
                growing = (motion > motion_at_start * settings.rest_growth_factor) \
                    & (motion > REST_NOISE_FLOOR_PER_S)
                if not growing.any():
                    break
                resting_since, motion_at_start = t, motion
        else:
            resting_since = None
    positions, orientations = read_poses(world)
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(orientations))):
        raise PhysicsError("non-finite final pose; use a smaller time step or more solver iterations")
    return positions, orientations, trajectory, tick * dt
