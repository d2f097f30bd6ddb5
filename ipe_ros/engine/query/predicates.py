"""Query predicates on (initial, final) states of one rollout (paper SI "Query definitions").

Pure numpy. Positions are (n, 3) arrays in metres of the dynamic bodies' centres of mass, in scene
order. "Smallest extent" is the smallest side of a body's bounding box in its own frame (a sphere's
diameter, a cylinder's diameter or length).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..scene.bodies import Scene, Table, half_heights_m


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
    """Horizontal centroid of the dynamic bodies that rest directly on the support (the tower's base)."""
    return _tower_base_xy_m(scene).copy()


@functools.lru_cache(maxsize=16)
def _tower_base_xy_m(scene: Scene) -> np.ndarray:
    # a function of the scene as given, read by every rollout of it (half a millisecond per rollout
    # in the bodies' rotation matrices); a worker unpickles its own copy of the scene for each sample,
    # so the cache is keyed by value (a scene's hash costs ~20 us)
    bodies = scene.dynamic_objects
    positions = np.array([b.centre_of_mass_m for b in bodies], float)
    lows = positions[:, 2] - half_heights_m(bodies, np.array([b.orientation_xyzw for b in bodies], float))
    top = scene.support.top_m
    scale = min(b.smallest_extent_m for b in bodies)
    on_support = np.abs(lows - top) <= 0.05 * scale
    if isinstance(scene.support, Table):
        on_support &= scene.support.covers_xy(positions[:, 0], positions[:, 1])
    chosen = positions[on_support] if on_support.any() else positions[[int(np.argmin(lows))]]
    return chosen[:, :2].mean(axis=0)
