"""Settling: the first ticks of a rollout in finer substeps (see config.SettlingSettings)."""

from __future__ import annotations

from ..config import SimSettings
from .world import World, residual_threshold, set_step


class Settling:
    """Which ticks settle, and the step configuration on entering and leaving them.

    Substeps are solved to the same relative precision as full steps: the residual threshold is
    absolute and impulses shrink with the step.
    """

    def __init__(self, settings: SimSettings, world: World):
        group = settings.settling
        self.substeps = group.substeps
        self.ticks = int(round(group.duration_s / world.time_step_s)) if group.substeps > 1 else 0
        self._settings, self._world = settings, world

    def covers(self, tick: int) -> bool:
        return tick < self.ticks

    def begin(self) -> None:
        if self.ticks:
            world = self._world
            set_step(world, world.time_step_s / self.substeps,
                     residual_threshold(self._settings, world.scale_m, 1 / self.substeps))

    def end(self) -> None:
        """Back to the world's own step (called after the last settling tick)."""
        world = self._world
        set_step(world, world.time_step_s, residual_threshold(self._settings, world.scale_m))
