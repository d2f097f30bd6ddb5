"""Removing the overlaps that position noise creates (paper SI: "remove interpenetrations")."""

from __future__ import annotations

import numpy as np

from ..config import SimSettings
from ..errors import PhysicsError
from .bullet import pybullet
from .world import World


def depenetrate(world: World, settings: SimSettings) -> int:
    """Move dynamic boxes apart until none overlaps another box or the support; return iterations.

    A geometric projection, not a simulation: each round finds every overlapping pair (its deepest
    contact), and moves the pair apart along the contact normal by the overlap depth, split evenly
    between two dynamic boxes or taken wholly by the dynamic one against static geometry. Velocities
    are never involved, so however deep the initial overlap, no energy enters the rollout: every box
    starts from rest at the separated pose.
    """
    p = pybullet()
    cid = world.client
    tolerance = settings.depenetration.tolerance_fraction * world.scale_m
    index = {body: i for i, body in enumerate(world.dynamic_ids)}
    for iteration in range(settings.depenetration.max_iterations):
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
    raise PhysicsError(f"boxes still overlap after {settings.depenetration.max_iterations} "
                       "depenetration rounds; lower sigma or raise depenetration.max_iterations")


#: halvings of the set-down distance when finding where a body touches (2^-16 of it: a micrometre of 6 cm)
SET_DOWN_HALVINGS = 16


def set_down(world: World, within_m: float) -> int:
    """Lower every dynamic body whose lowest point is at most ``within_m`` above what is under it until
    it touches it, from the lowest body up (so each lands on its support's final pose); return how many
    moved. Heights from a detector or a depth posterior are estimates: a box left millimetres above its
    support drops and strikes it, an impulse the scene at rest never had. A body farther up than
    ``within_m`` (thrown, hanging) keeps its height.

    Geometric, for every shape: the largest drop that leaves no pair deeper in contact than it was
    (pybullet's signed distances), by halving; the bodies beside it (whose distance a vertical move
    does not shorten) never stop it.
    """
    if within_m <= 0:
        return 0
    p = pybullet()
    cid = world.client
    lowest = {body: p.getAABB(body, physicsClientId=cid)[0][2] for body in world.dynamic_ids}
    moved = 0
    for body in sorted(world.dynamic_ids, key=lowest.__getitem__):
        low, high = p.getAABB(body, physicsClientId=cid)
        near = {other for other, _ in p.getOverlappingObjects([low[0], low[1], low[2] - within_m], high,
                                                              physicsClientId=cid) or () if other != body}
        position, orientation = p.getBasePositionAndOrientation(body, physicsClientId=cid)

        def deepest_at(drop_m: float) -> dict[int, float]:
            p.resetBasePositionAndOrientation(body, (position[0], position[1], position[2] - drop_m), orientation,
                                              physicsClientId=cid)
            return {other: min((c[8] for c in p.getClosestPoints(body, other, 0.0, physicsClientId=cid)), default=0.0)
                    for other in near}

        start = {other: min(depth, 0.0) for other, depth in deepest_at(0.0).items()}

        def touches(drop_m: float) -> bool:
            return any(depth < start[other] - 1e-9 for other, depth in deepest_at(drop_m).items())

        if not touches(within_m):
            p.resetBasePositionAndOrientation(body, position, orientation, physicsClientId=cid)
            continue
        free, touching = 0.0, within_m
        for _ in range(SET_DOWN_HALVINGS):
            middle = (free + touching) / 2
            free, touching = (free, middle) if touches(middle) else (middle, touching)
        p.resetBasePositionAndOrientation(body, (position[0], position[1], position[2] - free), orientation,
                                          physicsClientId=cid)
        moved += free > 0
    return moved
