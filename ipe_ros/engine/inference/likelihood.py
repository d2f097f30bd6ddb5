"""How likely the observed frames are given one rollout: the tracker's noise and the physics' own error.

The physics errs: pybullet and the world (or another engine) part by a fraction of the distance an
object has travelled (benchmarks/results/witness: 0.2% on a plain slide, 5-12% after collisions and
bounces). A likelihood of the tracker's noise alone would be confidently wrong on observations made
elsewhere, so each object's residual along each axis is modelled as

    r(t) = noise(t) + model_error_fraction * travelled(t) * g(t),    noise ~ N(0, sd^2) per frame,

g a unit Gaussian process with correlation exp(-|t - t'| / MODEL_ERROR_MEMORY_S): an engine whose
friction or restitution is a little off is off by a share of the path, the same share for frames
close in time (treated as fresh at every frame, 60 frames would shrink it 8-fold), while after a
bounce or a collision the error may change its sign (a single share for the whole window, rank one,
left the ball's bounces confidently wrong). ``travelled`` is the observed path's length (the frames
smoothed over ``SMOOTHING_FRAMES``, so the tracker's noise does not add path), so an object at rest
adds no error however long it rests. It is the observation's, not each rollout's: a covariance that
shrank with the rollout's own path would favour candidates that move less (their smaller
determinant outweighed centimetres of misfit). The fraction itself is inferred: each candidate is
weighed at every fraction of MODEL_ERROR_GRID (``fit``).

Chaos is the engine's own: a candidate rolled out from starts a tracker's error apart may end
centimetres or decimetres apart (a falling tower). One rollout per candidate would let a lucky start
decide. So a candidate of a scene where that can happen is rolled out several times (``particle``),
and its frames are judged against the replicates' mean, their spread added to the covariance as a
third term of the same form (a synthetic likelihood, Wood 2010, made for chaotic dynamics); where
the first two replicates part by no more than a few times what they started apart, no more are run. Orientations, where a frame gives
one and the observation a ``yaw_sd_rad``, add the angle between observed and simulated orientation,
its SD growing with the angle the object has turned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the physics' error is inferred with the properties: each candidate is weighed at each of these
#: fractions, equally likely a priori (log-uniform), and the likelihood marginalised over them
#: (quadrature: a dimension the sampler need not explore). benchmarks/results/witness: pybullet's and
#: MuJoCo's ends part by 0.2% of the travel on plain slides and rolls, 4-12% after a collision or
#: bounce; the grid spans a tenth of the smallest to twice the largest
MODEL_ERROR_GRID = tuple(float(f) for f in np.geomspace(0.0002, 0.25, 13))
#: how long the physics' error keeps its direction (about one bounce of a ball dropped 30 cm)
MODEL_ERROR_MEMORY_S = 0.25
#: frames averaged to read the observed path's length through the tracker's noise
SMOOTHING_FRAMES = 5
#: the largest error the witness saw pybullet make (12% of the distance travelled, a collision's):
#: what the consistency check allows at most
CONSISTENT_MODEL_ERROR = 0.12
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
    log_likelihood_by_error: tuple[float, ...] = ()  # at each model error of the grid


@dataclass(frozen=True)
class Track:
    """One object's frames, and what its residuals' covariance is made of (``_log_likelihood``)."""

    name: str
    times_s: np.ndarray
    positions_m: np.ndarray  # (m, 3)
    orientations_xyzw: np.ndarray  # (m, 4), NaN rows where a frame gave none
    sd_m: float
    path_m: np.ndarray  # (m,) the observed path's length at each frame
    correlation: np.ndarray  # (m, m) K
    turned_rad: np.ndarray  # (m,) the observed orientation's turn so far (NaN-free; 0 where unknown)


def observed_path_m(positions_m: np.ndarray) -> np.ndarray:
    """Path length up to each frame, along the frames smoothed by a centred moving average."""
    m = len(positions_m)
    half = min(SMOOTHING_FRAMES // 2, max(0, (m - 1) // 2))
    padded = np.concatenate([np.repeat(positions_m[:1], half, 0), positions_m, np.repeat(positions_m[-1:], half, 0)])
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    smooth = np.stack([np.convolve(padded[:, a], kernel, mode="valid") for a in range(3)], axis=1)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(smooth, axis=0), axis=1))])


def track(name: str, times_s, positions_m, orientations_xyzw, sd_m: float) -> Track:
    """An object's frames (orientations: NaN rows where a frame gave none) with the tracker's ``sd_m``."""
    times_s, positions_m = np.asarray(times_s, float), np.asarray(positions_m, float)
    correlation = np.exp(-np.abs(times_s[:, None] - times_s[None, :]) / MODEL_ERROR_MEMORY_S)
    q = np.asarray(orientations_xyzw, float)
    seen = ~np.isnan(q[:, 0])
    turned = np.zeros(len(q))
    if seen.sum() > 1:
        steps = rotation_angle_rad(q[seen][1:], q[seen][:-1])
        turned[seen] = np.concatenate([[0.0], np.cumsum(steps)])
    return Track(name, times_s, positions_m, q, sd_m, observed_path_m(positions_m), correlation, turned)


def interpolate_positions(times_s: np.ndarray, positions_m: np.ndarray, at_s: np.ndarray) -> np.ndarray:
    """Positions (m, 3) at ``at_s``, linear between recorded times, the last held after the rollout ended."""
    return np.stack([np.interp(at_s, times_s, positions_m[:, axis]) for axis in range(3)], axis=1)


def rotation_angle_rad(a_xyzw: np.ndarray, b_xyzw: np.ndarray) -> np.ndarray:
    dots = np.abs(np.sum(a_xyzw * b_xyzw, axis=-1))
    return 2 * np.arccos(np.clip(dots, 0.0, 1.0))


@dataclass(frozen=True)
class Predicted:
    """A candidate's rollouts read at one track's frame times: their mean position, their spread
    (SD per axis, None for one rollout or where they agree), orientations (the first replicate's)."""

    positions_m: np.ndarray  # (m, 3)
    spread_m: np.ndarray | None  # (m,)
    orientations_xyzw: np.ndarray  # (m, 4)


def fit(tracks, predicted: dict, yaw_sd_rad: float | None, model_errors: tuple[float, ...]) -> Fit:
    """The frames of ``tracks`` (``Track``s) against ``predicted`` (name -> ``Predicted``), at each of
    ``model_errors`` (fractions, equally likely a priori): the likelihood marginal over them, and
    the worst misfit in SDs allowed with the physics' error at most CONSISTENT_MODEL_ERROR (a grid
    reaching 25% would call an object that jumps half a metre consistent)."""
    by_error = np.array([_log_likelihood(tracks, predicted, yaw_sd_rad, f) for f in model_errors])
    marginal = float(np.logaddexp.reduce(by_error) - math.log(len(model_errors)))
    check = min(max(model_errors), CONSISTENT_MODEL_ERROR)
    return Fit(marginal, *_worst(tracks, predicted, check), log_likelihood_by_error=tuple(by_error))


def _log_likelihood(tracks, predicted: dict, yaw_sd_rad: float | None, model_error_fraction: float) -> float:
    total = 0.0
    for seen in tracks:
        guess = predicted[seen.name]
        residual = seen.positions_m - guess.positions_m
        scale = model_error_fraction * seen.path_m
        if guess.spread_m is not None:
            scale = np.sqrt(scale ** 2 + guess.spread_m ** 2)
        cov = np.outer(scale, scale) * seen.correlation
        cov[np.diag_indices_from(cov)] += seen.sd_m ** 2  # the tracker's noise (no identity matrix built per fraction)
        chol = np.linalg.cholesky(cov)
        log_det = float(2 * np.log(np.diag(chol)).sum())
        solved = np.linalg.solve(chol, residual)
        m = len(seen.times_s)
        total += float(-0.5 * (np.sum(solved * solved) + 3 * log_det + 3 * m * math.log(2 * math.pi)))
        has = ~np.isnan(seen.orientations_xyzw[:, 0])
        if yaw_sd_rad is not None and has.any():
            angle = rotation_angle_rad(seen.orientations_xyzw[has], guess.orientations_xyzw[has])
            sd = np.sqrt(yaw_sd_rad ** 2 + (model_error_fraction * seen.turned_rad[has]) ** 2)
            total += float(np.sum(-0.5 * (angle / sd) ** 2 - np.log(sd) - 0.5 * math.log(2 * math.pi)))
    return total


def _worst(tracks, predicted: dict, model_error_fraction: float) -> tuple[float, float, str, float]:
    """(distance, time, object, SDs) of the frame farthest from the prediction in SDs allowed."""
    worst = (0.0, 0.0, "", 0.0)
    for seen in tracks:
        guess = predicted[seen.name]
        residual = seen.positions_m - guess.positions_m
        allowed = seen.sd_m ** 2 + (model_error_fraction * seen.path_m) ** 2
        if guess.spread_m is not None:
            allowed = allowed + guess.spread_m ** 2
        ratio = np.linalg.norm(residual, axis=1) / np.sqrt(3 * allowed)
        i = int(np.argmax(ratio))
        if ratio[i] > worst[3]:
            worst = (float(np.linalg.norm(residual[i])), float(seen.times_s[i]), seen.name, float(ratio[i]))
    return worst
