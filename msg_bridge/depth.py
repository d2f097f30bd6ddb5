"""Depth camera messages <-> numpy: ``sensor_msgs/Image`` depth, ``sensor_msgs/CameraInfo`` and the
camera's ``geometry_msgs/PoseStamped``. Pure functions; bad input raises ``ValueError`` naming the field."""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import CameraInfo, Image

from ipe_ros.engine.errors import ConfigError

from .stamps import header_to_stamp_ns, stamp_ns_to_header

#: Depth encodings a depth camera driver publishes (REP 118): float metres or integer millimetres.
DEPTH_ENCODINGS = {"32FC1": (np.float32, 1.0), "16UC1": (np.uint16, 0.001), "mono16": (np.uint16, 0.001)}


def image_to_depth_m(msg: Image) -> np.ndarray:
    """(height, width) float metres; 0 and NaN stay (no reading)."""
    if msg.encoding not in DEPTH_ENCODINGS:
        raise ConfigError("image.encoding", f"must be a depth encoding ({', '.join(DEPTH_ENCODINGS)}), got "
                                            f"{msg.encoding!r}")
    dtype, scale = DEPTH_ENCODINGS[msg.encoding]
    itemsize = np.dtype(dtype).itemsize
    for name in ("height", "width"):
        if getattr(msg, name) < 1:
            raise ConfigError(f"image.{name}", f"must be >= 1 pixel, got {getattr(msg, name)}: an empty image")
    if msg.step < msg.width * itemsize:
        raise ConfigError("image.step", f"{msg.step} bytes per row cannot hold {msg.width} pixels of {msg.encoding}")
    data = bytes(msg.data)
    if len(data) < msg.step * msg.height:
        raise ConfigError("image.data", f"holds {len(data)} bytes, {msg.step} x {msg.height} expected")
    rows = np.frombuffer(data, np.uint8, count=msg.step * msg.height).reshape(msg.height, msg.step)
    pixels = rows[:, :msg.width * itemsize].copy().view(np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<"))
    return pixels.astype(float) * scale


def depth_m_to_image(depth_m: np.ndarray, stamp_ns: int, frame_id: str, encoding: str = "32FC1") -> Image:
    """The inverse of ``image_to_depth_m`` (little-endian; 16UC1 rounds to millimetres)."""
    if encoding not in DEPTH_ENCODINGS:
        raise ConfigError("encoding", f"must be one of {', '.join(DEPTH_ENCODINGS)}, got {encoding!r}")
    dtype, scale = DEPTH_ENCODINGS[encoding]
    depth = np.asarray(depth_m, float)
    values = depth.astype(np.float32) if dtype == np.float32 else \
        np.clip(np.round(np.nan_to_num(depth, nan=0.0) / scale), 0, 65535).astype("<u2")
    return Image(header=stamp_ns_to_header(stamp_ns, frame_id), height=depth.shape[0], width=depth.shape[1],
                 encoding=encoding, is_bigendian=0, step=depth.shape[1] * values.itemsize, data=values.tobytes())


def camera_info_to_dict(msg: CameraInfo) -> dict:
    """The fields ``vision.camera.camera_from_info`` reads (it takes P for a rectified image, applies
    binning and the region of interest as image_geometry does)."""
    roi = msg.roi
    return {"width": int(msg.width), "height": int(msg.height), "k": [float(v) for v in msg.k],
            "p": [float(v) for v in msg.p], "d": [float(v) for v in msg.d],
            "binning_x": int(msg.binning_x), "binning_y": int(msg.binning_y),
            "roi": {"x_offset": int(roi.x_offset), "y_offset": int(roi.y_offset), "width": int(roi.width),
                    "height": int(roi.height)}}


def pose_to_tuples(msg: PoseStamped) -> tuple[tuple[float, float, float], tuple[float, float, float, float], str, int]:
    """(position, orientation xyzw, frame id, stamp ns) of a camera pose; refuses non-finite or non-unit values."""
    p, q = msg.pose.position, msg.pose.orientation
    position = (float(p.x), float(p.y), float(p.z))
    orientation = (float(q.x), float(q.y), float(q.z), float(q.w))
    if not all(map(math.isfinite, position + orientation)):
        raise ConfigError("camera_pose.pose", "must be finite numbers")
    if abs(math.sqrt(sum(v * v for v in orientation)) - 1) > 1e-3:
        raise ConfigError("camera_pose.pose.orientation", f"must be a unit quaternion, got {list(orientation)}")
    return position, orientation, msg.header.frame_id, header_to_stamp_ns(msg.header)


# Depth perception's topics as the engine declares them (engine/vision/depth_source.py): each
# message converted as it arrives, given what the other topics hold, into (value, frame id).

def received_camera_info(msg: CameraInfo, held, values) -> tuple[dict, str]:
    return camera_info_to_dict(msg), msg.header.frame_id


def received_camera_pose(msg: PoseStamped, held, values) -> tuple[tuple, str]:
    position, orientation, frame, _ = pose_to_tuples(msg)
    return (position, orientation), frame


def received_depth_image(msg: Image, held, values):
    """A depth image made an observation with the newest camera info and the camera's pose (the
    ``depth.camera_pose`` parameter when set, in ``frame_id``; else the newest on ~/depth/camera_pose)."""
    from ipe_ros.engine.vision.camera import camera_from_info
    from ipe_ros.engine.vision.depth_model import DepthObservation
    from ipe_ros.engine.vision.depth_source import fixed_camera_pose

    fixed = fixed_camera_pose(values)
    pose = (fixed, str(values["frame_id"])) if fixed is not None else None
    if pose is None and "~/depth/camera_pose" in held:
        pose = (held["~/depth/camera_pose"].value, held["~/depth/camera_pose"].frame_id)
    if "~/depth/camera_info" not in held:
        raise ConfigError("camera_info", "no CameraInfo received yet on ~/depth/camera_info")
    if pose is None:
        raise ConfigError("camera_pose", "no camera pose yet: publish ~/depth/camera_pose or set depth.camera_pose")
    camera = camera_from_info(held["~/depth/camera_info"].value, *pose[0])
    return DepthObservation(camera, image_to_depth_m(msg)), pose[1]
