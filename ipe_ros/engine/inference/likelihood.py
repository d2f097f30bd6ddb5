"""How likely the observed frames are given one rollout: the tracker's noise and the physics' own error.

The physics errs: pybullet and the world (or another engine) part by a fraction of the distance an
object has travelled (benchmarks/results/witness: 0.2% on a plain slide, 5-12% after collisions and
bounces). A likelihood of the tracker's noise alone would be confidently wrong on observations made
elsewhere, so each object's residual along each axis is modelled as

    r(t) = noise(t) + model_error_fraction * travelled(t) * g,    noise ~ N(0, sd^2) per frame, g ~ N(0, 1)

one g per object and axis for the whole window: an engine whose friction or restitution is a little
off is off by a share of the path that grows through the window, not afresh at every frame (treating
it as fresh per frame would let 60 frames shrink it 8-fold). The covariance is diagonal plus rank one,
so its density is closed form (Sherman-Morrison), O(frames). ``travelled`` is the rollout's own path
length, so an object at rest adds no error however long it rests. Orientations, where a frame gives
one and the observation a ``yaw_sd_rad``, add the angle between observed and simulated orientation,
its SD growing with the angle the object has turned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: benchmarks/results/witness: pybullet's and MuJoCo's ends part by 0.2% of the travel on plain
#: slides and rolls, 4-12% after a collision or bounce; 5% is stated for all, not fitted
DEFAULT_MODEL_ERROR_FRACTION = 0.05
#: an observation is "consistent" when the best rollout stays within this many SDs of every frame
CONSISTENT_WITHIN_SD = 5.0


@dataclass(frozen=True)
class Fit:
    """One rollout against the frames."""

    log_likelihood: float
    worst_residual_m: float  # the largest distance between an observed and a simulated position
    worst_t_s: float
    worst_object: str
    worst_sds: float  # that residual over its frame's allowed SD (noise and model error)


def path_length_m(times_s: np.ndarray, positions_m: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """Distance travelled along the recorded path up to each of ``at_s``."""
    steps = np.linalg.norm(np.diff(positions_m, axis=0), axis=1)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    return np.interp(at_s, times_s, travelled)


def rank_one_log_density(residual: np.ndarray, sd_m: float, shape: np.ndarray) -> float:
    """log N(residual; 0, sd^2 I + shape shape^T), by Sherman-Morrison and the matrix determinant lemma."""
    a = sd_m * sd_m
    ss, sr, rr = float(shape @ shape), float(shape @ residual), float(residual @ residual)
    quadratic = (rr - sr * sr / (a + ss)) / a
    log_det = len(residual) * math.log(a) + math.log1p(ss / a)
    return -0.5 * (quadratic + log_det + len(residual) * math.log(2 * math.pi))


def interpolate_positions(times_s: np.ndarray, positions_m: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """Positions (m, 3) at ``at_s``, linear between recorded times, the last held after the rollout ended."""
    return np.stack([np.interp(at_s, times_s, positions_m[:, axis]) for axis in range(3)], axis=1)


def rotation_angle_rad(a_xyzw: np.ndarray, b_xyzw: np.ndarray) -> np.ndarray:
    dots = np.abs(np.sum(a_xyzw * b_xyzw, axis=-1))
    return 2 * np.arccos(np.clip(dots, 0.0, 1.0))


def fit(tracks: dict, rolled: dict, sd_m: float, yaw_sd_rad: float | None, model_error_fraction: float) -> Fit:
    """``tracks``: name -> (times, observed positions, observed orientations or None per frame);
    ``rolled``: name -> (times, simulated positions, simulated orientations)."""
    total, worst = 0.0, (0.0, 0.0, "", 0.0)
    for name, (times, observed, observed_orn) in tracks.items():
        sim_t, sim_p, sim_q = rolled[name]
        at = interpolate_positions(sim_t, sim_p, times)
        travelled = path_length_m(sim_t, sim_p, times)
        shape = model_error_fraction * travelled
        residual = observed - at
        for axis in range(3):
            total += rank_one_log_density(residual[:, axis], sd_m, shape)
        distance = np.linalg.norm(residual, axis=1)
        allowed = np.sqrt(3 * sd_m ** 2 + 3 * shape ** 2)
        i = int(np.argmax(distance / allowed))
        if distance[i] / allowed[i] > worst[3]:
            worst = (float(distance[i]), float(times[i]), name, float(distance[i] / allowed[i]))
        if yaw_sd_rad is not None and observed_orn is not None:
            seen = ~np.isnan(observed_orn[:, 0])
            if seen.any():
                nearest = np.clip(np.searchsorted(sim_t, times[seen]), 0, len(sim_t) - 1)
                angle = rotation_angle_rad(observed_orn[seen], sim_q[nearest])
                turned = _turned_rad(sim_q, sim_t, times[seen])
                sd = np.sqrt(yaw_sd_rad ** 2 + (model_error_fraction * turned) ** 2)
                total += float(np.sum(-0.5 * (angle / sd) ** 2 - np.log(sd) - 0.5 * math.log(2 * math.pi)))
    return Fit(total, *worst)


def _turned_rad(orientations_xyzw: np.ndarray, times_s: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    steps = rotation_angle_rad(orientations_xyzw[1:], orientations_xyzw[:-1])
    return np.interp(at_s, times_s, np.concatenate([[0.0], np.cumsum(steps)]))
