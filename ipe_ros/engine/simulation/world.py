"""pybullet, and only pybullet: build a world for one sample, configure its step, read its states.

One DIRECT client per process (``client()``), created on first use. Every sample gets a fresh world
(``resetSimulation`` and re-created bodies): resetting poses in a reused world made outcomes depend
on which samples ran before, re-creating does not.

Every other module of the simulation reaches pybullet through ``bullet.pybullet()`` and ``World.client``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..config import SimSettings
from .bullet import client, pybullet, quiet_c_output, without_leaked_references
from .hull_files import hull_file
from ..scene import shapes as shapes_module
from ..scene.bodies import Body, Box, Floor, Scene
from ..scene.shapes import BoxShape, Capsule, ConvexHull, Cylinder, Sphere

@dataclass
class World:
    """Handles of one built world. ``dynamic_ids`` follow ``scene.dynamic_objects`` order."""

    client: int
    dynamic_ids: list[int]
    scale_m: float  # smallest extent of any dynamic body: the scene's length scale
    time_step_s: float = 0.0  # the step actually used (finer than the preset's for small or fast bodies)
    contact_distance_m: float = 0.0  # how far ahead contacts are found (Bullet's breaking threshold), as built
    masses_kg: np.ndarray | None = None  # of the dynamic bodies
    inertia_kg_m2: np.ndarray | None = None  # (n, 3) their principal moments (pybullet's)
    direct_solver: bool = False  # bounces solved by pybullet's MLCP (Dantzig) solver (all steps, or impacts only)
    support_ids: tuple[int, ...] = ()  # the floor, or the table top and the floor under it
    static_ids: tuple[int, ...] = ()  # follow ``scene.static_objects``


def _collision_shape(p, cid: int, shape, offset_m: np.ndarray) -> int:
    """A pybullet collision shape for ``shape``, its frame moved by ``offset_m`` (the body's frame in
    pybullet is its centre of mass, so a shape whose centre of mass is off its origin shifts by -com)."""
    # Only a real offset is passed: pybullet wraps any shape given a frame in a compound (slower).
    moved = {"collisionFramePosition": [float(v) for v in offset_m]} if np.any(offset_m) else {}
    if isinstance(shape, BoxShape):
        return p.createCollisionShape(p.GEOM_BOX, halfExtents=[e / 2 for e in shape.extents_m], **moved,
                                      physicsClientId=cid)
    if isinstance(shape, Sphere):
        return p.createCollisionShape(p.GEOM_SPHERE, radius=shape.radius_m, **moved, physicsClientId=cid)
    if isinstance(shape, Cylinder):
        return p.createCollisionShape(p.GEOM_CYLINDER, radius=shape.radius_m, height=shape.length_m, **moved,
                                      physicsClientId=cid)
    if isinstance(shape, Capsule):
        return p.createCollisionShape(p.GEOM_CAPSULE, radius=shape.radius_m, height=shape.length_m, **moved,
                                      physicsClientId=cid)
    if isinstance(shape, ConvexHull):
        vertices = tuple(tuple(map(float, v)) for v in shape.vertices_m)
        return without_leaked_references(lambda: p.createCollisionShape(p.GEOM_MESH, vertices=vertices, **moved,
                                                                         physicsClientId=cid), (vertices, *vertices))
    # a compound: each part a child shape at its pose
    types, half_extents, radii, lengths, files, positions, orientations = [], [], [], [], [], [], []
    for part in shape.parts:
        sub = part.shape
        half, radius, length, file = [0.0, 0.0, 0.0], 0.0, 0.0, ""
        if isinstance(sub, BoxShape):
            kind, half = p.GEOM_BOX, [e / 2 for e in sub.extents_m]
        elif isinstance(sub, Sphere):
            kind, radius = p.GEOM_SPHERE, sub.radius_m
        elif isinstance(sub, Cylinder):
            kind, radius, length = p.GEOM_CYLINDER, sub.radius_m, sub.length_m
        elif isinstance(sub, Capsule):
            kind, radius, length = p.GEOM_CAPSULE, sub.radius_m, sub.length_m
        else:
            kind, file = p.GEOM_MESH, hull_file(np.asarray(sub.vertices_m, float))
        types.append(kind)
        half_extents.append(half)
        radii.append(radius)
        lengths.append(length)
        files.append(file)
        positions.append([float(a + b) for a, b in zip(part.position_m, offset_m)])
        orientations.append([float(v) for v in part.orientation_xyzw])
    return p.createCollisionShapeArray(shapeTypes=types, halfExtents=half_extents, radii=radii, lengths=lengths,
                                       fileNames=files, meshScales=[[1.0, 1.0, 1.0]] * len(types),
                                       collisionFramePositions=positions, collisionFrameOrientations=orientations,
                                       physicsClientId=cid)


#: pybullet gives a multibody a drag that no scene has: its velocity shrinks by 0.04 (1 + |v|) per
#: second (Bullet's default linear and angular damping), while a plain rigid body (``default``'s
#: maximal coordinates) gets none. A box sliding at 3 m/s on a floor stopped at 2.03 m under `paper`
#: and at 2.29 m under `default`, Coulomb friction's 2.294 m; on the zoo's ramps and sliding strikes
#: `default` differed from `paper` by a mean |dP| of 0.12-0.13 per object, 0.08-0.09 without the
#: drag (benchmarks/HISTORY.md). Every body, in either representation, is undamped.
NO_DAMPING = {"linearDamping": 0.0, "angularDamping": 0.0}


def _add_body(p, cid: int, body: Body, position, mass_kg: float, maximal: bool = False, orientation=None,
              shapes: dict | None = None) -> int:
    """One pybullet body. A dynamic body's pybullet frame is its centre of mass (``position`` is
    where that is); a static body's is its own frame. ``shapes`` caches collision shapes within one
    world (towers of identical blocks share one)."""
    centred = mass_kg > 0
    key = (body.shape, centred)
    shape = None if shapes is None else shapes.get(key)
    if shape is None:
        offset = -shapes_module.centre_of_mass_m(body.shape) if centred else np.zeros(3)
        shape = _collision_shape(p, cid, body.shape, offset)
        if shapes is not None:
            shapes[key] = shape
    quat = np.asarray(body.orientation_xyzw if orientation is None else orientation, float)
    quat = quat / np.linalg.norm(quat)
    handle = p.createMultiBody(baseMass=mass_kg, baseCollisionShapeIndex=shape,
                               basePosition=list(map(float, position)),
                               baseOrientation=list(map(float, quat)), useMaximalCoordinates=maximal,
                               physicsClientId=cid)
    _set_dynamics(p, cid, handle, body, mass_kg)
    return handle


def _set_dynamics(p, cid: int, handle: int, body: Body, mass_kg: float = 0.0) -> None:
    """A body's surface (friction, restitution), no damping (``NO_DAMPING``), and a mesh's own inertia
    where the shape carries it (pybullet's own estimate for a compound is its bounding box's)."""
    inertia = getattr(body.shape, "inertia_diagonal_per_kg_m2", None)
    # the mass with it: pybullet 3.2.7 sets a maximal-coordinates body's mass to the call's (0 when left
    # out) with its inertia, and its first step is NaN
    own = {"mass": float(mass_kg), "localInertiaDiagonal": [mass_kg * float(v) for v in inertia]} \
        if inertia is not None and mass_kg > 0 else {}
    p.changeDynamics(handle, -1, lateralFriction=body.friction, restitution=body.restitution,
                     physicsClientId=cid, **NO_DAMPING, **own)


def _add_dynamic_bodies(p, cid: int, bodies, positions_m, masses_kg, orientations_xyzw, maximal: bool) -> list[int]:
    """The dynamic bodies, in order, their centres of mass at ``positions_m``. A run of consecutive
    bodies with the same shape, mass and orientation (a pile of cubes, a tower's parallel blocks) is
    created by one pybullet call (``batchPositions``): pybullet's per-call cost is ~0.2 ms a body.
    The world is bit for bit the one that creating them one by one gives (same ids, same order;
    tests/test_determinism.py); a run of different orientations set afterwards would not be."""
    shapes: dict = {}
    quats = [_unit(q) for q in orientations_xyzw]
    ids: list[int] = []
    start = 0
    while start < len(bodies):
        end = start + 1
        while end < len(bodies) and bodies[end].shape == bodies[start].shape \
                and float(masses_kg[end]) == float(masses_kg[start]) and quats[end] == quats[start]:
            end += 1
        if end - start == 1:
            ids.append(_add_body(p, cid, bodies[start], positions_m[start], float(masses_kg[start]), maximal,
                                 orientations_xyzw[start], shapes))
            start = end
            continue
        key = (bodies[start].shape, True)
        if key not in shapes:
            shapes[key] = _collision_shape(p, cid, bodies[start].shape,
                                           -shapes_module.centre_of_mass_m(bodies[start].shape))
        run = p.createMultiBody(baseMass=float(masses_kg[start]), baseCollisionShapeIndex=shapes[key],
                                baseOrientation=quats[start],
                                batchPositions=[list(map(float, pos)) for pos in positions_m[start:end]],
                                useMaximalCoordinates=maximal, physicsClientId=cid)
        for handle, body in zip(run, bodies[start:end]):
            _set_dynamics(p, cid, handle, body, float(masses_kg[start]))
        ids.extend(run)
        start = end
    return ids


def _unit(quaternion) -> list[float]:
    q = np.asarray(quaternion, float)
    return [float(v) for v in q / np.linalg.norm(q)]


def residual_threshold(settings: SimSettings, scale_m: float, step_factor: float = 1,
                       threshold: float | None = None) -> float:
    """pybullet's solver stops once the largest squared impulse change of an iteration is below this.

    The threshold is absolute: scale it with the scene so small blocks converge too, and with the
    square of the step, since impulses grow with the step (steps ``step_factor`` times longer are
    solved to the same relative precision). ``threshold``: the unscaled one (None: the solver's).
    """
    base = settings.solver.residual_threshold if threshold is None else threshold
    return base * scale_m / 0.2 * step_factor ** 2


def set_step(world: World, step_s: float, residual: float | None = None) -> None:
    """Make the next steps ``step_s`` long (and solve them to ``residual`` when given)."""
    p = pybullet()
    p.setTimeStep(step_s, physicsClientId=world.client)
    if residual is not None:
        p.setPhysicsEngineParameter(solverResidualThreshold=residual, physicsClientId=world.client)


def build_world(scene: Scene, positions_m: np.ndarray, masses_kg: np.ndarray,
                settings: SimSettings, orientations_xyzw: np.ndarray | None = None, slot: int = 0) -> World:
    """A fresh world: support, static bodies, and the dynamic bodies with their centres of mass at
    ``positions_m`` (and ``orientations_xyzw``, default: the scene's), at rest; in the client of
    ``slot`` (``bullet.client``), whose world it replaces."""
    p = pybullet()
    cid = client(slot)
    p.resetSimulation(physicsClientId=cid)
    p.setGravity(*scene.gravity_m_s2, physicsClientId=cid)
    scale = min(b.smallest_extent_m for b in scene.dynamic_objects)
    time_step = time_step_of(scene, settings)
    p.setTimeStep(time_step, physicsClientId=cid)
    contact_distance = contact_distance_m(settings, scale, fastest_initial_speed_m_s(scene) * time_step)
    p.setPhysicsEngineParameter(
        numSolverIterations=settings.iterations_for(mass_ratio(masses_kg)),
        solverResidualThreshold=residual_threshold(settings, scale),
        warmStartingFactor=settings.solver.warm_start_factor,
        contactBreakingThreshold=contact_distance,
        deterministicOverlappingPairs=1,
        physicsClientId=cid)
    direct = uses_direct_solver(scene, settings, masses_kg)
    if direct and not settings.solver.direct_solver_for_impacts_only:  # else the rollout takes it per step
        _set_solver(p, cid, p.CONSTRAINT_SOLVER_LCP_DANTZIG)

    support = scene.support
    support_ids = []
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
        support_ids.append(_add_body(p, cid, top, top.position_m, 0.0))
        if support.floor_z_m is not None:
            plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
            body = p.createMultiBody(0, plane, basePosition=[0, 0, support.floor_z_m], physicsClientId=cid)
            p.changeDynamics(body, -1, lateralFriction=support.friction, restitution=support.restitution,
                             physicsClientId=cid)
            support_ids.append(body)
    static_ids = tuple(_add_body(p, cid, b, b.position_m, 0.0) for b in scene.static_objects)
    orientations = [b.orientation_xyzw for b in scene.dynamic_objects] if orientations_xyzw is None \
        else orientations_xyzw
    dynamic_ids = _add_dynamic_bodies(p, cid, scene.dynamic_objects, positions_m, masses_kg, orientations,
                                      _plain_rigid_bodies(scene, settings, direct))
    if direct and settings.solver.bounce_from_touch:
        for handle, body in zip(dynamic_ids, scene.dynamic_objects):
            if body.restitution > 0:
                p.changeDynamics(handle, -1, contactProcessingThreshold=0.0, physicsClientId=cid)
    inertia = np.array([p.getDynamicsInfo(h, -1, physicsClientId=cid)[2] for h in dynamic_ids], float)
    return World(client=cid, dynamic_ids=dynamic_ids, scale_m=scale, time_step_s=time_step,
                 contact_distance_m=contact_distance,
                 masses_kg=np.asarray(masses_kg, float), inertia_kg_m2=inertia.reshape(len(dynamic_ids), 3),
                 direct_solver=direct, support_ids=tuple(support_ids), static_ids=static_ids)


def add_fixed_body(world: World, body: Body, position_m, orientation_xyzw) -> int:
    """Add ``body`` as fixed geometry at this pose (its own frame): a probe for geometric questions
    such as where an object would rest, never simulated."""
    return _add_body(pybullet(), world.client, body, position_m, 0.0, orientation=orientation_xyzw)


def move_body(world: World, handle: int, position_m, orientation_xyzw) -> None:
    pybullet().resetBasePositionAndOrientation(handle, [float(v) for v in position_m],
                                               [float(v) for v in orientation_xyzw], physicsClientId=world.client)


def gap_between_m(world: World, handle: int, other: int, within_m: float) -> float:
    """The smallest distance between bodies ``handle`` and ``other`` (negative: overlapping), or
    inf when they are farther apart than ``within_m``."""
    points = pybullet().getClosestPoints(handle, other, within_m, physicsClientId=world.client)
    return min((point[8] for point in points), default=math.inf)


def gap_to_others_m(world: World, handle: int, within_m: float) -> float:
    """The smallest distance from body ``handle`` to any other body or the support (negative:
    overlapping), or ``within_m`` when nothing is that close."""
    # the world's own handles: pybullet's getNumBodies / getBodyUniqueId miss all but one of the
    # bodies a batched createMultiBody makes (identical boxes), so a probe would sink through them
    return min([within_m] + [gap_between_m(world, handle, other, within_m)
                             for other in (*world.support_ids, *world.static_ids, *world.dynamic_ids)
                             if other != handle])


def uses_direct_solver(scene: Scene, settings: SimSettings, masses_kg) -> bool:
    """Whether a world of ``scene`` is solved by the direct solver (``SolverSettings``:
    ``direct_solver_for_restitution``, ``direct_solver_min_restitution``, ``direct_solver_from_speed_m_s``,
    ``multibodies_from_aspect``)."""
    solver = settings.solver
    bounce, thrown = combined_restitution(scene), solver.direct_solver_from_speed_m_s
    return solver.direct_solver_for_restitution and bounce > 0 \
        and mass_ratio(masses_kg) <= solver.direct_solver_max_mass_ratio \
        and (bounce >= solver.direct_solver_min_restitution or _thin_box(scene, settings)
             or (thrown is not None and fastest_initial_speed_m_s(scene) >= thrown))


def in_plain_rigid_bodies(scene: Scene, settings: SimSettings, masses_kg) -> bool:
    """Whether a world of ``scene`` builds its dynamic bodies as plain rigid bodies
    (``SolverSettings.maximal_coordinates``, except thin boxes on the direct solver:
    ``SolverSettings.multibodies_from_aspect``)."""
    return _plain_rigid_bodies(scene, settings, uses_direct_solver(scene, settings, masses_kg))


def _plain_rigid_bodies(scene: Scene, settings: SimSettings, direct: bool) -> bool:
    """``in_plain_rigid_bodies`` for a world whose solver is already decided (``direct``)."""
    return settings.solver.maximal_coordinates and not (direct and _thin_box(scene, settings))


def _thin_box(scene: Scene, settings: SimSettings) -> bool:
    """A box at least ``multibodies_from_aspect`` times as long as it is thin, where plain rigid
    bodies are asked for."""
    aspect = settings.solver.multibodies_from_aspect
    return aspect is not None and settings.solver.maximal_coordinates \
        and any(isinstance(b.shape, BoxShape) and max(b.extents_m) >= aspect * min(b.extents_m)
                for b in scene.dynamic_objects)


def combined_restitution(scene: Scene) -> float:
    """The largest restitution two surfaces that may touch combine to (Bullet multiplies the two):
    a dynamic body against the support, a static body or another dynamic one."""
    dynamic = sorted((b.restitution for b in scene.dynamic_objects), reverse=True)
    others = [scene.support.restitution] + [b.restitution for b in scene.static_objects]  # a table's floor too
    pairs = [dynamic[0] * dynamic[1]] if len(dynamic) > 1 else []
    return max(pairs + [dynamic[0] * max(others)] if dynamic else [0.0])


#: Bullet's contact ERP as it comes (pybullet's ``contactERP``; found by comparing rollouts, it has no
#: getter): the share of a contact's penetration the solver removes per step, by velocity
BULLET_CONTACT_ERP = 0.08


def use_sequential_solver(world: World) -> None:
    """Back to pybullet's sequential-impulse solver (it pushes resting bodies out of each other
    where the direct solver leaves them sunk; see SolverSettings.direct_solver_for_restitution),
    with Bullet's own penetration recovery."""
    p = pybullet()
    _set_solver(p, world.client, p.CONSTRAINT_SOLVER_LCP_SI, BULLET_CONTACT_ERP)


def use_direct_solver(world: World) -> None:
    """pybullet's direct MLCP (Dantzig) solver for the next steps (an impact: simulation/impacts.py),
    without penetration recovery: removing the impact's penetration by velocity in the same solve
    added to the rebound (a ball dropped 0.5 m came back 1.06-1.16x e^2 h high at paper and
    default, 1.01 without), so the rebound is the restitution's alone; the steps after, on the
    sequential-impulse solver, push the bodies apart."""
    p = pybullet()
    _set_solver(p, world.client, p.CONSTRAINT_SOLVER_LCP_DANTZIG, 0.0)


def _set_solver(p, cid: int, kind: int, contact_erp: float | None = None) -> None:
    """pybullet's constraint solver for this world (``resetSimulation`` puts back the
    sequential-impulse one), and its contact ERP. Quietly: pybullet prints on every switch."""
    with quiet_c_output():
        if contact_erp is None:
            p.setPhysicsEngineParameter(constraintSolverType=kind, physicsClientId=cid)
        else:
            p.setPhysicsEngineParameter(constraintSolverType=kind, contactERP=contact_erp, physicsClientId=cid)


def contact_distance_m(settings: SimSettings, scale_m: float, travel_m: float) -> float:
    """How far ahead contacts are found: as far as the fastest body travels in a step, within bounds."""
    return min(max(settings.min_contact_fraction * scale_m, travel_m), settings.max_travel_fraction * scale_m)


def set_contact_distance(world: World, distance_m: float) -> None:
    pybullet().setPhysicsEngineParameter(contactBreakingThreshold=distance_m, physicsClientId=world.client)


def mass_ratio(masses_kg) -> float:
    """How many times the heaviest dynamic body outweighs the lightest."""
    masses = np.asarray(masses_kg, float)
    return float(masses.max() / masses.min()) if len(masses) else 1.0


def time_step_of(scene: Scene, settings: SimSettings) -> float:
    """The step a world of ``scene`` takes (``SimSettings.time_step_for`` its bodies' sizes and its
    fastest start)."""
    bodies = scene.dynamic_objects
    return settings.time_step_for(min(b.smallest_extent_m for b in bodies),
                                  float(np.linalg.norm(scene.gravity_m_s2)), fastest_initial_speed_m_s(scene),
                                  settings.time_scale_extent_m(b.extents_m for b in bodies))


def fastest_initial_speed_m_s(scene: Scene) -> float:
    """The fastest any point of a dynamic body moves at t = 0 (linear speed + spin x half diagonal)."""
    return max((float(np.linalg.norm(b.linear_velocity_m_s))
                + float(np.linalg.norm(b.angular_velocity_rad_s)) * float(np.linalg.norm(b.extents_m)) / 2
                for b in scene.dynamic_objects if b.moving), default=0.0)


def set_initial_velocities(world: World, scene: Scene) -> None:
    """Give the dynamic bodies the scene's velocities at t = 0 (separation never sets any)."""
    p = pybullet()
    for handle, body in zip(world.dynamic_ids, scene.dynamic_objects):
        if body.moving:
            p.resetBaseVelocity(handle, list(map(float, body.linear_velocity_m_s)),
                                list(map(float, body.angular_velocity_rad_s)), physicsClientId=world.client)


def bounding_boxes(world: World) -> np.ndarray:
    """(n, 2, 3): each dynamic body's axis-aligned bounding box (lowest and highest corner, m), as
    pybullet's broadphase has it."""
    p = pybullet()
    boxes = [p.getAABB(body, physicsClientId=world.client) for body in world.dynamic_ids]
    return np.array(boxes, float).reshape(-1, 2, 3)


def read_poses(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) centres of mass in metres and (n, 4) xyzw orientations of the dynamic bodies."""
    p = pybullet()
    pos = np.empty((len(world.dynamic_ids), 3))
    orn = np.empty((len(world.dynamic_ids), 4))
    for i, body in enumerate(world.dynamic_ids):
        pos[i], orn[i] = p.getBasePositionAndOrientation(body, physicsClientId=world.client)
    return pos, orn


def read_state(world: World) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every dynamic body's centre of mass (m), xyzw orientation, and linear (m/s) and angular
    (rad/s) velocity in the scene frame, in one pass, as (n, 3), (n, 4) and (n, 2, 3) views of one
    array: a rollout's look costs pybullet's per-call price and numpy's per-array one, not
    arithmetic."""
    p = pybullet()
    cid, n = world.client, len(world.dynamic_ids)
    values = itertools.chain.from_iterable(itertools.chain.from_iterable(
        p.getBasePositionAndOrientation(b, physicsClientId=cid) + p.getBaseVelocity(b, physicsClientId=cid)
        for b in world.dynamic_ids))
    rows = np.fromiter(values, float, 13 * n).reshape(n, 13)
    return rows[:, :3], rows[:, 3:7], rows[:, 7:].reshape(n, 2, 3)


def speeds_of(velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) linear speeds and (n,) angular speeds from ``read_state``'s (n, 2, 3) velocities."""
    speeds = np.sqrt(np.einsum("nkj,nkj->nk", velocities, velocities))
    return speeds[:, 0], speeds[:, 1]


def read_velocities(world: World) -> tuple[np.ndarray, np.ndarray]:
    """(n,) linear speeds in m/s and (n,) angular speeds in rad/s of the dynamic bodies."""
    return speeds_of(read_state(world)[2])
