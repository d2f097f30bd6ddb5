"""Uncertainty from the robot's own depth camera: the scene's posterior given depth images.

A hypothesised scene (each dynamic object's x, y and yaw; heights as published, since stacking
gives them) is rendered into the depth the camera would measure - the z-buffer of the hulls (our
rasteriser, ``render.body_patch``) over the support plane, cast per pixel - and compared with the
measured depth pixel by pixel:

    p(d | d_hat) = (1 - outlier) N(d; d_hat, sd(d_hat)) + outlier / max_range,
    sd(d_hat) = sd_m + sd_per_m2 * d_hat^2        (structured light and stereo: error grows with range^2)

Missing pixels (0, NaN, inf) are ignored; the outlier term absorbs unmodelled objects, edges and
flying pixels. Only pixels in the objects' reach count - the published objects' bounding boxes,
grown by ``reach_m``, seen from the camera - so the table and the background far from the objects
do not dominate; a reach pixel with nothing hypothesised in it and no support under it scores the
outlier density alone, the same for every hypothesis. Neighbouring pixels' errors are not
independent (edges, smoothing), so the log-likelihood is divided by ``temperature`` (3: the 95%
intervals then cover 96% of true poses in ``benchmarks/depth.py``) and only every
``pixel_stride``-th pixel in each direction is read.

The prior is the detector's: each object's published pose, x and y with SD ``prior_sd_m`` and yaw
with ``prior_yaw_sd_rad``. A block in plain view is pinned down by its pixels; one hidden behind
another keeps the prior's spread. Metropolis-Hastings with single-object moves (x, y, yaw together)
and an injected Generator; several cameras multiply their likelihoods.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import integer, positive
from ..errors import ConfigError
from ..scene import Floor, Scene
from ..shapes import quaternion_product
from .camera import PinholeCamera, camera_from_info, look_at
from .mcmc import effective_sample_size
from .render import EMPTY, Patch, SceneMesh, body_patch, scene_mesh
from .tinyrenderer import depth_with_pybullet


@dataclass(frozen=True)
class DepthObservation:
    """One measured depth image (metres along the optical axis; 0, NaN or inf: no reading) and the
    camera that took it."""

    camera: PinholeCamera
    depth_m: np.ndarray

    def __post_init__(self) -> None:
        depth = np.asarray(self.depth_m)
        if depth.shape != (self.camera.height_px, self.camera.width_px):
            raise ConfigError("depth", f"the image is {depth.shape[1] if depth.ndim == 2 else '?'} x "
                                       f"{depth.shape[0] if depth.ndim else '?'} pixels but the camera info says "
                                       f"{self.camera.width_px} x {self.camera.height_px}")


@dataclass(frozen=True)
class DepthSettings:
    """The depth perception's model and chain (see the module docstring)."""

    sd_m: float = 0.002
    sd_per_m2: float = 0.0025
    outlier: float = 0.05
    max_range_m: float = 10.0
    reach_m: float = 0.1
    pixel_stride: int = 2
    temperature: float = 3.0
    prior_sd_m: float = 0.03
    prior_yaw_sd_rad: float = 0.2
    proposal_sd_m: float = 0.005
    proposal_yaw_sd_rad: float = 0.03
    updates_per_object: int = 1000
    burn_in_fraction: float = 0.2

    def __post_init__(self) -> None:
        for name in ("sd_m", "max_range_m", "reach_m", "temperature", "prior_sd_m", "prior_yaw_sd_rad",
                     "proposal_sd_m", "proposal_yaw_sd_rad"):
            positive(getattr(self, name), f"depth.{name}")
        if not isinstance(self.sd_per_m2, (int, float)) or not 0 <= self.sd_per_m2 < 1:
            raise ConfigError("depth.sd_per_m2", f"must be in [0, 1), got {self.sd_per_m2!r}")
        if not isinstance(self.outlier, (int, float)) or not 0 < self.outlier < 1:
            raise ConfigError("depth.outlier", f"must be in (0, 1), got {self.outlier!r}")
        integer(self.pixel_stride, "depth.pixel_stride", 1, 16)
        integer(self.updates_per_object, "depth.updates_per_object", 1, 100_000)
        if not isinstance(self.burn_in_fraction, (int, float)) or not 0 <= self.burn_in_fraction < 1:
            raise ConfigError("depth.burn_in_fraction", f"must be in [0, 1), got {self.burn_in_fraction!r}")

    def chain_samples(self, objects: int) -> int:
        """Single-object updates in a chain over ``objects`` objects."""
        return self.updates_per_object * objects

    def burn_in(self, objects: int) -> int:
        return int(self.burn_in_fraction * self.chain_samples(objects))


def support_depth_m(scene: Scene, camera: PinholeCamera) -> np.ndarray:
    """(height, width) depth of the support under every pixel's ray (the floor, the table top within
    its edges, the floor under a table); NaN where the ray meets none."""
    rays = camera.rays()
    origin = np.asarray(camera.position_m, float)
    support = scene.support

    def plane(z: float) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (z - origin[2]) / rays[..., 2]
        t = np.where(t > 0, t, np.nan)
        return t, origin + t[..., None] * rays

    if isinstance(support, Floor):
        return plane(support.height_m)[0]
    t_top, hit = plane(support.top_height_m)
    below = plane(support.floor_z_m)[0] if support.floor_z_m is not None else np.nan
    return np.where(support.covers_xy(hit[..., 0], hit[..., 1]), t_top, below)


def _reach_mask(scene: Scene, camera: PinholeCamera, reach_m: float) -> np.ndarray:
    """Pixels that see the published objects' bounding boxes grown by ``reach_m``."""
    from ..shapes import BoxShape
    from ..scene import Body

    boxes = []
    for body in scene.dynamic_objects:
        extent = float(np.linalg.norm(body.extents_m)) + 2 * reach_m  # any yaw, any moved position within reach
        boxes.append(Body(name=body.name, shape=BoxShape((extent, extent, float(body.extents_m[2]) + 2 * reach_m)),
                          position_m=body.centre_of_mass_m, orientation_xyzw=(0.0, 0.0, 0.0, 1.0), friction=0.5,
                          restitution=0.0, mass_kg=1.0))
    mesh = scene_mesh(dataclasses.replace(scene, objects=tuple(boxes)))
    mask = np.zeros((camera.height_px, camera.width_px), bool)
    for b in range(len(boxes)):
        patch = body_patch(mesh, camera, b, mesh.positions_m[b])
        mask[patch.v0:patch.v1, patch.u0:patch.u1] |= np.isfinite(patch.depth)
    return mask


class DepthModel:
    """Every camera's measured depth at the pixels read, and the hypothesis' rendered depth, updated
    one moved object at a time (each object keeps its own depth layer per camera, as
    ``mcmc.ImageModel`` does for grey images)."""

    def __init__(self, scene: Scene, mesh: SceneMesh, observations: tuple[DepthObservation, ...],
                 settings: DepthSettings):
        self.mesh, self.observations, self.settings = mesh, observations, settings
        stride = settings.pixel_stride
        self.read, self.measured, self.support = [], [], []
        for obs in observations:
            measured = np.asarray(obs.depth_m, float)
            valid = np.isfinite(measured) & (measured > 0)
            grid = np.zeros_like(valid)
            grid[::stride, ::stride] = True
            self.read.append(valid & grid & _reach_mask(scene, obs.camera, settings.reach_m))
            self.measured.append(np.where(valid, measured, np.nan))
            self.support.append(support_depth_m(scene, obs.camera))
        self.log_outlier = math.log(settings.outlier / settings.max_range_m)

    def _pixel_ll(self, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        s = self.settings
        sd = s.sd_m + s.sd_per_m2 * np.where(np.isfinite(predicted), predicted, 0.0) ** 2
        with np.errstate(invalid="ignore", over="ignore"):
            normal = np.exp(-0.5 * ((measured - predicted) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
        inlier = np.where(np.isfinite(predicted), (1 - s.outlier) * normal, 0.0)
        return np.log(inlier + s.outlier / s.max_range_m)

    def _region_ll(self, v: int, region, depth_layers: np.ndarray) -> float:
        v0, v1, u0, u1 = region
        read = self.read[v][v0:v1, u0:u1]
        if not read.any():
            return 0.0
        nearest = depth_layers.min(axis=0)
        support = self.support[v][v0:v1, u0:u1]
        predicted = np.where(np.isfinite(nearest), nearest, support)  # NaN: nothing there, outlier density only
        predicted = np.where(np.isnan(predicted), np.inf, predicted)
        return float(self._pixel_ll(self.measured[v][v0:v1, u0:u1][read], predicted[read]).sum())

    def start(self, positions_m: np.ndarray, yaws_rad: np.ndarray) -> float:
        bodies = len(positions_m)
        self.layers = [np.full((bodies, obs.camera.height_px, obs.camera.width_px), np.inf) for obs in self.observations]
        self.patches = [[EMPTY] * bodies for _ in self.observations]
        for v, obs in enumerate(self.observations):
            for b in range(bodies):
                self._place(v, b, body_patch(self.mesh, obs.camera, b, positions_m[b], yaws_rad[b]))
        self.current = sum(self._region_ll(v, (0, obs.camera.height_px, 0, obs.camera.width_px), self.layers[v])
                           for v, obs in enumerate(self.observations)) / self.settings.temperature
        return self.current

    def _place(self, v: int, b: int, patch: Patch) -> None:
        old = self.patches[v][b]
        self.layers[v][b, old.v0:old.v1, old.u0:old.u1] = np.inf
        self.layers[v][b, patch.v0:patch.v1, patch.u0:patch.u1] = patch.depth
        self.patches[v][b] = patch

    def propose(self, body: int, position_m, yaw_rad: float) -> float:
        """The (tempered) log-likelihood with ``body`` moved; pending until ``accept``."""
        change, self._pending = 0.0, []
        for v, obs in enumerate(self.observations):
            new, old = body_patch(self.mesh, obs.camera, body, position_m, yaw_rad), self.patches[v][body]
            boxes = [p for p in (new, old) if p.v1 > p.v0]
            if not boxes:
                self._pending.append(None)
                continue
            region = (min(p.v0 for p in boxes), max(p.v1 for p in boxes), min(p.u0 for p in boxes),
                      max(p.u1 for p in boxes))
            v0, v1, u0, u1 = region
            layers = self.layers[v][:, v0:v1, u0:u1].copy()
            before = self._region_ll(v, region, layers)
            layers[body] = np.inf
            layers[body, new.v0 - v0:new.v1 - v0, new.u0 - u0:new.u1 - u0] = new.depth
            change += self._region_ll(v, region, layers) - before
            self._pending.append(new)
        self._proposed = (body, self.current + change / self.settings.temperature)
        return self._proposed[1]

    def accept(self) -> None:
        body, proposed = self._proposed
        for v, new in enumerate(self._pending):
            if new is not None:
                self._place(v, body, new)
        self.current = proposed


#: the depth chain's random stream, apart from the samples' (SeedSequence(seed).spawn(k))
DEPTH_STREAM = 0xDE9


#: the acceptance rate each object's proposal scale is tuned towards during burn-in
TARGET_ACCEPTANCE = 0.3


@dataclass(frozen=True)
class DepthPosterior:
    """The chain over every dynamic object's (x, y, yaw) after burn-in, and what it says per object."""

    names: tuple[str, ...]
    positions_m: np.ndarray  # (samples, objects, 3)
    yaws_rad: np.ndarray     # (samples, objects): turn from the published orientation
    acceptance_rate: float

    @property
    def effective_sample_size(self) -> float:
        values = np.concatenate([self.positions_m[:, :, :2].reshape(len(self.positions_m), -1), self.yaws_rad], axis=1)
        return float(np.median([effective_sample_size(values[:, j]) for j in range(values.shape[1])]))

    def spread(self) -> dict[str, dict[str, float]]:
        """Per object: posterior SD of x, y (metres) and yaw (radians)."""
        sd_xy = self.positions_m[:, :, :2].std(axis=0)
        sd_yaw = self.yaws_rad.std(axis=0)
        return {n: {"x_sd_m": float(sx), "y_sd_m": float(sy), "yaw_sd_rad": float(syaw)}
                for n, (sx, sy), syaw in zip(self.names, sd_xy, sd_yaw)}

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """(objects, 3) low and high ends of the central 95% intervals of x, y and yaw."""
        values = np.concatenate([self.positions_m[:, :, :2], self.yaws_rad[:, :, None]], axis=2)
        return np.quantile(values, 0.025, axis=0), np.quantile(values, 0.975, axis=0)

    def thinned(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        index = np.linspace(0, len(self.positions_m) - 1, k).round().astype(int)
        return self.positions_m[index], self.yaws_rad[index]


def run_depth_chain(scene: Scene, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                    rng: np.random.Generator) -> DepthPosterior:
    """Metropolis-Hastings over the dynamic objects' (x, y, yaw), from the published scene."""
    if not observations:
        raise ConfigError("depth", "depth perception needs at least one depth image")
    mesh = scene_mesh(scene)
    dynamic = len(scene.dynamic_objects)
    prior_centre = mesh.positions_m[:dynamic, :2].copy()
    positions = mesh.positions_m.copy()
    yaws = np.zeros(len(positions))
    model = DepthModel(scene, mesh, observations, settings)
    current = model.start(positions, yaws)

    def log_prior(b: int, xy: np.ndarray, yaw: float) -> float:
        return (-0.5 * float(np.sum((xy - prior_centre[b]) ** 2)) / settings.prior_sd_m ** 2
                - 0.5 * yaw * yaw / settings.prior_yaw_sd_rad ** 2)

    # per object, a proposal scale tuned during burn-in towards TARGET_ACCEPTANCE (a block in plain
    # view is pinned to a fraction of a millimetre, a hidden one wanders over its prior), then frozen
    scale = np.ones(dynamic)
    kept_xyz, kept_yaw, taken = [], [], 0
    total, burn_in = settings.chain_samples(dynamic), settings.burn_in(dynamic)
    for sample in range(total):
        b = int(rng.integers(0, dynamic))
        moved = positions[b].copy()
        moved[:2] += scale[b] * settings.proposal_sd_m * rng.standard_normal(2)
        yaw = yaws[b] + scale[b] * settings.proposal_yaw_sd_rad * rng.standard_normal()
        candidate = model.propose(b, moved, yaw)
        ratio = candidate - current + log_prior(b, moved[:2], yaw) - log_prior(b, positions[b, :2], yaws[b])
        accepted = bool(np.log(rng.random()) < ratio)
        if accepted:
            model.accept()
            positions[b], yaws[b], current = moved, yaw, candidate
            taken += 1
        if sample < burn_in:
            scale[b] *= math.exp(0.5 * ((1.0 if accepted else 0.0) - TARGET_ACCEPTANCE) / math.sqrt(1 + sample / dynamic))
            scale[b] = min(max(scale[b], 1e-3), 10.0)
        if sample >= burn_in:
            kept_xyz.append(positions[:dynamic].copy())
            kept_yaw.append(yaws[:dynamic].copy())
    return DepthPosterior(names=tuple(b.name for b in scene.dynamic_objects), positions_m=np.array(kept_xyz),
                          yaws_rad=np.array(kept_yaw), acceptance_rate=taken / total)


def scene_at_pose(scene: Scene, positions_m: np.ndarray, yaws_rad: np.ndarray) -> Scene:
    """The scene with its dynamic objects at these positions (frame origins), turned by these yaws from
    their published orientation, their own noise removed (the posterior stands in for it)."""
    state = iter(zip(positions_m, yaws_rad))
    objects = []
    for body in scene.objects:
        if body.static:
            objects.append(body)
            continue
        position, yaw = next(state)
        turn = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        objects.append(dataclasses.replace(body, position_m=tuple(float(v) for v in position),
                                           orientation_xyzw=tuple(float(v) for v in quaternion_product(
                                               turn, body.orientation_xyzw)),
                                           position_sigma_m=0.0, yaw_sigma_rad=None))
    return dataclasses.replace(scene, objects=tuple(objects))


@dataclass(frozen=True)
class DepthPerceivedScenes:
    """k scenes from the depth posterior, with how well the chain mixed and each object's spread."""

    scenes: tuple[Scene, ...]
    posterior: DepthPosterior
    chain_samples: int
    burn_in: int

    @property
    def acceptance_rate(self) -> float:
        return self.posterior.acceptance_rate

    @property
    def effective_sample_size(self) -> float:
        return self.posterior.effective_sample_size

    def to_dict(self) -> dict[str, Any]:
        """``roughly_independent``: the chain's effective sample size is at least half the k scenes it
        gave (as the vision system demands; here said, not refused: a robot still gets its answer)."""
        return {"kind": "depth", "acceptance_rate": self.acceptance_rate,
                "effective_sample_size": self.effective_sample_size, "chain_samples": self.chain_samples,
                "burn_in": self.burn_in, "samples": len(self.scenes),
                "roughly_independent": self.effective_sample_size >= 0.5 * len(self.scenes),
                "object_spread": self.posterior.spread()}


def perceive_depth(scene: Scene, k: int, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                   rng: np.random.Generator) -> DepthPerceivedScenes:
    """k scenes spread over the depth posterior of ``scene`` (the detector's guess) given the images."""
    posterior = run_depth_chain(scene, observations, settings, rng)
    if k > len(posterior.positions_m):
        raise ConfigError("depth.updates_per_object", f"the chain keeps {len(posterior.positions_m)} states after "
                                                      f"burn-in, fewer than the {k} samples asked; lengthen it")
    positions, yaws = posterior.thinned(k)
    scenes = tuple(scene_at_pose(scene, p, y) for p, y in zip(positions, yaws))
    objects = len(scene.dynamic_objects)
    return DepthPerceivedScenes(scenes=scenes, posterior=posterior, chain_samples=settings.chain_samples(objects),
                                burn_in=settings.burn_in(objects))


def perceive_depth_for(scene: Scene, k: int, observations: tuple[DepthObservation, ...], seed: int,
                       settings: DepthSettings | None = None) -> DepthPerceivedScenes:
    """``perceive_depth`` as a prediction with this ``seed`` runs it (the CLI, the node): its chain on a
    random stream of its own, apart from the samples'."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, DEPTH_STREAM]))
    return perceive_depth(scene, k, observations, settings or DepthSettings(), rng)


# -- inputs as a robot has them -------------------------------------------------------------------------
def load_camera_info(path: str | Path) -> dict:
    """A camera_info YAML (or JSON) file as a mapping."""
    import yaml

    try:
        data = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError("--camera-info", f"cannot read {path}: {exc}") from None
    return data


def load_depth_image(path: str | Path) -> np.ndarray:
    """Metres, as float: a .npy of float metres (or integer millimetres) or a 16-bit PNG of
    millimetres (0: no reading), as depth cameras write them."""
    path = Path(path)
    try:
        if path.suffix.lower() == ".npy":
            data = np.load(path, allow_pickle=False)
        elif path.suffix.lower() == ".png":
            from PIL import Image

            with Image.open(path) as image:
                data = np.asarray(image)
        else:
            raise ConfigError("--depth", f"{path.name}: give a .npy (metres, or integer millimetres) or a 16-bit .png "
                                         "(millimetres)")
    except (OSError, ValueError) as exc:
        raise ConfigError("--depth", f"cannot read {path}: {exc}") from None
    if data.ndim != 2:
        raise ConfigError("--depth", f"{path.name}: a depth image has one channel; got shape {list(data.shape)}")
    if np.issubdtype(data.dtype, np.integer):
        return data.astype(float) / 1000.0
    if not np.issubdtype(data.dtype, np.floating):
        raise ConfigError("--depth", f"{path.name}: depth must be numbers, got {data.dtype}")
    return data.astype(float)


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

    from ..scene_io import scene_to_dict

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


def render_depth_m(scene: Scene, camera: PinholeCamera, positions_m: np.ndarray | None = None,
                   yaws_rad: np.ndarray | None = None) -> np.ndarray:
    """(height, width) depth the camera would measure of the scene with its dynamic objects at
    ``positions_m`` turned by ``yaws_rad`` (default: as published): objects over the support; NaN
    where neither is."""
    mesh = scene_mesh(scene)
    positions = mesh.positions_m.copy()
    yaws = np.zeros(len(positions))
    if positions_m is not None:
        positions[:len(positions_m)] = positions_m
    if yaws_rad is not None:
        yaws[:len(yaws_rad)] = yaws_rad
    nearest = np.full((camera.height_px, camera.width_px), np.inf)
    for b in range(len(positions)):
        patch = body_patch(mesh, camera, b, positions[b], yaws[b])
        window = nearest[patch.v0:patch.v1, patch.u0:patch.u1]
        np.minimum(window, patch.depth, out=window)
    return np.where(np.isfinite(nearest), nearest, support_depth_m(scene, camera))
