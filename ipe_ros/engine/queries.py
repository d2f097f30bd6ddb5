"""Query predicates on (initial, final) states of one rollout (paper SI "Query definitions").

Pure numpy. Positions are (n, 3) arrays in metres for the dynamic boxes, in scene order.
"""

from __future__ import annotations

import math

import numpy as np

from .scene import Scene, Table, box_half_heights


def fallen_mask(initial_m: np.ndarray, final_m: np.ndarray, min_extents_m: np.ndarray,
                threshold_fraction: float) -> np.ndarray:
    """True where a box's centre dropped by more than ``threshold_fraction`` of its smallest extent."""
    drop = initial_m[:, 2] - final_m[:, 2]
    return drop > threshold_fraction * min_extents_m


def fall_direction_rad(initial_m: np.ndarray, final_m: np.ndarray, fallen: np.ndarray) -> float | None:
    """Angle of the mean horizontal displacement of the fallen boxes; None when none fell."""
    if not fallen.any():
        return None
    mean = (final_m[fallen, :2] - initial_m[fallen, :2]).mean(axis=0)
    if not np.any(mean):
        return None
    return float(math.atan2(mean[1], mean[0]))


def far_m(final_m: np.ndarray, fallen: np.ndarray, base_xy_m: np.ndarray) -> float:
    """Largest horizontal distance of a fallen box from the tower base (0 when none fell)."""
    if not fallen.any():
        return 0.0
    return float(np.linalg.norm(final_m[fallen, :2] - base_xy_m, axis=1).max())


def fell_off_mask(final_m: np.ndarray, table_top_m: float) -> np.ndarray:
    """Paper Exp. 5: a box fell off when its centre ends below the table top."""
    return final_m[:, 2] < table_top_m


def bump_ratio(fell_off: np.ndarray, groups: tuple[str, ...], group: str) -> float | None:
    """Share of ``group`` among the boxes that fell off (paper: red / (red + yellow)); None if none did."""
    total = int(fell_off.sum())
    if total == 0:
        return None
    in_group = np.array([g == group for g in groups])
    return float((fell_off & in_group).sum() / total)


def tower_base_xy_m(scene: Scene) -> np.ndarray:
    """Horizontal centroid of the dynamic boxes that rest directly on the support (the tower's base)."""
    boxes = scene.dynamic_boxes
    positions = np.array([b.position_m for b in boxes], float)
    lows = positions[:, 2] - box_half_heights(np.array([b.extents_m for b in boxes], float),
                                              np.array([b.orientation_xyzw for b in boxes], float))
    top = scene.support.top_m
    scale = min(min(b.extents_m) for b in boxes)
    on_support = np.abs(lows - top) <= 0.05 * scale
    if isinstance(scene.support, Table):
        on_support &= np.array([scene.support.covers_xy(x, y) for x, y in positions[:, :2]])
    chosen = positions[on_support] if on_support.any() else positions[[int(np.argmin(lows))]]
    return chosen[:, :2].mean(axis=0)
