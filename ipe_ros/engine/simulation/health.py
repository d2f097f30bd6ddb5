"""Numerical health of a rollout: divergence is a named error, never a silent wrong answer."""

from __future__ import annotations

import math

import numpy as np

from ..errors import PhysicsError

_FIX = "use a smaller time step or more solver iterations"


def speed_limit_m_s(gravity_m_s2: float, horizon_s: float, push_m_s2: float, push_duration_s: float) -> float:
    """The fastest any box can honestly move: free fall for the whole horizon plus the push's dv.

    Anything faster means the solver injected energy (diverged).
    """
    return 2.0 * (gravity_m_s2 * horizon_s + push_m_s2 * min(push_duration_s, horizon_s)) + 1.0


def check_speeds(speeds_m_s: np.ndarray, limit_m_s: float, t_s: float) -> None:
    """Raise PhysicsError for a non-finite speed or one above the physical bound."""
    fastest = speeds_m_s.max()
    if fastest <= limit_m_s:  # the usual case, in one pass (a NaN or an infinity fails it)
        return
    if not np.all(np.isfinite(speeds_m_s)):
        raise PhysicsError(f"non-finite velocity at t = {t_s:.3f} s; {_FIX}")
    raise PhysicsError(f"a box reached {fastest:.3g} m/s at t = {t_s:.3f} s,"
                       f" above the physical bound {limit_m_s:.3g} m/s (solver divergence); {_FIX}")


def check_final_poses(positions_m: np.ndarray, orientations_xyzw: np.ndarray) -> None:
    if not (np.all(np.isfinite(positions_m)) and np.all(np.isfinite(orientations_xyzw))):
        raise PhysicsError(f"non-finite final pose; {_FIX}")


def energy_j(masses_kg: np.ndarray, inertia_kg_m2: np.ndarray, gravity_m_s2: np.ndarray, positions_m: np.ndarray,
             orientations_xyzw: np.ndarray, velocities_m_s: np.ndarray, spins_rad_s: np.ndarray) -> float:
    """Kinetic (linear and rotational) plus potential energy of the dynamic bodies, joules.

    ``inertia_kg_m2``: (n, 3) principal moments about each body's own axes; ``spins_rad_s``: (n, 3)
    angular velocities in the scene frame, turned into each body's frame by its unit quaternion
    (v - 2w (u x v) + 2 u x (u x v)).
    """
    return _energy_j(*_plain_constants(masses_kg, inertia_kg_m2, gravity_m_s2), positions_m, orientations_xyzw,
                     velocities_m_s, spins_rad_s)


def _plain_constants(masses_kg, inertia_kg_m2, gravity_m_s2) -> tuple[tuple, tuple, tuple]:
    """The bodies' masses, (n, 3) inertia and gravity as tuples of floats, what ``_energy_j`` takes."""
    return (tuple(np.asarray(masses_kg, float).tolist()), tuple(map(tuple, np.asarray(inertia_kg_m2, float).tolist())),
            tuple(float(v) for v in gravity_m_s2))


def _energy_j(masses_kg, inertia_kg_m2, gravity_m_s2, positions_m, orientations_xyzw,
              velocities_m_s, spins_rad_s) -> float:
    """``energy_j`` with the bodies' constants already sequences of floats. Plain floats, body by
    body: this runs at every look of every rollout, and for a scene's handful of bodies numpy's
    per-operation cost is five times the arithmetic."""
    gx, gy, gz = gravity_m_s2
    total = 0.0
    for m, (ix, iy, iz), (px, py, pz), (ux, uy, uz, w), (vx, vy, vz), (ox, oy, oz) in zip(
            masses_kg, inertia_kg_m2, np.asarray(positions_m, float).tolist(),
            np.asarray(orientations_xyzw, float).tolist(), np.asarray(velocities_m_s, float).tolist(),
            np.asarray(spins_rad_s, float).tolist()):
        norm = math.sqrt(ux * ux + uy * uy + uz * uz + w * w)
        ux, uy, uz, w = ux / norm, uy / norm, uz / norm, w / norm
        tx, ty, tz = 2 * (uy * oz - uz * oy), 2 * (uz * ox - ux * oz), 2 * (ux * oy - uy * ox)  # 2 u x v
        lx = ox - w * tx + (uy * tz - uz * ty)
        ly = oy - w * ty + (uz * tx - ux * tz)
        lz = oz - w * tz + (ux * ty - uy * tx)
        total += 0.5 * (m * (vx * vx + vy * vy + vz * vz) + ix * lx * lx + iy * ly * ly + iz * lz * lz) \
            - m * (px * gx + py * gy + pz * gz)
    return total


def energy_scale_j(scene) -> float:
    """A scene's energy scale, the yardstick for ``max_energy_gain_j``: each dynamic body's weight
    times its largest extent, plus its initial kinetic energy."""
    g = float(np.linalg.norm(scene.gravity_m_s2))
    return sum(b.resolved_mass_kg * (g * max(b.extents_m) + 0.5 * float(np.dot(b.linear_velocity_m_s,
                                                                             b.linear_velocity_m_s)))
               for b in scene.dynamic_objects)


class EnergyWatch:
    """The most energy a rollout gained beyond what the push and the initial velocities put in.

    Once the push is over nothing outside the scene does work on it, so its energy can only fall
    (collisions, friction): any rise is the solver's doing (a body squeezed out of a penetration is
    launched). The reference is the energy at t = 0, or at the end of the push when there is one.
    """

    def __init__(self, masses_kg: np.ndarray, inertia_kg_m2: np.ndarray, gravity_m_s2: np.ndarray):
        # plain floats once: the energy is worked out at every look (tuples: a collapse trial's deep
        # copy of this watch shares them)
        self._constants = _plain_constants(masses_kg, inertia_kg_m2, gravity_m_s2)
        self._reference: float | None = None
        self.max_gain_j = 0.0
        #: the least energy seen since the reference: what the scene holds at most from then on
        self.lowest_j: float | None = None

    def energy(self, positions, orientations, velocities, spins) -> float:
        return _energy_j(*self._constants, positions, orientations, velocities, spins)

    def reference(self, energy: float) -> None:
        self._reference = self.lowest_j = energy

    def look(self, energy: float) -> None:
        if self._reference is not None:
            self.max_gain_j = max(self.max_gain_j, energy - self._reference)
            self.lowest_j = min(self.lowest_j, energy)

    def created_j(self, energy: float) -> float:
        """Energy above the least seen since the reference (0 before it): made by the solver, since
        what collisions and friction took cannot come back."""
        return 0.0 if self.lowest_j is None else energy - self.lowest_j


def deepest_penetration_fraction(world, smallest_extents_m: np.ndarray, among: np.ndarray | None = None,
                                 detect: bool = True) -> float:
    """The deepest any dynamic body (of ``among``, default all) is inside the support or another body,
    as a fraction of its own smallest extent (0 when nothing overlaps). ``detect``: find the contacts
    of the state now; else read the ones the last step found (cheaper, one step old)."""
    return _deepest_fraction(world, _contacts(world, detect), smallest_extents_m, among)


def deeper_than(world, smallest_extents_m: np.ndarray, fraction: float, among: np.ndarray | None = None,
                detect: bool = True) -> bool:
    """``deepest_penetration_fraction(...) > fraction``, cheaply in the usual case: when no contact
    is deeper than ``fraction`` of the smallest body's extent, none can be deeper than ``fraction`` of
    its own, and the per-body pass is skipped (this runs at every look of a collapse)."""
    contacts = _contacts(world, detect)
    if not contacts or -min(c[8] for c in contacts) <= fraction * float(np.min(smallest_extents_m)):
        return False
    return _deepest_fraction(world, contacts, smallest_extents_m, among) > fraction


def _contacts(world, detect: bool) -> tuple:
    from .bullet import pybullet

    p = pybullet()
    if detect:
        p.performCollisionDetection(physicsClientId=world.client)
    return p.getContactPoints(physicsClientId=world.client)


def _deepest_fraction(world, contacts, smallest_extents_m: np.ndarray, among: np.ndarray | None) -> float:
    index = {handle: i for i, handle in enumerate(world.dynamic_ids) if among is None or among[i]}
    deepest = 0.0
    for contact in contacts:
        depth = -contact[8]
        if depth <= 0:
            continue
        for handle in (contact[1], contact[2]):
            if handle in index:
                deepest = max(deepest, depth / smallest_extents_m[index[handle]])
    return float(deepest)
