"""How long the next step is: ticks per step (collapse) and substeps per tick (settling, travel).

Time runs on a grid of ticks of the world's step dt. A step spans ``ticks`` ticks cut into
``substeps`` pybullet steps of dt * ticks / substeps, solved to the same relative precision (the
solver's residual threshold is absolute and velocity errors grow with the step).
"""

from __future__ import annotations

import math

from ..config import SimSettings
from .world import World, contact_distance_m, residual_threshold, set_contact_distance, set_step


def substeps_for(fastest_m_s: float, settings: SimSettings, world: World, travel_fraction: float | None = None) -> int:
    """Substeps per tick that keep the fastest corner within the travel limit (``travel_fraction``
    of the smallest extent; None: the settings' ``max_travel_fraction``)."""
    fraction = settings.max_travel_fraction if travel_fraction is None else travel_fraction
    travel = fastest_m_s * world.time_step_s / (fraction * world.scale_m)
    return max(1, math.ceil(travel - 1e-9))


def ticks_allowed(fastest_m_s: float, settings: SimSettings, world: World, travel_fraction: float | None = None) -> int:
    """The most ticks one step may span within the travel limit (``travel_fraction``, None: the
    settings' ``max_travel_fraction``; 0: not even one)."""
    fraction = settings.max_travel_fraction if travel_fraction is None else travel_fraction
    return int(fraction * world.scale_m / (fastest_m_s * world.time_step_s))


class StepControl:
    """Holds the step in force and sets pybullet's when it changes."""

    def __init__(self, settings: SimSettings, world: World):
        self._settings, self._world = settings, world
        self.ticks, self.substeps = 1, 1
        self._contact_distance_m = world.contact_distance_m
        self._least_substeps = 1  # raised for the end of the horizon (collapse.end_substeps)
        self._ending = False  # in the end phase
        self._residual: float | None = None  # the unscaled residual threshold in force (None: the solver's)

    def end_phase(self, fastest_m_s: float) -> None:
        """From now on every tick runs in at least ``collapse.end_substeps`` substeps, and in as many
        as keep the fastest corner within ``collapse.end_travel_fraction`` (``end_speed``)."""
        self._ending = True
        self.end_speed(fastest_m_s)

    def end_speed(self, fastest_m_s: float) -> None:
        """In the end phase: the least substeps for the fastest corner's speed now (the answer reads
        the poses at the horizon, and a body caught mid-impact ends inside what it hit by about
        its last substep's travel, which the solver has not yet pushed out)."""
        if not self._ending:
            return
        group = self._settings.collapse
        least = group.end_substeps
        if group.end_travel_fraction is not None:
            least = max(least, substeps_for(fastest_m_s, self._settings, self._world, group.end_travel_fraction))
        self._least_substeps = least
        self.set(self.ticks, self.substeps)

    def find_contacts_ahead(self, fastest_m_s: float) -> None:
        """Contacts as far ahead as the fastest corner travels in the step in force (changed only
        when that moves by more than a quarter, to keep the contact cache)."""
        world = self._world
        step_s = world.time_step_s * self.ticks / self.substeps
        distance = contact_distance_m(self._settings, world.scale_m, fastest_m_s * step_s)
        if abs(distance - self._contact_distance_m) > 0.25 * self._contact_distance_m:
            self._contact_distance_m = distance
            set_contact_distance(world, distance)

    def reapply(self) -> None:
        """Set pybullet's contact distance to this world's again: Bullet keeps it in one global for
        every client of the process, so a world stepped beside another (islands) must set its own
        before it steps on."""
        set_contact_distance(self._world, self._contact_distance_m)

    def solve_to(self, residual: float | None) -> None:
        """Solve the steps from now on to this unscaled residual threshold (None: the solver's)."""
        if residual != self._residual:
            self._residual = residual
            self._apply()

    def snapshot(self) -> tuple[int, int, float, int, bool, float | None]:
        return self.ticks, self.substeps, self._contact_distance_m, self._least_substeps, self._ending, self._residual

    def restore(self, snapshot: tuple[int, int, float, int, bool, float | None]) -> None:
        """Back to a ``snapshot()``, in pybullet too (its step and contact distance are not part of
        a saved world state)."""
        (self.ticks, self.substeps, self._contact_distance_m, self._least_substeps, self._ending,
         self._residual) = snapshot
        # dt x (ticks / substeps): restore has always rounded the step so, where ``set`` rounds it as
        # dt x ticks / substeps; the two may differ in the last bit, and answers after an undo are
        # pinned (benchmarks/bit_identity.py)
        self._apply(self._world.time_step_s * (self.ticks / self.substeps))
        set_contact_distance(self._world, self._contact_distance_m)

    def _apply(self, step_s: float | None = None) -> None:
        world = self._world
        factor = self.ticks / self.substeps
        set_step(world, world.time_step_s * self.ticks / self.substeps if step_s is None else step_s,
                 residual_threshold(self._settings, world.scale_m, factor, self._residual))

    def set(self, ticks: int, substeps: int) -> None:
        substeps = min(max(substeps, self._least_substeps), self._settings.max_substeps)
        if (ticks, substeps) == (self.ticks, self.substeps):
            return
        self.ticks, self.substeps = ticks, substeps
        self._apply()

