"""When a rollout may end: early termination once nothing can change the answer any more.

The episode's end is the task's business, not the physics': this module only reads states and
says "stop" (see config.EarlyStopSettings for the rule and its reasons).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import EarlyStopSettings

#: Motion (linear speed in box sizes per second, or angular speed in rad/s, whichever is larger)
#: below which a box's growth over the rest window counts as contact jitter, not a tip starting.
#: Boxes of the paper's stable towers still show a median 0.0025 /s (90th percentile 0.0075 /s)
#: after 1 s; a slow tip that must not be missed goes from 0.007 to 0.008 /s over a window.
#: Absolute, not a fraction of the rest thresholds: loosening those must not blind this check.
REST_NOISE_FLOOR_PER_S = 0.0025


@dataclass(frozen=True)
class DecidedHeights:
    """Per dynamic box, the outcomes already decided (only when nothing but fall / any_fall is asked).

    fallen_below_z_m: a box whose centre is below this height has fallen: its outcome no longer changes,
        though its motion may still change another's (``RestWatch``).
    never_falls: boxes that cannot drop that far whatever happens (a block lying on the floor), or None.
    stop_at_first_fall: the yes/no question "will anything fall?": end at the first fallen box.
    """

    fallen_below_z_m: np.ndarray
    never_falls: np.ndarray | None = None
    stop_at_first_fall: bool = False


class RestWatch:
    """Looks at the boxes every so often and says when the rollout can end."""

    def __init__(self, settings: EarlyStopSettings, scale_m: float, earliest_stop_s: float,
                 decided: DecidedHeights | None, n_boxes: int, radii_m: np.ndarray):
        """``radii_m``: each box's bounding radius (half its diagonal), what it reaches from its centre."""
        self._settings = settings
        self._scale_m = scale_m
        self._rest_speed_m_s = settings.speed_sizes_per_s * scale_m
        self._earliest_stop_s = earliest_stop_s
        self._decided = decided
        self._radii_m = np.asarray(radii_m, float)
        self._resting_since: float | None = None
        self._motion_at_start = np.zeros(n_boxes)
        #: the bodies whose outcome is not decided yet (as of the last look): only they must be at rest
        self.undecided = np.ones(n_boxes, bool)

    @property
    def enabled(self) -> bool:
        return self._settings.enabled

    @property
    def needs_heights(self) -> bool:
        return self._decided is not None

    def should_stop(self, t_s: float, speeds_m_s: np.ndarray, spins_rad_s: np.ndarray,
                    heights_m: np.ndarray | None) -> bool:
        settings = self._settings
        settled = (speeds_m_s < self._rest_speed_m_s) & (spins_rad_s < settings.angular_rad_s)
        out_of_reach = None
        if self._decided is not None:
            fallen_now = heights_m < self._decided.fallen_below_z_m
            if self._decided.stop_at_first_fall and fallen_now.any():
                return True
            never = self._decided.never_falls
            decided = fallen_now if never is None else fallen_now | never
            self.undecided = ~decided
            # a decided box's outcome is settled, not its motion: a fallen block rolling on, or a
            # bottom block shoved along, can still topple one whose outcome is open. Only a box wholly
            # below every open one (fallen off the table) cannot reach them any more
            lowest_open_m = np.min(heights_m - self._radii_m, where=~decided, initial=np.inf)
            out_of_reach = decided & (heights_m + self._radii_m < lowest_open_m)
            settled |= out_of_reach
        if not (t_s >= self._earliest_stop_s and settled.all()):
            self._resting_since = None
            return False
        # how much each box still moves, in 1/s (box sizes per second or rad/s): worked out only
        # once everything is settled, which most looks are not
        motion = np.maximum(speeds_m_s / self._scale_m, spins_rad_s)
        if out_of_reach is not None:
            motion = np.where(out_of_reach, 0.0, motion)
        if self._resting_since is None:
            self._resting_since, self._motion_at_start = t_s, motion
            return False
        if t_s - self._resting_since >= settings.duration_s - 1e-9:
            # A block just starting to tip moves slowly but faster and faster; a settling one slows
            # down. Box by box: another block still settling would mask a slow tip.
            growing = (motion > self._motion_at_start * settings.growth_factor) & (motion > REST_NOISE_FLOOR_PER_S)
            if not growing.any():
                return True
            self._resting_since, self._motion_at_start = t_s, motion
        return False
