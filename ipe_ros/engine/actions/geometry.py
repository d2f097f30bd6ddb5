"""The scene's contact geometry, read without simulating: what touches what, what rests on what,
and which objects can reach each other within a rollout (the groups a question leaves apart)."""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import numpy as np

from .. import simulation
from ..config import SimSettings, SolverSettings
from ..scene.disjoint import DisjointSets
from ..scene.bodies import Body, Scene, Table, lowest_z_m
from ..scene.shapes import BoxShape
from .kinds import Action, Place, Remove


#: A world built only to look at the scene's geometry (contacts, rays, bounds): never stepped, so
#: it needs no solver for bounces (each switch to pybullet's direct solver allocates ~0.6 KB that
#: pybullet 3.2.7 never frees, and the node builds such a world for every question).
_GEOMETRY_SETTINGS = SimSettings(name="geometry", time_step_s=1 / 240, horizon_s=1.0,
                                 solver=SolverSettings(iterations=10, direct_solver_for_restitution=False))


def geometry_world(scene: Scene):
    """The scene at rest in a pybullet world of its own (contacts, and inertias as the rollout has them)."""
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
    world = geometry_world(scene)
    p = simulation.bullet.pybullet()
    reach = margin_m + 0.01 * world.scale_m
    pairs = tuple((i, j) for (i, a), (j, b) in itertools.combinations(enumerate(world.dynamic_ids), 2)
                  if p.getClosestPoints(a, b, reach, physicsClientId=world.client))
    boxes = tuple(simulation.world.bounding_boxes(world))
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
    sets = DisjointSets(len(names))
    for i, j in touching.pairs:
        sets.union(i, j)
    boxes = touching.boxes
    while True:
        members = sets.groups()
        bounds = {r: (np.min([boxes[i][0] for i in m], axis=0), np.max([boxes[i][1] for i in m], axis=0))
                  for r, m in members.items()}
        reach = {r: reach_m(scene, [bodies[i] for i in m], bounds[r]) for r, m in members.items()}
        for r, q in itertools.combinations(bounds, 2):
            (lo_r, hi_r), (lo_q, hi_q) = bounds[r], bounds[q]
            gap = np.maximum(0.0, np.maximum(lo_r[:2] - hi_q[:2], lo_q[:2] - hi_r[:2]))
            if float(np.linalg.norm(gap)) < max(reach[r], reach[q]) + margin_m:
                sets.union(r, q)
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


def reached(scene_groups: list[frozenset[str]], names) -> frozenset[str]:
    """Every object in a group with one of ``names``: all that removing them could affect."""
    return frozenset().union(*(g for g in scene_groups if g & set(names)))


def affected_regions(scene: Scene, actions: list[Action], margin_m: float, scene_groups: list[frozenset[str]],
                     pushes: bool) -> tuple[frozenset[str] | None, ...]:
    """Per action, the groups of objects it can affect (None: the whole scene)."""
    everything = frozenset(b.name for b in scene.dynamic_objects)
    out = []
    for action in actions:
        region = None
        if isinstance(action, Remove):
            region = reached(scene_groups, action.names)
        elif isinstance(action, Place) and not pushes:
            with_it = dataclasses.replace(scene, objects=scene.objects + (action.body,))
            region = next(g for g in groups(with_it, margin_m) if action.body.name in g)
        out.append(None if region is None or region >= everything else region)
    return tuple(out)
