"""Settling: the first ticks of a rollout in finer substeps (see config.SettlingSettings)."""

from __future__ import annotations

from ..config import SimSettings


class Settling:
    """Which ticks settle, and into how many substeps each is cut."""

    def __init__(self, settings: SimSettings, time_step_s: float):
        group = settings.settling
        self.substeps = group.substeps
        self.ticks = int(round(group.duration_s / time_step_s)) if group.substeps > 1 else 0

    def covers(self, tick: int) -> bool:
        return tick < self.ticks
