"""``final_pose``: where each object ends up, in the scene frame: per object the mean final
position and its standard deviation over the rollouts (metres), and the circular mean of the final
yaw (rotation about +z of the object's own x axis, ZYX convention) with its circular standard
deviation (radians; None when the yaws cancel)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..results.stats import circular_mean
from .base import Query, Reading, Samples


#: an object "moved" (the yes/no outcome the self-check compares) when its centre ends farther than
#: this fraction of its smallest extent from where it started
MOVED_FRACTION = 0.5


def yaw_rad(orientations_xyzw: np.ndarray) -> np.ndarray:
    """Yaw (ZYX Euler) of each xyzw quaternion."""
    x, y, z, w = np.asarray(orientations_xyzw, float).T
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


class FinalPose(Query):
    name = "final_pose"
    fields = ("final_pose",)
    summary = "per object: mean and spread of where it ends up (position, yaw)"

    def read(self, reading: Reading) -> dict[str, Any]:
        moved = np.linalg.norm(reading.final_m - reading.initial_m, axis=1) > MOVED_FRACTION * reading.smallest_extents_m
        return {"final_pose": {"position_m": reading.final_m.copy(),
                               "yaw_rad": yaw_rad(reading.final_orientations_xyzw), "moved": moved}}

    def flags(self, rollout) -> dict[str, list[float]]:
        # what the self-check compares: which objects ended far from where they started
        if rollout.get("final_pose") is None:
            return {}
        return {"final_pose": [float(v) for v in rollout.value("final_pose")["moved"]]}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        positions = np.array([r.value("final_pose")["position_m"] for r in samples.rollouts])  # (rollouts, n, 3)
        yaws = np.array([r.value("final_pose")["yaw_rad"] for r in samples.rollouts])
        spread = positions.std(axis=0, ddof=1) if len(positions) > 1 else np.zeros(positions.shape[1:])
        out = {}
        for i, name in enumerate(samples.names):
            resultant = float(np.hypot(np.cos(yaws[:, i]).mean(), np.sin(yaws[:, i]).mean()))
            mean_yaw = circular_mean(yaws[:, i])
            out[name] = {"position_m": [float(v) for v in positions[:, i].mean(axis=0)],
                         "position_sd_m": [float(v) for v in spread[i]],
                         "yaw_rad": mean_yaw,
                         "yaw_sd_rad": None if mean_yaw is None else math.sqrt(max(0.0, -2 * math.log(min(1.0, resultant))))}
        return {"final_pose": out}

    def describe(self, prediction) -> list[str]:
        lines = []
        for name, pose in (prediction.final_pose or {}).items():
            x, y, z = pose["position_m"]
            sx, sy, sz = pose["position_sd_m"]
            yaw = "-" if pose["yaw_rad"] is None else f"{math.degrees(pose['yaw_rad']):.0f} deg"
            lines.append(f"{name} ends at ({x:.3f}, {y:.3f}, {z:.3f}) m, sd ({sx:.3f}, {sy:.3f}, {sz:.3f}), yaw {yaw}")
        return lines


QUERY = FinalPose()
