"""Which of pybullet's solvers the next step of a bouncy world needs: the direct one for impacts only.

Bullet's two solvers each get one thing right. The direct (MLCP, Dantzig) solver solves an impact's
contacts at once, so a bounce gives back what Newton's restitution says (the sequential-impulse
solver, giving each contact its restitution in turn, added 6.6 J to a 12 J scene where a thrown ball
wedged under a cylinder against the floor). But its friction is a box, not a cone: each of the two
friction directions, which Bullet takes along the world's axes for a floor, is bounded by mu N on its
own, so a box slid at 30 deg veered to 18 deg and one slid at 45 deg stopped at 0.71x Coulomb's
distance. The sequential-impulse solver's friction is a cone (pybullet's implicit cone friction):
the same in every direction.

Restitution only acts where a contact closes faster than Bullet's restitution threshold; everywhere
else the two solvers solve the same contacts. So a world that may bounce steps on the
sequential-impulse solver, and on the direct one only for the steps in which some contact whose
surfaces can bounce closes that fast (docs/model.md, "Friction the same in every direction").
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.bodies import Scene
from .bullet import pybullet
from .world import World, use_direct_solver, use_sequential_solver

#: Bullet's restitution velocity threshold (btContactSolverInfo's default, which pybullet keeps): a
#: contact closing slower than this does not bounce, whatever its restitution
#: (tests/test_mechanics.py holds pybullet to it).
RESTITUTION_THRESHOLD_M_S = 0.2
#: a contact is an impact of the next step when it closes within this many of the step's lengths
#: (contacts are read at the start of the step, and a body speeds up within it)
CLOSING_STEPS = 2.0


class ImpactWatch:
    """Before each step of a world that may bounce, the solver that step needs (``choose``)."""

    def __init__(self, world: World, scene: Scene, push_m_s2: float = 0.0):
        self.world = world
        self.p = pybullet()
        restitution = {handle: body.restitution for handle, body in zip(world.dynamic_ids, scene.dynamic_objects)}
        restitution.update({handle: body.restitution for handle, body in zip(world.static_ids,
                                                                               scene.static_objects)})
        restitution.update({handle: scene.support.restitution for handle in world.support_ids})
        self.restitution = restitution
        #: how far a point of each dynamic body can be from its centre of mass (its bounding box's
        #: diagonal: a mesh's centre of mass may lie off the box's centre)
        self.reach_m = [float(np.linalg.norm(body.extents_m)) for body in scene.dynamic_objects]
        self.direct = False  # the solver in force: a world is built on the sequential-impulse one
        #: the fastest anything can speed up without a contact (gravity, tilted by the push)
        self.acceleration_m_s2 = float(np.linalg.norm(scene.gravity_m_s2)) + push_m_s2
        self.quiet_s = 0.0  # for this long nothing can close fast enough to bounce: no look needed

    def choose(self, step_s: float) -> bool:
        """Put the solver the next ``step_s`` needs in force; True when that is the direct one.

        Holding the direct solver on after an impact would switch less, but its friction then acts
        for longer: held 30 ms, the zoo's bouncy blocks fell 20 deg off the way they fall turned
        (tests/test_invariance.py)."""
        if self.quiet_s > 0:
            self.quiet_s -= step_s
            direct = False
        else:
            direct = self.impact_ahead(step_s)
        if direct != self.direct:
            (use_direct_solver if direct else use_sequential_solver)(self.world)
            self.direct = direct
        return direct

    def impact_ahead(self, step_s: float) -> bool:
        """Whether a contact between surfaces that can bounce closes faster than the restitution
        threshold within ``CLOSING_STEPS`` steps of ``step_s``, at the bodies' present poses. Bullet
        keeps no contact ahead of a body solved from the touch (``SolverSettings.bounce_from_touch``):
        its impact shows here once it touches, which is the step that solves it."""
        p, cid = self.p, self.world.client
        velocities = {handle: p.getBaseVelocity(handle, physicsClientId=cid) for handle in self.world.dynamic_ids}
        # no point of a body moves faster than this; no contact closes faster than its two bodies' sum
        bound = {handle: math.sqrt(vx * vx + vy * vy + vz * vz) + math.sqrt(wx * wx + wy * wy + wz * wz) * reach
                 for (handle, ((vx, vy, vz), (wx, wy, wz))), reach in zip(velocities.items(), self.reach_m)}
        fastest = sorted(bound.values(), reverse=True)
        closing_at_most = sum(fastest[:2])
        if closing_at_most <= RESTITUTION_THRESHOLD_M_S:
            # nearly at rest: look no further, nor again until two bodies speeding up freely could
            # close that fast (a quarter of that time: contacts can pass speed on, as a lever does)
            self.quiet_s = (RESTITUTION_THRESHOLD_M_S - closing_at_most) / (8 * self.acceleration_m_s2)
            return False
        p.performCollisionDetection(physicsClientId=cid)
        contacts = p.getContactPoints(physicsClientId=cid)
        if not contacts:
            return False
        restitution = self.restitution
        ahead_s = CLOSING_STEPS * step_s
        centres: dict[int, tuple] = {}  # plain floats: numpy's per-call cost is 20x the arithmetic here
        for contact in contacts:
            a, b = contact[1], contact[2]
            if restitution.get(a, 0.0) * restitution.get(b, 0.0) <= 0.0:
                continue  # Bullet multiplies the two: one surface that does not bounce, no bounce
            if bound.get(a, 0.0) + bound.get(b, 0.0) <= RESTITUTION_THRESHOLD_M_S:
                continue
            ax, ay, az = self._point_velocity(a, contact[5], velocities, centres)
            bx, by, bz = self._point_velocity(b, contact[6], velocities, centres)
            nx, ny, nz = contact[7]  # from b to a
            closing_m_s = (bx - ax) * nx + (by - ay) * ny + (bz - az) * nz
            if closing_m_s > RESTITUTION_THRESHOLD_M_S and closing_m_s * ahead_s >= contact[8]:
                return True
        return False

    def _point_velocity(self, handle: int, point, velocities: dict, centres: dict) -> tuple[float, float, float]:
        """The velocity of body ``handle``'s material point at ``point``, from the dynamic bodies'
        ``velocities`` (static bodies: zero); their centres of mass read once a look, in ``centres``."""
        motion = velocities.get(handle)
        if motion is None:
            return (0.0, 0.0, 0.0)
        centre = centres.get(handle)
        if centre is None:
            centre = centres[handle] = self.p.getBasePositionAndOrientation(handle,
                                                                            physicsClientId=self.world.client)[0]
        (cx, cy, cz), ((vx, vy, vz), (wx, wy, wz)) = centre, motion
        rx, ry, rz = point[0] - cx, point[1] - cy, point[2] - cz
        return (vx + wy * rz - wz * ry, vy + wz * rx - wx * rz, vz + wx * ry - wy * rx)
