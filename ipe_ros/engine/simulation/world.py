"""pybullet, and only pybullet: build a world for one sample, configure its step, read its states.

One DIRECT client per process (``client()``), created on first use. Every sample gets a fresh world
(``resetSimulation`` and re-created bodies): resetting poses in a reused world made outcomes depend
on which samples ran before, re-creating does not.

Every other module of the simulation reaches pybullet through ``pybullet()`` and ``World.client``.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys
from dataclasses import dataclass

import numpy as np

from ..config import SimSettings
from ..scene import Box, Floor, Scene

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


def pybullet():
    global _PYBULLET
    if _PYBULLET is None:
        with _quiet_c_output():
            import pybullet
        _PYBULLET = pybullet
    return _PYBULLET


def client() -> int:
    """This process's pybullet DIRECT client (re-created after a fork or a disconnect)."""
    global _CLIENT, _CLIENT_PID
    p = pybullet()
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


def residual_threshold(settings: SimSettings, scale_m: float, step_factor: float = 1) -> float:
    """pybullet's solver stops once the largest squared impulse change of an iteration is below this.

    The threshold is absolute: scale it with the scene so small blocks converge too, and with the
    square of the step, since impulses grow with the step (steps ``step_factor`` times longer are
    solved to the same relative precision).
    """
    return settings.solver.residual_threshold * scale_m / 0.2 * step_factor ** 2


def set_step(world: World, step_s: float, residual: float | None = None) -> None:
    """Make the next steps ``step_s`` long (and solve them to ``residual`` when given)."""
    p = pybullet()
    p.setTimeStep(step_s, physicsClientId=world.client)
    if residual is not None:
        p.setPhysicsEngineParameter(solverResidualThreshold=residual, physicsClientId=world.client)


def build_world(scene: Scene, positions_m: np.ndarray, masses_kg: np.ndarray,
                settings: SimSettings, orientations_xyzw: np.ndarray | None = None) -> World:
    """A fresh world: support, static boxes, and the dynamic boxes at ``positions_m`` (and
    ``orientations_xyzw``, default: the scene's), at rest."""
    p = pybullet()
    cid = client()
    p.resetSimulation(physicsClientId=cid)
    p.setGravity(*scene.gravity_m_s2, physicsClientId=cid)
    scale = min(min(b.extents_m) for b in scene.dynamic_boxes)
    time_step = settings.time_step_for(scale, float(np.linalg.norm(scene.gravity_m_s2)))
    p.setTimeStep(time_step, physicsClientId=cid)
    p.setPhysicsEngineParameter(
        numSolverIterations=settings.solver.iterations,
        solverResidualThreshold=residual_threshold(settings, scale),
        warmStartingFactor=settings.solver.warm_start_factor,
        deterministicOverlappingPairs=1,
        physicsClientId=cid)

    support = scene.support
    if isinstance(support, Floor):
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        body = p.createMultiBody(0, plane, basePosition=[0, 0, support.height_m], physicsClientId=cid)
        p.changeDynamics(body, -1, lateralFriction=support.friction, restitution=support.restitution,
                         physicsClientId=cid)
    else:
        top = Box(name="__table__", extents_m=(support.size_m[0], support.size_m[1], support.thickness_m),
                  position_m=(support.center_xy_m[0], support.center_xy_m[1],
                              support.top_height_m - support.thickness_m / 2),
                  orientation_xyzw=(0.0, 0.0, 0.0, 1.0), friction=support.friction,
                  restitution=support.restitution, static=True)
        _add_box(p, cid, top, top.position_m, 0.0)
        if support.floor_z_m is not None:
            plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
            body = p.createMultiBody(0, plane, basePosition=[0, 0, support.floor_z_m], physicsClientId=cid)
            p.changeDynamics(body, -1, lateralFriction=support.friction, restitution=support.restitution,
                             physicsClientId=cid)
    for b in scene.static_boxes:
        _add_box(p, cid, b, b.position_m, 0.0)
    orientations = [None] * len(positions_m) if orientations_xyzw is None else orientations_xyzw
    shapes: dict = {}
    dynamic_ids = [_add_box(p, cid, b, pos, float(m), settings.solver.maximal_coordinates, orn, shapes)
                   for b, pos, m, orn in zip(scene.dynamic_boxes, positions_m, masses_kg, orientations)]
    return World(client=cid, dynamic_ids=dynamic_ids, scale_m=scale, time_step_s=time_step)


def read_poses(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) positions in metres and (n, 4) xyzw orientations of the dynamic boxes."""
    p = pybullet()
    pos = np.empty((len(world.dynamic_ids), 3))
    orn = np.empty((len(world.dynamic_ids), 4))
    for i, body in enumerate(world.dynamic_ids):
        pos[i], orn[i] = p.getBasePositionAndOrientation(body, physicsClientId=world.client)
    return pos, orn


def read_velocities(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n,) linear speeds in m/s and (n,) angular speeds in rad/s of the dynamic boxes."""
    p = pybullet()
    pairs = np.array([p.getBaseVelocity(b, physicsClientId=world.client) for b in world.dynamic_ids])
    pairs = pairs.reshape(len(world.dynamic_ids), 2, 3)
    speeds = np.sqrt(np.einsum("nkj,nkj->nk", pairs, pairs))
    return speeds[:, 0], speeds[:, 1]
