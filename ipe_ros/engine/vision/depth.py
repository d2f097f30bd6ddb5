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

A real camera's range is biased by millimetres (a scale error, a calibration offset), which would
move every object along the view and make the posterior confidently wrong: each camera's range
offset is a nuisance parameter of the chain (prior N(0, ``offset_prior_sd_m``), one move per four
scans of the objects), pinned down by the support around the objects, whose place is known.

The prior is the detector's: each object's published pose, x and y with SD ``prior_sd_m`` and yaw
with ``prior_yaw_sd_rad``. A block in plain view is pinned down by its pixels; one hidden behind
another keeps the prior's spread. Metropolis-Hastings with single-object moves (x, y, yaw together)
and an injected Generator; several cameras multiply their likelihoods.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..checks import integer, positive
from ..errors import ConfigError, clip
from ..scene import Floor, Scene
from ..shapes import quaternion_product
from .camera import MAX_SIDE_PX, PinholeCamera, camera_from_info, look_at
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
    offset_prior_sd_m: float = 0.01
    offset_proposal_sd_m: float = 0.0005

    def __post_init__(self) -> None:
        for name in ("sd_m", "max_range_m", "reach_m", "temperature", "prior_sd_m", "prior_yaw_sd_rad",
                     "proposal_sd_m", "proposal_yaw_sd_rad", "offset_proposal_sd_m"):
            positive(getattr(self, name), f"depth.{name}")
        if not isinstance(self.offset_prior_sd_m, (int, float)) or not 0 <= self.offset_prior_sd_m <= 0.1:
            raise ConfigError("depth.offset_prior_sd_m", f"must be in [0, 0.1] (0: the camera's range taken as "
                                                         f"exact), got {self.offset_prior_sd_m!r}")
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


#: the depth chain's random stream, apart from the samples' (SeedSequence(seed).spawn(k))
DEPTH_STREAM = 0xDE9

#: the share of a prediction's budget the depth chain may take; the samples get what it leaves
CHAIN_BUDGET_SHARE = 0.5


#: the acceptance rate each object's proposal scale is tuned towards during burn-in
TARGET_ACCEPTANCE = 0.3

#: the most memory the chain's depth layers (bodies x pixels x cameras, float64) may take
MAX_LAYER_BYTES = 1 << 30

#: scans of the objects between checks of the chain's projected end against its deadline
BUDGET_CHECK_SCANS = 10

#: scans of the objects per move of the cameras' range offsets: an offset move reads every pixel in
#: reach (an object's, its own patch), and the support pins the offset within a few moves
OFFSET_MOVE_SCANS = 4


@dataclass(frozen=True)
class DepthPosterior:
    """The chain over every dynamic object's (x, y, yaw) after burn-in, and what it says per object."""

    names: tuple[str, ...]
    positions_m: np.ndarray  # (samples, objects, 3)
    yaws_rad: np.ndarray     # (samples, objects): turn from the published orientation
    acceptance_rate: float
    offsets_m: np.ndarray | None = None  # (samples, cameras): each camera's range offset (measured - true)
    pixels: np.ndarray | None = None  # (objects,) pixels read where the object is in front at the mean pose

    def camera_offsets(self) -> list[dict[str, float]]:
        """Per camera: posterior mean and SD of its range offset (how much longer it measures than the
        scene is), in metres."""
        if self.offsets_m is None or not self.offsets_m.size:
            return []
        return [{"mean_m": float(o.mean()), "sd_m": float(o.std())} for o in self.offsets_m.T]

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

    def mean(self) -> tuple[np.ndarray, np.ndarray]:
        """(objects, 3) posterior mean positions and (objects,) mean turns from the published yaw."""
        return self.positions_m.mean(axis=0), self.yaws_rad.mean(axis=0)

    def covariance(self) -> np.ndarray:
        """(objects, 3, 3) posterior covariance of each object's (x, y, yaw) in m and rad."""
        values = np.concatenate([self.positions_m[:, :, :2], self.yaws_rad[:, :, None]], axis=2)
        centred = values - values.mean(axis=0)
        return np.einsum("sai,saj->aij", centred, centred) / max(1, len(values) - 1)

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """(objects, 3) low and high ends of the central 95% intervals of x, y and yaw."""
        values = np.concatenate([self.positions_m[:, :, :2], self.yaws_rad[:, :, None]], axis=2)
        return np.quantile(values, 0.025, axis=0), np.quantile(values, 0.975, axis=0)

    def thinned(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        index = np.linspace(0, len(self.positions_m) - 1, k).round().astype(int)
        return self.positions_m[index], self.yaws_rad[index]


def check_layer_memory(scene: Scene, observations: tuple[DepthObservation, ...]) -> None:
    """The chain keeps one depth layer per body and camera: refused up front when that is too big."""
    bodies = len(scene.objects)
    pixels = sum(o.camera.width_px * o.camera.height_px for o in observations)
    needed = bodies * pixels * 8
    if needed > MAX_LAYER_BYTES:
        raise ConfigError("depth", f"{bodies} bodies x {pixels} pixels need {needed / 1e9:.2g} GB of depth layers (at "
                                   f"most {MAX_LAYER_BYTES / 1e9:.2g} GB); bin or crop the image (camera_info "
                                   "binning_x/y, roi) or send fewer objects")


def run_depth_chain(scene: Scene, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                    rng: np.random.Generator, deadline_s: float | None = None) -> DepthPosterior:
    """Metropolis-Hastings over the dynamic objects' (x, y, yaw), from the published scene.

    ``deadline_s`` (``time.monotonic()``): the chain is refused (ConfigError naming ``budget_s``) as
    soon as its first scans show it cannot finish by then, and stopped if it runs past it."""
    if not observations:
        raise ConfigError("depth", "depth perception needs at least one depth image")
    check_layer_memory(scene, observations)
    started = time.monotonic()
    mesh = scene_mesh(scene)
    dynamic = len(scene.dynamic_objects)
    prior_centre = mesh.positions_m[:dynamic, :2].copy()
    positions = mesh.positions_m.copy()
    yaws = np.zeros(len(positions))
    model = DepthModel(scene, mesh, observations, settings)
    current = model.start(positions, yaws)
    if deadline_s is not None and time.monotonic() > deadline_s:
        raise ConfigError("budget_s", f"reading the depth image for {dynamic} objects took "
                                      f"{time.monotonic() - started:.3g} s, all the budget leaves the depth chain; "
                                      "raise the budget, bin or crop the image, or send fewer objects")

    def log_prior(b: int, xy: np.ndarray, yaw: float) -> float:
        return (-0.5 * float(np.sum((xy - prior_centre[b]) ** 2)) / settings.prior_sd_m ** 2
                - 0.5 * yaw * yaw / settings.prior_yaw_sd_rad ** 2)

    # per object, a proposal scale tuned during burn-in towards TARGET_ACCEPTANCE (a block in plain
    # view is pinned to a fraction of a millimetre, a hidden one wanders over its prior), then frozen
    scale = np.ones(dynamic)
    offset_scale = np.ones(len(observations))
    kept_xyz, kept_yaw, kept_offsets, taken = [], [], [], 0
    total, burn_in = settings.chain_samples(dynamic), settings.burn_in(dynamic)

    def adapted(value: float, accepted: bool, sample: int) -> float:
        value *= math.exp(0.5 * ((1.0 if accepted else 0.0) - TARGET_ACCEPTANCE) / math.sqrt(1 + sample / dynamic))
        return min(max(value, 1e-3), 10.0)

    def move_offsets(sample: int) -> None:
        """One move of each camera's range offset: a real camera's depth is biased by millimetres (range
        error, calibration), which would otherwise move every object along the view; the support
        around the objects, whose place is known, pins it down."""
        nonlocal current
        for v in range(len(observations)):
            old = model.offsets_m[v]
            new = old + offset_scale[v] * settings.offset_proposal_sd_m * rng.standard_normal()
            candidate = model.propose_offset(v, new)
            ratio = candidate - current - 0.5 * (new * new - old * old) / settings.offset_prior_sd_m ** 2
            accepted = bool(np.log(rng.random()) < ratio)
            if accepted:
                model.accept_offset()
                current = candidate
            if sample < burn_in:
                offset_scale[v] = adapted(offset_scale[v], accepted, sample)

    for sample in range(total):
        if deadline_s is not None and sample % (BUDGET_CHECK_SCANS * dynamic) == 0 and sample:
            _check_deadline(started, deadline_s, sample, total, dynamic)
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
            scale[b] = adapted(scale[b], accepted, sample)
        if settings.offset_prior_sd_m > 0 and sample % (OFFSET_MOVE_SCANS * dynamic) == dynamic - 1:
            move_offsets(sample)
        if sample >= burn_in:
            kept_xyz.append(positions[:dynamic].copy())
            kept_yaw.append(yaws[:dynamic].copy())
            kept_offsets.append(model.offsets_m.copy())
    model.start(np.concatenate([np.mean(kept_xyz, axis=0), positions[dynamic:]]),
                np.concatenate([np.mean(kept_yaw, axis=0), yaws[dynamic:]]))
    return DepthPosterior(names=tuple(b.name for b in scene.dynamic_objects), positions_m=np.array(kept_xyz),
                          yaws_rad=np.array(kept_yaw), acceptance_rate=taken / total,
                          offsets_m=np.array(kept_offsets), pixels=model.pixels_seen(dynamic))


def _check_deadline(started: float, deadline_s: float, done: int, total: int, objects: int) -> None:
    now = time.monotonic()
    projected = started + (now - started) * total / done
    if projected > deadline_s:
        raise ConfigError("budget_s", f"the depth chain over {objects} objects needs ~{projected - started:.3g} s "
                                      f"({total} updates; {done} took {now - started:.3g} s), more than the "
                                      f"{deadline_s - started:.3g} s the budget leaves it; raise the "
                                      "budget or send fewer objects")


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
    """k scenes from the depth posterior, with how well the chain mixed, and the scene refined: every
    dynamic object at its posterior mean pose (``refined``), with its covariance in ``to_dict``."""

    scenes: tuple[Scene, ...]
    posterior: DepthPosterior
    chain_samples: int
    burn_in: int
    refined: Scene

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
                "objects": self.objects(), "camera_offsets": self.posterior.camera_offsets()}

    def objects(self) -> dict[str, dict[str, Any]]:
        """Per dynamic object: the refined pose (posterior mean; height and tilt as published), how many
        pixels read show it there (0: the image says nothing of it, its pose is the detector's prior),
        the posterior covariance of (x, y, yaw) and the SDs on its diagonal."""
        covariance = self.posterior.covariance()
        refined = {b.name: b for b in self.refined.dynamic_objects}
        out = {}
        pixels = self.posterior.pixels if self.posterior.pixels is not None else [None] * len(covariance)
        for name, c, seen in zip(self.posterior.names, covariance, pixels):
            body = refined[name]
            out[name] = {"position_m": list(body.position_m), "orientation_xyzw": list(body.orientation_xyzw),
                         "pixels": None if seen is None else int(seen),
                         "covariance_x_y_yaw": c.tolist(), "x_sd_m": float(math.sqrt(c[0, 0])),
                         "y_sd_m": float(math.sqrt(c[1, 1])), "yaw_sd_rad": float(math.sqrt(c[2, 2]))}
        return out


def perceive_depth(scene: Scene, k: int, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                   rng: np.random.Generator, deadline_s: float | None = None) -> DepthPerceivedScenes:
    """k scenes spread over the depth posterior of ``scene`` (the detector's guess) given the images."""
    posterior = run_depth_chain(scene, observations, settings, rng, deadline_s)
    if k > len(posterior.positions_m):
        raise ConfigError("depth.updates_per_object", f"the chain keeps {len(posterior.positions_m)} states after "
                                                      f"burn-in, fewer than the {k} samples asked; lengthen it")
    positions, yaws = posterior.thinned(k)
    scenes = tuple(scene_at_pose(scene, p, y) for p, y in zip(positions, yaws))
    objects = len(scene.dynamic_objects)
    return DepthPerceivedScenes(scenes=scenes, posterior=posterior, chain_samples=settings.chain_samples(objects),
                                burn_in=settings.burn_in(objects), refined=scene_at_pose(scene, *posterior.mean()))


def perceive_depth_for(scene: Scene, k: int, observations: tuple[DepthObservation, ...], seed: int,
                       settings: DepthSettings | None = None, budget_s: float | None = None) -> DepthPerceivedScenes:
    """``perceive_depth`` as a prediction with this ``seed`` runs it (the CLI, the node): its chain on a
    random stream of its own, apart from the samples', within ``budget_s`` seconds when given."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, DEPTH_STREAM]))
    deadline = None if budget_s is None else time.monotonic() + budget_s
    return perceive_depth(scene, k, observations, settings or DepthSettings(), rng, deadline)


# -- inputs as a robot has them -------------------------------------------------------------------------
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
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError("--camera-info", f"cannot read {path}: {clip(str(exc), 300)}") from None
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
    except (OSError, ValueError) as exc:
        if isinstance(exc, ConfigError):
            raise
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

    with Image.open(path) as image:
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
