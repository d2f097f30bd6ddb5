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


def _add_box(p, cid: int, box: Box, position, mass_kg: float, maximal: bool = False, orientation=None) -> int:
    half = [e / 2 for e in box.extents_m]
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
    quat = np.asarray(box.orientation_xyzw if orientation is None else orientation, float)
    quat = quat / np.linalg.norm(quat)
    body = p.createMultiBody(baseMass=mass_kg, baseCollisionShapeIndex=shape,
                             basePosition=list(map(float, position)),
                             baseOrientation=list(map(float, quat)), useMaximalCoordinates=maximal,
                             physicsClientId=cid)
    p.changeDynamics(body, -1, lateralFriction=box.friction, restitution=box.restitution,
                     physicsClientId=cid)
    return body


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
        # pybullet's threshold is absolute: scale it with the scene so small blocks converge too.
        solverResidualThreshold=settings.solver_residual_threshold * scale / 0.2,
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
    dynamic_ids = [_add_box(p, cid, b, pos, float(m), settings.maximal_coordinates, orn)
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
    pairs = [p.getBaseVelocity(b, physicsClientId=world.client) for b in world.dynamic_ids]
    return (np.array([np.linalg.norm(v) for v, _ in pairs]), np.array([np.linalg.norm(w) for _, w in pairs]))


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
             stop_at_first_fall: bool = False) -> tuple[np.ndarray, np.ndarray, list | None, float]:
    """Run the horizon; return final positions, orientations, (if asked) a trajectory, and the
    simulated time in seconds (shorter than the horizon when early termination ended the rollout).

    ``fallen_below_z_m`` (per dynamic box, only when nothing but ``fall`` / ``any_fall`` is asked): a box whose
    centre is below this height has fallen, its outcome is decided, so early termination no longer
    waits for it to come to rest. With ``stop_at_first_fall`` (a yes/no question: will anything
    fall?) the rollout ends as soon as any box is below its height, checked every 0.05 s.

    The trajectory, recorded every ``record_every`` steps when > 0, is a list of (time_s, positions,
    orientations). Raises PhysicsError on non-finite states or speeds above ``speed_limit_m_s``.
    """
    p = _pybullet()
    cid = world.client
    dt = world.time_step_s
    steps = int(round(settings.horizon_s / dt))
    gravity = np.asarray(scene.gravity_m_s2, float)
    push_steps = 0
    if push_m_s2 > 0:
        push_steps = int(round(push_duration_s / dt))
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
    earliest_stop = max(push_steps * dt, settings.rest_min_time_s)
    resting_since: float | None = None
    liveliness_at_start = 0.0
    step = 0
    for step in range(1, steps + 1):
        p.stepSimulation(physicsClientId=cid)
        if step == push_steps:
            p.setGravity(*gravity.tolist(), physicsClientId=cid)
        if trajectory is not None and step % record_every == 0:
            trajectory.append((step * dt, *read_poses(world)))
        rest_due = settings.early_stop and step % rest_every == 0
        check_due = step % check_every == 0 or step == steps
        if not (rest_due or check_due):
            continue
        speeds, spins = read_velocities(world)  # one read serves both checks
        if check_due:
            if not np.all(np.isfinite(speeds)):
                raise PhysicsError(f"non-finite velocity at t = {step * dt:.3f} s; "
                                   "use a smaller time step or more solver iterations")
            if speeds.max() > limit:
                raise PhysicsError(f"a box reached {speeds.max():.3g} m/s at t = {step * dt:.3f} s,"
                                   f" above the physical bound {limit:.3g} m/s (solver divergence); "
                                   "use a smaller time step or more solver iterations")
        if rest_due:
            t = step * dt
            settled = (speeds < rest_speed) & (spins < settings.rest_angular_rad_s)
            if fallen_below_z_m is not None:
                fallen_now = read_poses(world)[0][:, 2] < fallen_below_z_m
                if stop_at_first_fall and fallen_now.any():
                    break
                settled |= fallen_now
            # how close to moving the liveliest box is (1 = at the rest threshold)
            liveliness = float(np.max(np.where(settled, np.maximum(speeds / rest_speed,
                                                                    spins / settings.rest_angular_rad_s), 0.0)))
            if np.all(settled) and t >= earliest_stop:
                if resting_since is None:
                    resting_since, liveliness_at_start = t, liveliness
                elif t - resting_since >= settings.rest_duration_s - 1e-9:
                    # A tower that is just starting to tip moves slowly but faster and faster;
                    # a settling one slows down. Only the latter has come to rest.
                    if liveliness <= liveliness_at_start * settings.rest_growth_factor:
                        break
                    resting_since, liveliness_at_start = t, liveliness
            else:
                resting_since = None
    positions, orientations = read_poses(world)
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(orientations))):
        raise PhysicsError("non-finite final pose; use a smaller time step or more solver iterations")
    return positions, orientations, trajectory, step * dt
