"""The depth camera's likelihood: what a hypothesised scene would look like to it, pixel by pixel.

A hypothesised scene (each dynamic object's x, y and yaw; heights as published, since stacking
gives them) is rendered into the depth the camera would measure - the z-buffer of the hulls (our
rasteriser, ``render.body_patch``) over the support plane, cast per pixel - and compared with the
measured depth pixel by pixel:

    p(d | d_hat) = (1 - outlier) N(d - offset; d_hat, sd(d_hat)) + outlier / max_range,
    sd(d_hat) = sd_m + sd_per_m2 * d_hat^2        (structured light and stereo: error grows with range^2)

Missing pixels (0, NaN, inf, negative, beyond max_range) are ignored; the outlier term absorbs
unmodelled objects, edges and flying pixels. Only pixels in the objects' reach count - the published
objects' bounding boxes, grown by ``reach_m``, seen from the camera - so the table and the background
far from the objects do not dominate; a reach pixel with nothing hypothesised in it and no support
under it scores the outlier density alone, the same for every hypothesis. Neighbouring pixels'
errors are not independent (edges, smoothing), so the log-likelihood is divided by ``temperature``
and only every ``pixel_stride``-th pixel in each direction is read. ``offset`` is the camera's range
offset, estimated by the chain (``depth.py``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..checks import integer, positive
from ..errors import ConfigError
from ..scene.bodies import Floor, Scene
from .camera import PinholeCamera
from .render import EMPTY, Patch, SceneMesh, body_patch, scene_mesh


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
    temperature: float = 4.0
    prior_sd_m: float = 0.03
    prior_yaw_sd_rad: float = 0.2
    proposal_sd_m: float = 0.005
    proposal_yaw_sd_rad: float = 0.03
    updates_per_object: int = 1000
    burn_in_fraction: float = 0.2
    offset_prior_sd_m: float = 0.01
    offset_proposal_sd_m: float = 0.0005
    prior_height_sd_m: float = 0.01
    proposal_height_sd_m: float = 0.002

    def __post_init__(self) -> None:
        for name in ("sd_m", "max_range_m", "reach_m", "temperature", "prior_sd_m", "prior_yaw_sd_rad",
                     "proposal_sd_m", "proposal_yaw_sd_rad", "offset_proposal_sd_m", "proposal_height_sd_m"):
            positive(getattr(self, name), f"depth.{name}")
        for name, meaning in (("offset_prior_sd_m", "the camera's range taken as exact"),
                              ("prior_height_sd_m", "the detector's heights taken as exact")):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 0.1:
                raise ConfigError(f"depth.{name}", f"must be in [0, 0.1] (0: {meaning}), got {value!r}")
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
    from ..scene.shapes import BoxShape
    from ..scene.bodies import Body

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
            with np.errstate(invalid="ignore"):  # 0, NaN, inf, negative or beyond the range: no reading
                valid = np.isfinite(measured) & (measured > 0) & (measured < settings.max_range_m)
            grid = np.zeros_like(valid)
            grid[::stride, ::stride] = True
            self.read.append(valid & grid & _reach_mask(scene, obs.camera, settings.reach_m))
            self.measured.append(np.where(valid, measured, np.nan))
            self.support.append(support_depth_m(scene, obs.camera))
        self.read_pixels = [np.nonzero(read) for read in self.read]
        if not any(len(rows) for rows, _ in self.read_pixels):
            raise ConfigError("depth", "no usable depth where the objects are: every pixel that sees them (or the "
                                       f"support within {settings.reach_m:g} m) is 0, NaN, inf, negative or beyond "
                                       f"{settings.max_range_m:g} m, or the objects are out of view; check the camera "
                                       "driver, the camera info and the camera pose")
        self.offsets_m = np.zeros(len(observations))
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
        return float(self._pixel_ll(self.measured[v][v0:v1, u0:u1][read] - self.offsets_m[v], predicted[read]).sum())

    def pixels_seen(self, objects: int) -> np.ndarray:
        """(objects,) pixels read where each of the first ``objects`` bodies is the nearest surface now."""
        counts = np.zeros(objects, int)
        for v, (rows, columns) in enumerate(self.read_pixels):
            if len(rows):
                depth = self.layers[v][:, rows, columns]
                nearest = depth.argmin(axis=0)[np.isfinite(depth.min(axis=0))]
                counts += np.bincount(nearest[nearest < objects], minlength=objects)
        return counts

    def propose_offset(self, v: int, offset_m: float) -> float:
        """The (tempered) log-likelihood with camera v's range offset moved; pending until ``accept_offset``.
        Only the offset changes, so the hypothesis' depth at the pixels read is composed once."""
        rows, columns = self.read_pixels[v]
        change = 0.0
        if len(rows):
            nearest = self.layers[v][:, rows, columns].min(axis=0)
            predicted = np.where(np.isfinite(nearest), nearest, self.support[v][rows, columns])
            predicted = np.where(np.isnan(predicted), np.inf, predicted)
            measured = self.measured[v][rows, columns]
            change = float(self._pixel_ll(measured - offset_m, predicted).sum()
                           - self._pixel_ll(measured - self.offsets_m[v], predicted).sum())
        self._proposed_offset = (v, offset_m, self.current + change / self.settings.temperature)
        return self._proposed_offset[2]

    def accept_offset(self) -> None:
        v, offset_m, proposed = self._proposed_offset
        self.offsets_m[v] = offset_m
        self.current = proposed

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


#: the most memory the chain's depth layers (bodies x pixels x cameras, float64) may take
MAX_LAYER_BYTES = 1 << 30


def check_layer_memory(scene: Scene, observations: tuple[DepthObservation, ...]) -> None:
    """The chain keeps one depth layer per body and camera: refused up front when that is too big."""
    bodies = len(scene.objects)
    pixels = sum(o.camera.width_px * o.camera.height_px for o in observations)
    needed = bodies * pixels * 8
    if needed > MAX_LAYER_BYTES:
        raise ConfigError("depth", f"{bodies} bodies x {pixels} pixels need {needed / 1e9:.2g} GB of depth layers (at "
                                   f"most {MAX_LAYER_BYTES / 1e9:.2g} GB); bin or crop the image (camera_info "
                                   "binning_x/y, roi) or send fewer objects")


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
