"""One pinhole camera model for every image the engine reads or makes, in ROS's convention.

``sensor_msgs/CameraInfo`` and image_geometry's ``PinholeCameraModel`` follow OpenCV: in a rectified
image the pixel in column u and row v has its centre at image coordinates (u, v) (not u + 0.5), a
point (x, y, z) of the camera's optical frame (REP 103: x right, y down, z forward) appears at
(fx x / z + cx, fy y / z + cy), and the ray through pixel (u, v) is ((u - cx) / fx, (v - cy) / fy, 1).
A camera whose principal point is the image's centre has cx = (width - 1) / 2. The rasteriser, the
depth model and the recordings all sample pixels this way (``tests/test_camera.py`` checks it against
depth written from the formula above, sharing no code with them).

The SI's grey images (three views 45 degrees apart) and a robot's depth camera are both this camera:
the former built by ``look_at``, the latter from its ``camera_info`` (``camera_from_info``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..checks import integer, positive
from ..errors import ConfigError, clip
from ..scene.limits import MAX_COORDINATE_M
from ..scene.bodies import Scene
from ..scene.shapes import rotation_matrix

#: fields of view a rectified pinhole image can have (a telephoto lens, a wide-angle one)
MIN_FOV_DEG, MAX_FOV_DEG = 0.5, 170.0

#: the largest image side read or rendered (a 4096 px camera is 16.8 Mpx; each view keeps a few
#: float layers of it per object in view)
MAX_SIDE_PX = 4096


@dataclass(frozen=True)
class PinholeCamera:
    """A rectified pinhole camera (``fx``, ``fy``, ``cx``, ``cy`` in pixels, as in CameraInfo's P or K;
    pixel centres at integer coordinates) with a ``width_px`` x ``height_px`` image, at a pose in the
    scene frame: ``position_m`` and ``orientation_xyzw`` of its optical frame (z forward, x right,
    y down in the image)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width_px: int
    height_px: int
    position_m: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            positive(getattr(self, name), f"camera_info.{name}")
        for name in ("cx", "cy"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"camera_info.{name}", f"must be a finite number, got {value!r}")
        for name in ("width_px", "height_px"):
            integer(getattr(self, name), f"camera_info.{name}", 8, MAX_SIDE_PX)
        for name, side in (("fx", self.width_px), ("fy", self.height_px)):
            fov_deg = math.degrees(2 * math.atan(side / 2 / getattr(self, name)))
            if not MIN_FOV_DEG <= fov_deg <= MAX_FOV_DEG:
                raise ConfigError(f"camera_info.{name}", f"{getattr(self, name):.6g} px gives a {fov_deg:.3g} degree "
                                                         f"field of view across {side} px; a camera's is "
                                                         f"{MIN_FOV_DEG:g}-{MAX_FOV_DEG:g} (is K in pixels?)")
        position = np.asarray(self.position_m, float)
        q = np.asarray(self.orientation_xyzw, float)
        if position.shape != (3,) or not np.all(np.abs(position) <= MAX_COORDINATE_M):
            raise ConfigError("camera_pose.position_m", f"must be 3 numbers within {MAX_COORDINATE_M:g} m of the "
                                                        f"scene's origin, got {clip(repr(list(self.position_m)), 120)}")
        if q.shape != (4,) or not np.all(np.isfinite(q)) or abs(np.linalg.norm(q) - 1) > 1e-3:
            raise ConfigError("camera_pose.orientation_xyzw", f"must be a unit quaternion, got {list(self.orientation_xyzw)!r}")

    @functools.cached_property
    def axes(self) -> np.ndarray:
        """Rows: the optical frame's x (right), y (down), z (forward) in the scene frame (computed
        once: a chain projects every proposal through it)."""
        axes = rotation_matrix(self.orientation_xyzw).T
        axes.flags.writeable = False
        return axes

    def project(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3) scene points -> ((n, 2) image coordinates (u, v), (n,) depths along the optical axis)."""
        local = (np.asarray(points_m, float) - np.asarray(self.position_m, float)) @ self.axes.T
        depth = local[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            pixels = np.stack([self.fx * local[:, 0] / depth + self.cx, self.fy * local[:, 1] / depth + self.cy], axis=1)
        return pixels, depth

    def rays(self) -> np.ndarray:
        """(height, width, 3) scene-frame direction of every pixel centre's ray, scaled so that its
        optical-axis component is 1 (a point at depth d along it is position + d * ray)."""
        u = (np.arange(self.width_px) - self.cx) / self.fx
        v = (np.arange(self.height_px) - self.cy) / self.fy
        local = np.stack(np.broadcast_arrays(u[None, :], v[:, None], np.ones((self.height_px, self.width_px))), axis=-1)
        return local @ self.axes

    def rays_at(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """(n, 3) ``rays()`` of the pixels (rows[i], columns[i]) alone."""
        local = np.stack([(np.asarray(columns) - self.cx) / self.fx, (np.asarray(rows) - self.cy) / self.fy,
                          np.ones(len(rows))], axis=1)
        return local @ self.axes


def look_at_axes(position_m, target_m) -> np.ndarray:
    """Rows: right, down, forward (unit vectors in the scene frame) of a camera at ``position_m``
    looking at ``target_m`` with +z up in its image."""
    forward = np.asarray(target_m, float) - np.asarray(position_m, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward])


def look_at(position_m, target_m, width_px: int = 320, height_px: int = 240,
            horizontal_fov_rad: float = math.radians(58)) -> PinholeCamera:
    """A camera at ``position_m`` looking at ``target_m`` (image up towards +z), square pixels, the
    principal point at the image's centre; the default field of view is a Kinect's."""
    from scipy.spatial.transform import Rotation

    # the optical axes (x right, y down, z forward) are the look-at camera's, as columns
    q = Rotation.from_matrix(look_at_axes(position_m, target_m).T).as_quat()
    f = width_px / 2 / math.tan(horizontal_fov_rad / 2)
    return PinholeCamera(fx=f, fy=f, cx=(width_px - 1) / 2, cy=(height_px - 1) / 2, width_px=width_px,
                         height_px=height_px, position_m=tuple(float(v) for v in position_m),
                         orientation_xyzw=tuple(float(v) for v in q))


def cameras_for(scene: Scene, settings) -> tuple[PinholeCamera, ...]:
    """The cameras a ``VisionSettings`` asks for (views, separation, resolution) around ``scene``."""
    return default_cameras(scene, settings.views, math.radians(settings.separation_deg), settings.resolution_px)


def default_cameras(scene: Scene, views: int = 3, separation_rad: float = math.radians(45),
                    resolution_px: int = 256, elevation_rad: float = math.radians(20),
                    fov_rad: float = math.radians(40),
                    first_azimuth_rad: float = math.radians(-90)) -> tuple[PinholeCamera, ...]:
    """``views`` square cameras ``separation_rad`` apart around the vertical through the dynamic
    bodies' centre, far enough that the bodies' bounding sphere fills about 80% of the image."""
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
        cameras.append(look_at(centre + offset, centre, resolution_px, resolution_px, fov_rad))
    return tuple(cameras)


def camera_from_info(info: dict, position_m, orientation_xyzw) -> PinholeCamera:
    """The camera of a rectified image, read as image_geometry reads camera info: from a camera_info
    YAML (``image_width``, ``camera_matrix: {data: [...]}``, ``projection_matrix``,
    ``distortion_coefficients``) or sensor_msgs/CameraInfo's own names (``width``, ``k``, ``p``, ``d``,
    ``binning_x``, ``roi``), at the optical frame's pose in the scene frame.

    The projection matrix P gives fx, fy, cx, cy (a rectified image's intrinsics); K only when P is
    absent or all zero, and then only if the distortion is zero (an image with distortion must be
    rectified first: depth_image_proc's register/rectify, or image_proc). Binning divides the
    resolution and the intrinsics; a region of interest moves the principal point."""
    if not isinstance(info, dict):
        raise ConfigError("camera_info", "must be a mapping with image_width, image_height and camera_matrix")
    width, height = info.get("image_width", info.get("width")), info.get("image_height", info.get("height"))
    k_key, k = _numbers(info, ("camera_matrix", "k", "K"), 9)
    p_key, p = _numbers(info, ("projection_matrix", "p", "P"), 12)
    d_key, d = _numbers(info, ("distortion_coefficients", "d", "D"), None)
    d = d or []
    if p is not None and any(p):
        fx, fy, cx, cy, source = p[0], p[5], p[2], p[6], p_key
    elif k is not None:
        if any(d):
            raise ConfigError(f"camera_info.{d_key}",
                              f"are not zero ({', '.join(f'{v:g}' for v in d)}) and there is no projection "
                              "matrix: rectify the image (image_proc, depth_image_proc) and pass its camera info, "
                              "whose P gives the rectified intrinsics")
        fx, fy, cx, cy, source = k[0], k[4], k[2], k[5], k_key
    else:
        raise ConfigError("camera_info.camera_matrix", "must hold the 9 numbers of K (fx 0 cx, 0 fy cy, 0 0 1) "
                                                       "or the 12 of P")
    binning_x, binning_y = (_binning(info, axis) for axis in ("x", "y"))
    roi = info.get("roi") or {}
    x_offset, y_offset = (int(roi.get(key, 0) or 0) if isinstance(roi, dict) else 0
                          for key in ("x_offset", "y_offset"))
    if isinstance(roi, dict) and int(roi.get("width", 0) or 0) > 0:
        if any(d):
            raise ConfigError("camera_info.roi", "a region of interest of a distorted camera is not supported: "
                                                 "publish the rectified full image")
        width, height = int(roi["width"]), int(roi["height"])
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (width, height)):
        raise ConfigError("camera_info.width", f"image width and height must be integers, got "
                                               f"{clip(repr(width), 40)} x {clip(repr(height), 40)}")
    for name, value in (("fx", fx), ("fy", fy)):
        if not value > 0:
            raise ConfigError(f"camera_info.{source}", f"{name} must be > 0, got {value!r}")
    return PinholeCamera(fx=fx / binning_x, fy=fy / binning_y, cx=(cx - x_offset) / binning_x,
                         cy=(cy - y_offset) / binning_y, width_px=width // binning_x, height_px=height // binning_y,
                         position_m=tuple(position_m), orientation_xyzw=tuple(orientation_xyzw))


def _numbers(info: dict, keys: tuple[str, ...], count: int | None) -> tuple[str | None, list[float] | None]:
    """The first of ``keys`` present, as floats (a YAML matrix's ``data`` or a plain list); the error
    names the key as the file or message spelled it."""
    meaning = {9: "the 9 numbers of K (fx 0 cx, 0 fy cy, 0 0 1)", 12: "the 12 numbers of P (fx 0 cx Tx, 0 fy cy Ty, "
                                                                       "0 0 1 0)", None: "a list of numbers"}[count]
    for key in keys:
        if key in info and info[key] is not None:
            value = info[key]
            value = value.get("data") if isinstance(value, dict) else value
            try:
                numbers = [float(v) for v in value]
            except (TypeError, ValueError):
                numbers = None
            if numbers is None or (count is not None and len(numbers) != count) or \
                    not all(map(math.isfinite, numbers)):
                raise ConfigError(f"camera_info.{key}", f"must hold {meaning}, all finite")
            return key, numbers
    return None, None


def _binning(info: dict, axis: str) -> int:
    value = info.get(f"binning_{axis}", 0) or 0
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 64:
        raise ConfigError(f"camera_info.binning_{axis}", f"must be an integer in [0, 64] (0 and 1: none), got {value!r}")
    return max(value, 1)
