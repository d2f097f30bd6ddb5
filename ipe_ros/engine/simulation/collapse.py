"""Collapse steps: coarser steps once something has clearly fallen (see config.CollapseSettings)."""

from __future__ import annotations

import copy

import numpy as np

from ..config import SimSettings
from .bullet import pybullet


class CollapseWatch:
    """Watches for the first clear fall; from then on the scene is collapsing.

    ``collapse_below_z_m`` (per dynamic body): the scene is collapsing once any body is below its
    height, looked at after the push and the settling, while something still moves fast; once
    nothing does, the collapse is over (``settled``) and the watch starts again from there.
    """

    def __init__(self, settings: SimSettings, collapse_below_z_m: np.ndarray | None, smallest_m: np.ndarray):
        self._group = settings.collapse
        self._below_z = collapse_below_z_m
        self._smallest_m = smallest_m
        self.watching = collapse_below_z_m is not None and settings.collapse.enabled
        self.collapsing = False

    @property
    def active(self) -> bool:
        return self.watching or self.collapsing

    def look(self, tick: int, quiet_from_tick: int, heights_m: np.ndarray | None, moving: bool) -> bool:
        """True when the collapse starts at this look. ``moving``: some body is faster than
        ``collapse.quiet_sizes_per_s``."""
        if self.watching and tick >= quiet_from_tick and np.any(heights_m < self._below_z):
            if not moving:  # it fell and is still again: nothing left to step through coarsely
                self._watch_from(heights_m)
                return False
            # Something fell: what follows is chaotic at any step size, so only its statistics
            # matter and coarser steps reproduce them (benchmarks/accuracy_vs_time.py).
            self.watching, self.collapsing = False, True
            return True
        return False

    def still_standing(self, heights_m: np.ndarray) -> bool:
        """Some body has not clearly fallen (since the watch began): it can still fall."""
        return bool(np.any(heights_m >= self._below_z))

    def settled(self, heights_m: np.ndarray) -> None:
        """Nothing moves fast any more: the collapse is over. What still stands is as delicate as
        before it (a column rocked at coarse steps until it fell, one `paper` leaves standing), so
        fine steps again, and a new collapse once something clearly falls from where it is now."""
        self.collapsing = False
        self.watching = True
        self._watch_from(heights_m)

    def _watch_from(self, heights_m: np.ndarray) -> None:
        self._below_z = heights_m - self._group.drop_fraction * self._smallest_m

    def end(self) -> None:
        """Back to fine steps for the rest of the rollout."""
        self.watching = self.collapsing = False

    def coarse_factor(self, allowed_ticks: int) -> int:
        """Ticks per step while collapsing: as coarse as the preset and the travel limit allow."""
        return max(1, min(self._group.step_factor, allowed_ticks))


class CollapseTrial:
    """Collapse steps on trial: the rollout as it was at the look where they began, to go back to
    when they make energy (``config.CollapseSettings.max_created_energy_fraction``).

    pybullet's own saveState keeps the contact caches: the solver warm-starts resting contacts from
    them, and a 39-cube column put back by poses and velocities alone starts with cold contacts and
    kicks its lower cubes over (2 of 8 samples), where going back with its caches leaves it
    standing as `paper` does. Everything else the loop keeps (its watches, the step in force, the
    values read at that look) is copied beside it. Going back gives the rollout that never took
    collapse steps, to within pybullet's restore (~1e-6 m after 200 steps, not bit for bit;
    tests/test_hard_cases.py compares the answers).
    """

    def __init__(self, world, tick: int, looked: tuple, parts: dict, frames: int, pybullet_steps: int = 0):
        self._world = world
        self._state = pybullet().saveState(physicsClientId=world.client)
        self.tick = tick
        self.pybullet_steps = pybullet_steps  # the rollout's steps taken when it began (its anchors count from it)
        self._looked = looked  # what the loop read and worked out at that look
        self._parts = copy.deepcopy(parts)  # the loop's watches, as they were before the collapse began
        self._frames = frames

    def restore(self, trajectory: list | None) -> tuple[tuple, dict]:
        """Put the world back; returns the look's values and fresh copies of the loop's parts."""
        pybullet().restoreState(stateId=self._state, physicsClientId=self._world.client)
        if trajectory is not None:
            del trajectory[self._frames:]
        return self._looked, copy.deepcopy(self._parts)

    def close(self) -> None:
        if self._state is not None:
            pybullet().removeState(self._state, physicsClientId=self._world.client)
            self._state = None
