"""Pinhole cameras looking at a scene: the SI's evidence is three images from viewpoints 45 degrees apart."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene import Scene


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: ``position_m`` looking at ``target_m`` with +z up, a square image of
    ``resolution_px`` pixels and a vertical/horizontal field of view ``fov_rad``.

    Image axes: u to the right, v down; depth along the viewing direction."""

    position_m: tuple[float, float, float]
    target_m: tuple[float, float, float]
    fov_rad: float
    resolution_px: int

    @property
    def axes(self) -> np.ndarray:
        """Rows: right, down, forward (unit vectors in the scene frame)."""
        return look_at_axes(self.position_m, self.target_m)

    @property
    def width_px(self) -> int:
        return self.resolution_px

    @property
    def height_px(self) -> int:
        return self.resolution_px

    @property
    def focal_px(self) -> float:
        return self.resolution_px / 2 / math.tan(self.fov_rad / 2)

    def project(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) scene points -> ((n, 2) pixel coordinates (u, v), (n,) depths in metres)."""
        local = (np.asarray(points_m, float) - np.asarray(self.position_m, float)) @ self.axes.T
        depth = local[:, 2]
        pixels = self.focal_px * local[:, :2] / depth[:, None] + self.resolution_px / 2
        return pixels, depth


def look_at_axes(position_m, target_m) -> np.ndarray:
    """Rows: right, down, forward (unit vectors in the scene frame) of a camera at ``position_m``
    looking at ``target_m`` with +z up in its image."""
    forward = np.asarray(target_m, float) - np.asarray(position_m, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def cameras_for(scene: Scene, settings) -> tuple[Camera, ...]:
    """The cameras a ``VisionSettings`` asks for (views, separation, resolution) around ``scene``."""
    return default_cameras(scene, settings.views, math.radians(settings.separation_deg), settings.resolution_px)


def default_cameras(scene: Scene, views: int = 3, separation_rad: float = math.radians(45),
                    resolution_px: int = 256, elevation_rad: float = math.radians(20),
                    fov_rad: float = math.radians(40), first_azimuth_rad: float = math.radians(-90)) -> tuple[Camera, ...]:
    """``views`` cameras ``separation_rad`` apart around the vertical through the dynamic bodies'
    centre, far enough that the bodies' bounding sphere fills about 80% of the image."""
    corners = np.array([np.asarray(b.position_m) + s * np.asarray(b.extents_m) / 2
                        for b in scene.dynamic_objects for s in ((-1, -1, -1), (1, 1, 1))])
    low, high = corners.min(axis=0), corners.max(axis=0)
    centre = (low + high) / 2
    radius = float(np.linalg.norm(high - low) / 2)
    distance = radius / math.sin(fov_rad / 2) / 0.8
    cameras = []
    for i in range(views):
        azimuth = first_azimuth_rad + i * separation_rad
        offset = distance * np.array([math.cos(elevation_rad) * math.cos(azimuth),
                                      math.cos(elevation_rad) * math.sin(azimuth), math.sin(elevation_rad)])
        cameras.append(Camera(position_m=tuple(float(v) for v in centre + offset),
                              target_m=tuple(float(v) for v in centre), fov_rad=fov_rad, resolution_px=resolution_px))
    return tuple(cameras)
