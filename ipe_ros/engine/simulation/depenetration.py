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
