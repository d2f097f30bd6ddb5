"""Collapse steps: coarser steps once something has clearly fallen (see config.CollapseSettings)."""

from __future__ import annotations

import numpy as np

from ..config import SimSettings


class CollapseWatch:
    """Watches for the first clear fall; from then on the scene is collapsing.

    ``collapse_below_z_m`` (per dynamic body): the scene is collapsing once any body is below its
    height, looked at after the push and the settling.
    """

    def __init__(self, settings: SimSettings, collapse_below_z_m: np.ndarray | None):
        self._group = settings.collapse
        self._below_z = collapse_below_z_m
        self.watching = collapse_below_z_m is not None and settings.collapse.enabled
        self.collapsing = False

    @property
    def active(self) -> bool:
        return self.watching or self.collapsing

    def look(self, tick: int, quiet_from_tick: int, heights_m: np.ndarray | None) -> bool:
        """True when the collapse starts at this look."""
        if self.watching and tick >= quiet_from_tick and np.any(heights_m < self._below_z):
            # Something fell: what follows is chaotic at any step size, so only its statistics
            # matter and coarser steps reproduce them (benchmarks/accuracy_vs_time.py).
            self.watching, self.collapsing = False, True
            return True
        return False

    def end(self) -> None:
        """Back to fine steps for the rest of the rollout."""
        self.watching = self.collapsing = False

    def coarse_factor(self, allowed_ticks: int) -> int:
        """Ticks per step while collapsing: as coarse as the preset and the travel limit allow."""
        return max(1, min(self._group.step_factor, allowed_ticks))
