"""Collapse steps: coarser steps once something has clearly fallen (see config.CollapseSettings)."""

from __future__ import annotations

import numpy as np

from ..config import SimSettings
from .world import World, pybullet, residual_threshold, set_step


class CollapseSteps:
    """Watches for the first clear fall, then chooses each stretch's step from the fastest corner.

    ``collapse_below_z_m`` (per dynamic box): the scene is collapsing once any box is below its
    height, looked at after the push and the settling.
    """

    def __init__(self, settings: SimSettings, world: World, collapse_below_z_m: np.ndarray | None,
                 half_diagonals_m: np.ndarray, gravity_m_s2: float, look_every_ticks: int):
        self._settings, self._world = settings, world
        self._below_z = collapse_below_z_m
        self.watching = collapse_below_z_m is not None and settings.collapse.enabled
        self.collapsing = False
        self._half_diagonals_m = half_diagonals_m
        self._g = gravity_m_s2
        self._look_every = look_every_ticks
        self.ticks_per_step = 1

    @property
    def active(self) -> bool:
        return self.watching or self.collapsing

    def look(self, tick: int, quiet_from_tick: int, heights_m: np.ndarray | None, speeds_m_s: np.ndarray,
             spins_rad_s: np.ndarray) -> None:
        """Start the collapse when a box is below its height; while collapsing, set the step."""
        world, group = self._world, self._settings.collapse
        if self.watching and tick >= quiet_from_tick and np.any(heights_m < self._below_z):
            # Something fell: what follows is chaotic at any step size, so only its statistics
            # matter and coarser steps reproduce them (benchmarks/accuracy_vs_time.py).
            self.watching, self.collapsing = False, True
            if group.solver_iterations is not None:
                pybullet().setPhysicsEngineParameter(numSolverIterations=group.solver_iterations,
                                                     physicsClientId=world.client)
        if not self.collapsing:
            return
        # Coarse, but no box may travel more than a fraction of the smallest box per step (else fast
        # blocks sink deep into what they hit): bound the speed until the next look.
        dt = world.time_step_s
        fastest_m_s = float((speeds_m_s + spins_rad_s * self._half_diagonals_m).max()) + self._g * self._look_every * dt
        allowed = int(group.max_travel_fraction * world.scale_m / (fastest_m_s * dt))
        factor = max(1, min(group.step_factor, allowed))
        if factor != self.ticks_per_step:
            self.ticks_per_step = factor
            set_step(world, dt * factor, residual_threshold(self._settings, world.scale_m, factor))
