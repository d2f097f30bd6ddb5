"""A scene at a perception's pose: the one place a posterior's state becomes a scene (the vision
chain's positions, the depth chain's positions, yaws and tilts)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.spatial.transform import Rotation

from ..scene.bodies import Scene
from ..scene.shapes import quaternion_product


def scene_at_pose(scene: Scene, positions_m: np.ndarray, yaws_rad: np.ndarray | None = None,
                  tilts_rad: np.ndarray | None = None) -> Scene:
    """The scene with its dynamic objects at these positions (frame origins), turned by these yaws from
    their published orientation (none: as published, untouched) and then tilted by these tilts
    (rotation vectors (a, b, 0) about the scene's axes; none: as published), their own noise removed
    (the posterior stands in for it)."""
    dynamic = [body for body in scene.objects if not body.static]
    if yaws_rad is None and tilts_rad is None:  # positions alone (the vision posterior's states)
        moved = iter(positions_m)
        return dataclasses.replace(scene, objects=tuple(
            b if b.static else dataclasses.replace(b, position_m=tuple(float(v) for v in next(moved)),
                                                  position_sigma_m=0.0, yaw_sigma_rad=None)
            for b in scene.objects))
    if yaws_rad is None:
        yaws_rad = np.zeros(len(dynamic))
    tilts = np.zeros((len(dynamic), 2)) if tilts_rad is None else np.asarray(tilts_rad, float)
    # every object's turn and tilt composed in one call each (per object, scipy's overhead was most of
    # a 10-block posterior's 48 scenes' 0.12 s)
    turns = [(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)) for yaw in yaws_rad]
    tilt_quats = Rotation.from_rotvec(np.column_stack([tilts, np.zeros(len(dynamic))])).as_quat()
    orientations = iter(quaternion_product(tilt_quats, quaternion_product(
        np.array(turns).reshape(-1, 4), np.array([body.orientation_xyzw for body in dynamic]).reshape(-1, 4))))
    positions = iter(positions_m)
    objects = []
    for body in scene.objects:
        if body.static:
            objects.append(body)
            continue
        position, orientation = next(positions), next(orientations)
        objects.append(dataclasses.replace(body, position_m=tuple(float(v) for v in position),
                                           orientation_xyzw=tuple(float(v) for v in orientation),
                                           position_sigma_m=0.0, yaw_sigma_rad=None))
    return dataclasses.replace(scene, objects=tuple(objects))
