"""The depth camera's likelihood: what a hypothesised scene would look like to it, pixel by pixel.

A hypothesised scene (each dynamic object's x, y, height and yaw) is rendered into the depth the
camera would measure - each pixel's ray cast at the bodies' convex parts (``raycast``), the nearest
hit or else the support plane - and compared with the measured depth pixel by pixel:

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
from .raycast import convex_body, pixel_box, pose_rotations, ray_depths
from .render import body_patch, scene_mesh


#: no depth camera reads nearer than this (structured light and stereo: 0.1-0.3 m; time of flight a
#: few cm): a reading below it is no reading, as 0 is
MIN_READING_M = 0.02


@dataclass(frozen=True)
class DepthObservation:
    """One measured depth image (metres along the optical axis; below MIN_READING_M, NaN or inf: no
    reading) and the camera that took it."""

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
    """The depth perception's model (see the module docstring) and its sampler (``depth_chain``):
    ``chains`` independent chains (the workers run one each), each: ``locate_*`` the search for the
    posterior's peak, ``shape_points`` the poses its curvature is fitted to, then ``burn_in_sweeps``
    + its share of ``kept_states`` (or k, when more) sweeps of ``proposals_per_sweep`` independence
    proposals per object - a share ``prior_share`` of them drawn from the prior and the rest from a
    Student-t (``proposal_dof``) around the peak - and ``walk_steps`` random-walk steps.
    ``set_down_sds``: the samples' objects are set down onto what is under them (``Scene.set_down_m``)
    when within this many posterior SDs of their height above it (0: heights as sampled)."""

    sd_m: float = 0.002
    sd_per_m2: float = 0.0025
    outlier: float = 0.05
    max_range_m: float = 10.0
    reach_m: float = 0.1
    pixel_stride: int = 2
    temperature: float = 4.0
    prior_sd_m: float = 0.03
    prior_yaw_sd_rad: float = 0.2
    offset_prior_sd_m: float = 0.01
    prior_height_sd_m: float = 0.01
    prior_tilt_sd_rad: float = 0.0
    locate_sweeps: int = 2
    locate_rounds: int = 20
    locate_candidates: int = 16
    shape_points: int = 64
    proposals_per_sweep: int = 8
    walk_steps: int = 3
    kept_states: int = 64
    burn_in_sweeps: int = 16
    proposal_dof: float = 4.0
    prior_share: float = 0.1
    chains: int = 2
    set_down_sds: float = 5.0

    def __post_init__(self) -> None:
        for name in ("sd_m", "max_range_m", "reach_m", "temperature", "prior_sd_m", "prior_yaw_sd_rad",
                     "proposal_dof"):
            positive(getattr(self, name), f"depth.{name}")
        for name, meaning in (("offset_prior_sd_m", "the camera's range taken as exact"),
                              ("prior_height_sd_m", "the detector's heights taken as exact"),
                              ("prior_tilt_sd_rad", "the detector's tilts taken as exact")):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= 0.1:
                raise ConfigError(f"depth.{name}", f"must be in [0, 0.1] (0: {meaning}), got {value!r}")
        if isinstance(self.set_down_sds, bool) or not isinstance(self.set_down_sds, (int, float)) \
                or not 0 <= self.set_down_sds <= 20:
            raise ConfigError("depth.set_down_sds", f"must be in [0, 20] (0: heights as sampled), got {self.set_down_sds!r}")
        if not isinstance(self.sd_per_m2, (int, float)) or not 0 <= self.sd_per_m2 < 1:
            raise ConfigError("depth.sd_per_m2", f"must be in [0, 1), got {self.sd_per_m2!r}")
        for name in ("outlier", "prior_share"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < 1:
                raise ConfigError(f"depth.{name}", f"must be in (0, 1), got {value!r}")
        integer(self.pixel_stride, "depth.pixel_stride", 1, 16)
        for name, low, high in (("locate_sweeps", 0, 10), ("locate_rounds", 1, 30), ("locate_candidates", 1, 1000),
                                ("shape_points", 16, 1000), ("proposals_per_sweep", 1, 100), ("walk_steps", 0, 100),
                                ("kept_states", 1, 100_000), ("burn_in_sweeps", 0, 10_000), ("chains", 1, 16)):
            integer(getattr(self, name), f"depth.{name}", low, high)

    def kept_per_chain(self, k: int = 0) -> int:
        """States each chain keeps: its share of ``kept_states``, or of k when more."""
        return -(-max(self.kept_states, k) // self.chains)

    def sweeps(self, k: int = 0) -> int:
        """Sweeps over the objects after the search, per chain: burn-in, then one kept state per sweep."""
        return self.burn_in_sweeps + self.kept_per_chain(k)

    def chain_samples(self, objects: int, k: int = 0) -> int:
        """Single-object proposals of the sampling sweeps over ``objects`` objects, every chain's."""
        return self.chains * self.sweeps(k) * (self.proposals_per_sweep + self.walk_steps) * objects

    def burn_in(self, objects: int) -> int:
        return self.chains * self.burn_in_sweeps * (self.proposals_per_sweep + self.walk_steps) * objects


def support_depth_m(scene: Scene, camera: PinholeCamera) -> np.ndarray:
    """(height, width) depth of the support under every pixel's ray (the floor, the table top within
    its edges, the floor under a table); NaN where the ray meets none."""
    return support_depth_from_rays(scene, np.asarray(camera.position_m, float), camera.rays())


def support_depth_from_rays(scene: Scene, origin_m: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """``support_depth_m`` along these rays (``(..., 3)``, optical component 1) from ``origin_m``."""
    support = scene.support

    def plane(z: float) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (z - origin_m[2]) / rays[..., 2]
        t = np.where(t > 0, t, np.nan)
        return t, origin_m + t[..., None] * rays

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
    """Every camera's measured depth at the pixels read, and the hypothesis' depth there: one layer
    per body (its depth at every pixel read, inf where it does not cover it), so moving one body
    re-casts that body's rays alone. ``log_likelihoods`` scores many poses of one body at once, the
    others where they are."""

    def __init__(self, scene: Scene, observations: tuple[DepthObservation, ...], settings: DepthSettings):
        self.observations, self.settings = observations, settings
        self.bodies = [convex_body(b) for b in (*scene.dynamic_objects, *(b for b in scene.objects if b.static))]
        stride = settings.pixel_stride
        self.rows, self.columns, self.rays, self.measured, self.support = [], [], [], [], []
        for obs in observations:
            measured = np.asarray(obs.depth_m, float)
            with np.errstate(invalid="ignore"):  # 0, NaN, inf, negative or beyond the range: no reading
                valid = np.isfinite(measured) & (measured >= MIN_READING_M) & (measured < settings.max_range_m)
            grid = np.zeros_like(valid)
            grid[::stride, ::stride] = True
            rows, columns = np.nonzero(valid & grid & _reach_mask(scene, obs.camera, settings.reach_m))
            rays = obs.camera.rays_at(rows, columns)
            self.rows.append(rows)
            self.columns.append(columns)
            self.rays.append(rays)
            self.measured.append(measured[rows, columns])
            support = support_depth_from_rays(scene, np.asarray(obs.camera.position_m, float), rays)
            self.support.append(np.where(np.isnan(support), np.inf, support))  # inf: the outlier density alone
        if not any(len(rows) for rows in self.rows):
            raise ConfigError("depth", "no usable depth where the objects are: every pixel that sees them (or the "
                                       f"support within {settings.reach_m:g} m) is 0, NaN, inf, nearer than "
                                       f"{MIN_READING_M:g} m or beyond {settings.max_range_m:g} m, or the objects are "
                                       "out of view; check the camera (depth in metres; 16UC1 in millimetres), "
                                       "its driver, the camera info and the camera pose")
        self.offsets_m = np.zeros(len(observations))
        self.others = [np.delete(np.arange(len(self.bodies)), b) for b in range(len(self.bodies))]  # every body but b
        self._cast = None  # the last poses scored, reused by ``move`` (``_cast_at``)

    def _pixel_ll(self, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """Per pixel log p(measured | predicted); predicted inf: nothing there, the outlier density."""
        s = self.settings
        finite = np.isfinite(predicted)
        sd = s.sd_m + s.sd_per_m2 * np.where(finite, predicted, 0.0) ** 2
        with np.errstate(invalid="ignore", over="ignore"):
            normal = np.exp(-0.5 * ((measured - predicted) / sd) ** 2) / (sd * math.sqrt(2 * math.pi))
        return np.log(np.where(finite, (1 - s.outlier) * normal, 0.0) + s.outlier / s.max_range_m)

    def _in_view(self, v: int, body: int, positions_m: np.ndarray, rotations: np.ndarray) -> np.ndarray:
        """(pixels read,) bool: in the image box that ``body`` can cover in these poses."""
        box = pixel_box(self.bodies[body], self.observations[v].camera, positions_m, rotations)
        if box is None:
            return np.ones(len(self.rows[v]), bool)
        u0, u1, v0, v1 = box
        # the pixels read are in raster order (np.nonzero): the box's rows are one run of them
        first, end = np.searchsorted(self.rows[v], (math.ceil(v0 - 1), math.floor(v1 + 1) + 1))
        inside = np.zeros(len(self.rows[v]), bool)
        columns = self.columns[v][first:end]
        inside[first:end] = (columns >= u0 - 1) & (columns <= u1 + 1)
        return inside

    def _depths(self, v: int, body: int, positions_m: np.ndarray, rotations: np.ndarray,
                index: np.ndarray) -> np.ndarray:
        """(poses, pixels) depth of ``body`` in each pose at the pixels read ``index``."""
        return ray_depths(self.bodies[body], np.asarray(self.observations[v].camera.position_m, float),
                          self.rays[v][index], positions_m, rotations)

    def _predicted(self, v: int, index, nearest: np.ndarray) -> np.ndarray:
        return np.where(np.isfinite(nearest), nearest, self.support[v][index])

    def _rescore(self, v: int, index=slice(None)) -> None:
        """Camera v's per-pixel log-likelihood of the state as it is, at these pixels read."""
        self.pixel_ll_now[v][index] = self._pixel_ll(self.measured[v][index] - self.offsets_m[v],
                                                     self._predicted(v, index, self.layers[v][:, index].min(axis=0)))

    def start(self, positions_m: np.ndarray, yaws_rad: np.ndarray, tilts_rad: np.ndarray | None = None) -> float:
        """Every body at its pose (``tilts_rad``: (bodies, 2), none: as published): the layers and the
        (tempered) log-likelihood."""
        self.layers = [np.full((len(self.bodies), len(rows)), np.inf) for rows in self.rows]
        self._cast = None
        self.pixel_ll_now = [np.zeros(len(rows)) for rows in self.rows]
        for v in range(len(self.observations)):
            for b in range(len(self.bodies)):
                self._place(v, b, np.asarray(positions_m[b], float), float(yaws_rad[b]),
                            None if tilts_rad is None else tilts_rad[b])
            self._rescore(v)
        self.current = float(sum(ll.sum() for ll in self.pixel_ll_now)) / self.settings.temperature
        return self.current

    def _place(self, v: int, body: int, position_m: np.ndarray, yaw_rad: float,
               tilt_rad: np.ndarray | None = None) -> np.ndarray:
        """Cast ``body``'s rays in this pose; the pixels read whose depth may have changed."""
        rotation = pose_rotations(np.array([yaw_rad]), None if tilt_rad is None else np.asarray(tilt_rad)[None])
        changed = self._in_view(v, body, position_m[None], rotation)
        index = np.flatnonzero(changed)
        changed |= np.isfinite(self.layers[v][body])
        self.layers[v][body] = np.inf
        self.layers[v][body, index] = self._depths(v, body, position_m[None], rotation, index)[0]
        return changed

    def log_likelihoods(self, body: int, positions_m: np.ndarray, yaws_rad: np.ndarray,
                        tilts_rad: np.ndarray | None = None) -> np.ndarray:
        """(poses,) the (tempered) log-likelihood with ``body`` at each pose, the rest as they are."""
        positions_m = np.asarray(positions_m, float)
        rotations = pose_rotations(yaws_rad, tilts_rad)
        change = np.zeros(len(positions_m))
        casts = []
        # kept until the state changes: the pose taken is one of these (``move``); copies, so that a
        # caller reusing its arrays cannot make a pose look scored
        self._cast = (body, positions_m.copy(), np.array(yaws_rad, float),
                      None if tilts_rad is None else np.array(tilts_rad, float), casts)
        for v in range(len(self.observations)):
            # where the poses may show it, and where it shows now
            index = np.flatnonzero(self._in_view(v, body, positions_m, rotations) | np.isfinite(self.layers[v][body]))
            casts.append((index, np.full((len(positions_m), 0), np.inf), np.zeros((len(positions_m), 0))))
            if not len(index):
                continue
            others = (self.layers[v][:, index][self.others[body]].min(axis=0) if len(self.bodies) > 1
                      else np.full(len(index), np.inf))
            moved = self._depths(v, body, positions_m, rotations, index)
            measured = self.measured[v][index] - self.offsets_m[v]
            after = self._pixel_ll(measured, self._predicted(v, index, np.minimum(others, moved)))
            casts[v] = (index, moved, after)
            change += after.sum(axis=1) - self.pixel_ll_now[v][index].sum()
        return self.current + change / self.settings.temperature

    def move(self, body: int, position_m: np.ndarray, yaw_rad: float, log_likelihood: float,
             tilt_rad: np.ndarray | None = None) -> None:
        """Put ``body`` at this pose, whose (tempered) log-likelihood ``log_likelihoods`` gave."""
        position_m = np.asarray(position_m, float)
        cast = self._cast_at(body, position_m, float(yaw_rad), tilt_rad)
        for v in range(len(self.observations)):
            if cast is None:
                changed = self._place(v, body, position_m, float(yaw_rad), tilt_rad)
                self._rescore(v, np.flatnonzero(changed))
            else:  # as this pose was scored (a pose taken was just scored), at pixels that include where it was
                index, depths, pixel_ll = cast[v]
                self.layers[v][body] = np.inf
                self.layers[v][body, index] = depths
                self.pixel_ll_now[v][index] = pixel_ll
        self.current = float(log_likelihood)
        self._cast = None  # scored against the state before this move

    def _cast_at(self, body: int, position_m: np.ndarray, yaw_rad: float,
                 tilt_rad: np.ndarray | None) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None:
        """Per camera, (pixels read, ``body``'s depth there, their log-likelihood) at this pose if the
        last ``log_likelihoods`` scored it and nothing has moved since; None otherwise."""
        if self._cast is None or self._cast[0] != body:
            return None
        _, positions, yaws, tilts, casts = self._cast
        same = np.all(positions == position_m, axis=1) & (yaws == yaw_rad)
        tilt = np.zeros(2) if tilt_rad is None else np.asarray(tilt_rad, float)
        same &= np.all(tilt == 0) if tilts is None else np.all(tilts == tilt, axis=1)
        hits = np.flatnonzero(same)
        return None if not len(hits) else [(index, depths[hits[0]], pixel_ll[hits[0]]) for index, depths, pixel_ll in casts]

    def offset_log_likelihoods(self, v: int, offsets_m: np.ndarray) -> np.ndarray:
        """(offsets,) the (tempered) log-likelihood with camera v's range offset at each value; the
        hypothesis' depth at the pixels read is composed once."""
        if not len(self.rows[v]):
            return np.full(len(offsets_m), self.current)
        predicted = self._predicted(v, slice(None), self.layers[v].min(axis=0))
        moved = self._pixel_ll(self.measured[v][None] - np.asarray(offsets_m, float)[:, None], predicted).sum(axis=1)
        return self.current + (moved - self.pixel_ll_now[v].sum()) / self.settings.temperature

    def set_offset(self, v: int, offset_m: float, log_likelihood: float) -> None:
        self.offsets_m[v] = offset_m
        self._cast = None
        if len(self.rows[v]):
            self._rescore(v)
        self.current = float(log_likelihood)

    def pixels_seen(self, objects: int) -> np.ndarray:
        """(objects,) pixels read where each of the first ``objects`` bodies is the nearest surface now."""
        counts = np.zeros(objects, int)
        for layers in self.layers:
            if layers.shape[1]:
                nearest = layers.argmin(axis=0)[np.isfinite(layers.min(axis=0))]
                counts += np.bincount(nearest[nearest < objects], minlength=objects)
        return counts


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
                   yaws_rad: np.ndarray | None = None, tilts_rad: np.ndarray | None = None) -> np.ndarray:
    """(height, width) depth the camera would measure of the scene with its dynamic objects at
    ``positions_m`` turned by ``yaws_rad`` (default: as published): objects over the support; NaN
    where neither is. The likelihood's own depth (``raycast``), at every pixel."""
    bodies = [*scene.dynamic_objects, *(b for b in scene.objects if b.static)]
    positions = np.array([b.position_m for b in bodies], float)
    yaws = np.zeros(len(bodies))
    if positions_m is not None:
        positions[:len(positions_m)] = positions_m
    if yaws_rad is not None:
        yaws[:len(yaws_rad)] = yaws_rad
    origin = np.asarray(camera.position_m, float)
    nearest = np.full((camera.height_px, camera.width_px), np.inf)
    tilted = np.zeros((len(bodies), 2))
    if tilts_rad is not None:
        tilted[:len(tilts_rad)] = tilts_rad
    for body, position, yaw, tilt in zip(bodies, positions, yaws, tilted):
        convex, rotation = convex_body(body), pose_rotations(np.array([yaw]), tilt[None])
        box = pixel_box(convex, camera, position[None], rotation)
        u0, u1, v0, v1 = (0, camera.width_px - 1, 0, camera.height_px - 1) if box is None else box
        columns = np.arange(max(int(np.floor(u0)), 0), min(int(np.ceil(u1)) + 1, camera.width_px))
        rows = np.arange(max(int(np.floor(v0)), 0), min(int(np.ceil(v1)) + 1, camera.height_px))
        if not len(rows) or not len(columns):
            continue
        grid_rows, grid_columns = (a.ravel() for a in np.meshgrid(rows, columns, indexing="ij"))
        depth = ray_depths(convex, origin, camera.rays_at(grid_rows, grid_columns), position[None], rotation)[0]
        window = nearest[rows[0]:rows[-1] + 1, columns[0]:columns[-1] + 1]
        np.minimum(window, depth.reshape(len(rows), len(columns)), out=window)
    return np.where(np.isfinite(nearest), nearest, support_depth_m(scene, camera))
