"""A depth camera's evidence as a robot saves it: the image (16-bit PNG of millimetres or .npy), its
camera_info YAML and the camera's pose; and a worked example of all three. Every file is bounded
before it is parsed.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ..errors import ConfigError, clip
from ..scene.bodies import Scene
from .camera import MAX_SIDE_PX, camera_from_info, look_at
from .depth_model import DepthObservation
from .tinyrenderer import depth_with_pybullet


#: a camera_info file is a few hundred bytes; anything far larger is not one
MAX_CAMERA_INFO_BYTES = 1 << 20

#: a depth file's size limit: a 4096 x 4096 image of float64 metres
MAX_DEPTH_FILE_BYTES = MAX_SIDE_PX * MAX_SIDE_PX * 8 + (1 << 16)


def load_camera_info(path: str | Path) -> dict:
    """A camera_info YAML (or JSON) file as a mapping: at most MAX_CAMERA_INFO_BYTES, and no YAML
    aliases (camera_info files have none; nested aliases expand exponentially)."""
    import yaml

    class NoAliases(yaml.SafeLoader):
        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                raise yaml.YAMLError("YAML aliases (*name) are not allowed in camera info")
            return super().compose_node(parent, index)

    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_CAMERA_INFO_BYTES:
            raise ConfigError("--camera-info", f"{path.name} is {size} bytes; a camera_info YAML is a few hundred "
                                               f"(at most {MAX_CAMERA_INFO_BYTES})")
        data = yaml.load(path.read_bytes(), Loader=NoAliases)
    except (OSError, yaml.YAMLError) as exc:  # a YAML error spans lines (where, what, the line): one here
        raise ConfigError("--camera-info", f"cannot read {path}: {clip(' '.join(str(exc).split()), 300)}") from None
    if not isinstance(data, dict):
        raise ConfigError("--camera-info", f"{path.name}: must be a mapping with image_width, image_height and "
                                           "camera_matrix")
    return data


def load_depth_image(path: str | Path) -> np.ndarray:
    """Metres, as float: a .npy of float metres (or integer millimetres) or a 16-bit PNG of
    millimetres (0: no reading), as depth cameras write them. The size is checked before the pixels
    are read; an 8-bit, palette or colour PNG (or another format named .png) is refused, not read as
    millimetres."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_DEPTH_FILE_BYTES:
            raise ConfigError("--depth", f"{path.name} is {size} bytes, more than a {MAX_SIDE_PX} x {MAX_SIDE_PX} "
                                         "depth image can be")
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as handle:  # the header first: its shape is checked before any pixel is read
                version = np.lib.format.read_magic(handle)
                read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                    np.lib.format.read_array_header_2_0
                shape, _, _ = read_header(handle)
            _check_image_size(path, shape)
            data = np.load(path, allow_pickle=False)
        elif path.suffix.lower() == ".png":
            data = _read_depth_png(path)
        else:
            raise ConfigError("--depth", f"{path.name}: give a .npy (metres, or integer millimetres) or a 16-bit .png "
                                         "(millimetres)")
    except ConfigError:
        raise
    except (OSError, ValueError) as exc:
        raise ConfigError("--depth", f"cannot read {path}: {clip(str(exc), 300)}") from None
    if np.issubdtype(data.dtype, np.integer):
        return data.astype(float) / 1000.0
    if not np.issubdtype(data.dtype, np.floating):
        raise ConfigError("--depth", f"{path.name}: depth must be numbers, got {data.dtype}")
    return data.astype(float)


def _check_image_size(path: Path, shape: tuple) -> None:
    if len(shape) != 2:
        raise ConfigError("--depth", f"{path.name}: a depth image has one channel; got shape {list(shape)}")
    if not all(1 <= side <= MAX_SIDE_PX for side in shape):
        raise ConfigError("--depth", f"{path.name}: {shape[1]} x {shape[0]} pixels; each side must be 1-{MAX_SIDE_PX}")


def _read_depth_png(path: Path) -> np.ndarray:
    from PIL import Image

    try:
        opened = Image.open(path)
    except Image.DecompressionBombError:  # the header claims more pixels than PIL will read at all
        with open(path, "rb") as handle:
            head = handle.read(24)
        width, height = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
        _check_image_size(path, (height, width))
        raise
    with opened as image:
        if image.format != "PNG":
            raise ConfigError("--depth", f"{path.name} is a {image.format} file, not a PNG")
        _check_image_size(path, (image.height, image.width))
        if image.mode not in ("I;16", "I;16B", "I;16L", "I"):
            raise ConfigError("--depth", f"{path.name} is a PNG of mode {image.mode} (8-bit, palette or colour); a "
                                         "depth PNG holds 16-bit millimetres (mode I;16), as depth cameras save them")
        return np.asarray(image)


def load_observation(depth_path: str | Path, camera_info_path: str | Path, camera_pose: str) -> DepthObservation:
    """A depth image with its camera from the files a robot saves: the image, its camera_info YAML and
    the pose text "x,y,z,qx,qy,qz,qw"."""
    position, orientation = parse_pose(camera_pose)
    camera = camera_from_info(load_camera_info(camera_info_path), position, orientation)
    return DepthObservation(camera, load_depth_image(depth_path))


def parse_pose(text: str) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """"x,y,z,qx,qy,qz,qw" -> (position, unit quaternion)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 7 or not all(map(math.isfinite, values)):
        raise ConfigError("--camera-pose", f"must be x,y,z,qx,qy,qz,qw (metres, a unit quaternion), got {text!r}")
    q = np.asarray(values[3:])
    if abs(np.linalg.norm(q) - 1) > 1e-3:
        raise ConfigError("--camera-pose", f"the quaternion must have norm 1, got {np.linalg.norm(q):.4g}")
    return tuple(values[:3]), tuple(values[3:])


def write_depth_example(directory: str | Path, truth: Scene, seed: int = 0) -> dict[str, Path]:
    """A worked example a robot would have: ``truth`` seen by a depth camera (pybullet's renderer,
    noise sd 2 mm + 2.5 mm/m^2 x depth^2, 5% of pixels missing, saved as a 16-bit PNG of mm), the
    camera's camera_info YAML and pose, and the detector's guess of the scene (every object moved
    N(0, 1 cm) in x and y). Returns the files' paths by role."""
    import json

    import yaml
    from PIL import Image

    from ..scene.format import scene_to_dict

    rng = np.random.default_rng(seed)
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    corners = np.array([np.asarray(b.position_m) + s * float(np.linalg.norm(b.extents_m)) / 2
                        for b in truth.dynamic_objects for s in (-1, 1)])
    centre = (corners.min(axis=0) + corners.max(axis=0)) / 2
    radius = float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0))) / 2
    distance = radius / math.tan(math.radians(20)) * 1.1
    azimuth, elevation = math.radians(-60), math.radians(25)
    eye = centre + distance * np.array([math.cos(elevation) * math.cos(azimuth),
                                        math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    camera = look_at(eye, centre)
    clean = depth_with_pybullet(truth, camera, far_m=max(8.0, 3 * distance))
    measured = clean + (0.002 + 0.0025 * clean ** 2) * rng.standard_normal(clean.shape)
    measured = np.where(np.isfinite(measured) & (rng.random(clean.shape) >= 0.05), measured, 0.0)
    guess = dataclasses.replace(truth, objects=tuple(
        dataclasses.replace(b, position_m=(b.position_m[0] + float(rng.normal(0, 0.01)),
                                           b.position_m[1] + float(rng.normal(0, 0.01)), b.position_m[2]))
        if not b.static else b for b in truth.objects))
    paths = {"scene": directory / "scene.json", "truth": directory / "truth.json", "depth": directory / "depth.png",
             "camera_info": directory / "camera_info.yaml", "camera_pose": directory / "camera_pose.txt"}
    paths["scene"].write_text(json.dumps(scene_to_dict(guess), indent=1) + "\n")
    paths["truth"].write_text(json.dumps(scene_to_dict(truth), indent=1) + "\n")
    Image.fromarray(np.clip(np.round(measured * 1000), 0, 65535).astype(np.uint16)).save(paths["depth"])
    paths["camera_info"].write_text(yaml.safe_dump({
        "image_width": camera.width_px, "image_height": camera.height_px, "camera_name": "ipe_example_depth",
        "camera_matrix": {"rows": 3, "cols": 3, "data": [camera.fx, 0.0, camera.cx, 0.0, camera.fy, camera.cy,
                                                         0.0, 0.0, 1.0]},
        "distortion_model": "plumb_bob", "distortion_coefficients": {"rows": 1, "cols": 5, "data": [0.0] * 5},
        "projection_matrix": {"rows": 3, "cols": 4, "data": [camera.fx, 0.0, camera.cx, 0.0, 0.0, camera.fy, camera.cy,
                                                             0.0, 0.0, 0.0, 1.0, 0.0]}},
        sort_keys=False))
    paths["camera_pose"].write_text(",".join(f"{v:.6f}" for v in (*camera.position_m, *camera.orientation_xyzw)) + "\n")
    return paths
