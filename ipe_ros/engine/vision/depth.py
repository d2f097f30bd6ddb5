"""Uncertainty from the robot's own depth camera: the scene's posterior given depth images.

The likelihood is ``depth_model.DepthModel``'s. The prior is the detector's: each object's published
pose, x and y with SD ``prior_sd_m`` and yaw with ``prior_yaw_sd_rad``. A block in plain view is
pinned down by its pixels; one hidden behind another keeps the prior's spread. Heights are
estimated too (prior N(published, ``prior_height_sd_m``)), tilts taken as published. The sampler
(``depth_chain``) finds each object's peak, fits its curvature and samples by batched independence
proposals, with an injected Generator; several cameras multiply their likelihoods.

A real camera's range is biased by millimetres (a scale error, a calibration offset), which would
move every object along the view and make the posterior confidently wrong: each camera's range
offset is a nuisance parameter of the chain (prior N(0, ``offset_prior_sd_m``), a block of its
own), pinned down by the support around the objects, whose place is known.

The chain's answer for the robot: k scenes for the IPE, each object's refined pose (the posterior
mean) and covariance. Reading a robot's files is ``depth_io.py``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..scene.bodies import MAX_SET_DOWN_M, Scene, lowest_z_m, support_top_below
from ..sampling.montecarlo import MapFn, far_over_budget
from .depth_chain import ChainRun, OutOfTime, projected_end, sample_depth_posterior
from .depth_model import (DepthModel, DepthObservation, DepthSettings, check_layer_memory, render_depth_m,
                          support_depth_m)
from .mcmc import effective_sample_size
from .scene_pose import scene_at_pose
from .metropolis import thinned_index

__all__ = ["DEPTH_STREAM", "DepthObservation", "DepthPerceivedScenes", "DepthPosterior",
           "DepthSettings", "perceive_depth", "perceive_depth_for", "render_depth_m", "run_depth_chain",
           "scene_at_pose", "support_depth_m"]


#: the depth chain's random stream, apart from the samples' (SeedSequence(seed).spawn(k))
DEPTH_STREAM = 0xDE9



#: batches of proposals between checks of the chain's projected end against its deadline
BUDGET_CHECK_BATCHES = 10
#: the share of its scorings a chain does before its pace may refuse it: the first ones (locating
#: each object, caches still cold) run up to twice as slow as the rest, 2% in they are within 10%
WARM_UP_SHARE = 0.02


@dataclass(frozen=True)
class DepthPosterior:
    """The chain over every dynamic object's (x, y, yaw) after burn-in, and what it says per object."""

    names: tuple[str, ...]
    positions_m: np.ndarray  # (samples, objects, 3)
    yaws_rad: np.ndarray     # (samples, objects): turn from the published orientation
    acceptance_rate: float
    offsets_m: np.ndarray | None = None  # (samples, cameras): each camera's range offset (measured - true)
    pixels: np.ndarray | None = None  # (objects,) pixels read where the object is in front at the mean pose
    chains: int = 1  # the samples are this many independent chains' states, one after the other, equally many
    tilts_rad: np.ndarray | None = None  # (samples, objects, 2): tilts about the scene's x and y axes (none: 0)
    #: "states": every chain kept all its states; "budget": the deadline ended the chains first
    stopped_by: str = "states"

    def camera_offsets(self) -> list[dict[str, float]]:
        """Per camera: posterior mean and SD of its range offset (how much longer it measures than the
        scene is), in metres."""
        if self.offsets_m is None or not self.offsets_m.size:
            return []
        return [{"mean_m": float(o.mean()), "sd_m": float(o.std())} for o in self.offsets_m.T]

    @property
    def effective_sample_size(self) -> float:
        """The median ESS over every object's x, y and yaw (and z, when heights are estimated): the
        sum of the chains' own."""
        values = self.pose_values()
        values = values.reshape(len(values), -1)
        varying = [j for j in range(values.shape[1]) if np.ptp(values[:, j]) > 0]
        return float(np.median([sum(effective_sample_size(part) for part in np.split(values[:, j], self.chains))
                                for j in varying or range(values.shape[1])]))

    def pose_values(self) -> np.ndarray:
        """(samples, objects, 4): each object's x, y, z (m) and yaw (rad, a turn from the published)."""
        return np.concatenate([self.positions_m[:, :, :3], self.yaws_rad[:, :, None]], axis=2)

    def spread(self) -> dict[str, dict[str, float]]:
        """Per object: posterior SD of x, y, z (metres) and yaw (radians): the covariance's diagonal."""
        sd = np.sqrt(np.diagonal(self.covariance(), axis1=1, axis2=2))
        return {n: {"x_sd_m": float(s[0]), "y_sd_m": float(s[1]), "z_sd_m": float(s[2]), "yaw_sd_rad": float(s[3])}
                for n, s in zip(self.names, sd)}

    def tilts(self) -> np.ndarray:
        """(samples, objects, 2) tilts about the scene's x and y axes (rad; 0 where taken as published)."""
        return self.tilts_rad if self.tilts_rad is not None else np.zeros((*self.yaws_rad.shape, 2))

    def mean(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(objects, 3) posterior mean positions, (objects,) mean turns from the published yaw and
        (objects, 2) mean tilts."""
        return self.positions_m.mean(axis=0), self.yaws_rad.mean(axis=0), self.tilts().mean(axis=0)

    def covariance(self) -> np.ndarray:
        """(objects, 4, 4) posterior covariance of each object's (x, y, z, yaw) in m and rad."""
        values = self.pose_values()
        centred = values - values.mean(axis=0)
        return np.einsum("sai,saj->aij", centred, centred) / max(1, len(values) - 1)

    def interval95(self) -> tuple[np.ndarray, np.ndarray]:
        """(objects, 4) low and high ends of the central 95% intervals of x, y, z and yaw."""
        values = self.pose_values()
        return np.quantile(values, 0.025, axis=0), np.quantile(values, 0.975, axis=0)

    def thinned(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """k states spread evenly over the chain: positions, turns and tilts."""
        index = thinned_index(len(self.positions_m), k)
        return self.positions_m[index], self.yaws_rad[index], self.tilts()[index]


def run_depth_chain(scene: Scene, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                    rng: np.random.Generator, deadline_s: float | None = None, k: int = 0,
                    map_fn: MapFn | None = None) -> DepthPosterior:
    """The posterior over the dynamic objects' (x, y, height, yaw) and each camera's range offset,
    from the published scene (``depth_chain``): ``settings.chains`` independent chains, through
    ``map_fn`` (the worker pool: one chain per worker) or one after the other here, keeping at least
    ``k`` states together. The chains and their seeds never depend on the workers.

    ``deadline_s`` (``time.monotonic()``): a chain is refused (ConfigError naming ``budget_s``) once,
    warmed up, its pace shows it would take far more than is left; otherwise it runs,
    and the deadline ends it with the states it kept (``stopped_by`` "budget"; the chains cut to
    equally many), or with the same error when it comes before the first."""
    if not observations:
        raise ConfigError("depth", "depth perception needs at least one depth image")
    check_layer_memory(scene, observations)
    one_chain = dataclasses.replace(settings, kept_states=settings.kept_per_chain(k), chains=1)
    budget_s = None if deadline_s is None else deadline_s - time.monotonic()
    tasks = [_ChainTask(scene, observations, one_chain, chain_rng, budget_s) for chain_rng in rng.spawn(settings.chains)]
    if map_fn is not None and len(tasks) > 1:
        runs = map_fn(run_one_chain, tasks)
    else:  # one after the other: each its share of what is left, so that together they end by the deadline
        runs = [run_one_chain(t if deadline_s is None else
                              dataclasses.replace(t, budget_s=(deadline_s - time.monotonic()) / (len(tasks) - i)))
                for i, t in enumerate(tasks)]
    stopped = any(r.stopped_by_budget for r in runs)
    if stopped:  # the chains' states, one chain after the other, equally many (the ESS splits them so)
        states = min(len(r.positions_m) for r in runs)
        runs = [r.first(states) for r in runs]
    dynamic = len(scene.dynamic_objects)
    positions, yaws = np.concatenate([r.positions_m for r in runs]), np.concatenate([r.yaws_rad for r in runs])
    tilts = np.concatenate([r.tilts_rad for r in runs])
    model = DepthModel(scene, observations, settings)  # which pixels show each object at the posterior mean
    model.start(*_with_static(scene, positions.mean(axis=0), yaws.mean(axis=0), tilts.mean(axis=0)))
    return DepthPosterior(names=tuple(b.name for b in scene.dynamic_objects), positions_m=positions, yaws_rad=yaws,
                          acceptance_rate=float(np.mean([r.acceptance_rate for r in runs])),
                          offsets_m=np.concatenate([r.offsets_m for r in runs]), pixels=model.pixels_seen(dynamic),
                          chains=len(runs), tilts_rad=tilts, stopped_by="budget" if stopped else "states")


@dataclass(frozen=True)
class _ChainTask:
    """One chain of the depth posterior, for a worker: ``budget_s`` is what the budget left it when
    sent (each process's clock starts its own deadline from it)."""

    scene: Scene
    observations: tuple[DepthObservation, ...]
    settings: DepthSettings
    rng: np.random.Generator
    budget_s: float | None


def _with_static(scene: Scene, positions_m: np.ndarray, yaws_rad: np.ndarray,
                 tilts_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every body's pose (dynamic ones first, as ``DepthModel`` orders them): the dynamic ones' given."""
    static = [b for b in scene.objects if b.static]
    return (np.concatenate([positions_m, np.array([b.position_m for b in static], float).reshape(-1, 3)]),
            np.concatenate([yaws_rad, np.zeros(len(static))]), np.concatenate([tilts_rad, np.zeros((len(static), 2))]))


#: an object whose lowest point is this far above the support rests on another: its tilt is estimated
RESTING_ON_ANOTHER_M = 0.005


def resting_on_another(scene: Scene) -> np.ndarray:
    """(dynamic objects,) bool: the object's lowest point is above the support under it (a box on a
    box can lie tilted; one on the floor or a table top lies as the support does)."""
    out = []
    for body in scene.dynamic_objects:
        top = support_top_below(scene.support, body.position_m[0], body.position_m[1])
        out.append(lowest_z_m(body) > (-np.inf if top is None else top) + RESTING_ON_ANOTHER_M)
    return np.array(out, bool)


def run_one_chain(task: _ChainTask) -> ChainRun:
    """One chain from the published scene (module-level: a worker process runs it)."""
    started = time.monotonic()
    deadline_s = None if task.budget_s is None else started + task.budget_s
    scene, dynamic = task.scene, len(task.scene.dynamic_objects)
    positions, yaws, tilts = _with_static(scene, np.array([b.position_m for b in scene.dynamic_objects],
                                                          float).reshape(-1, 3), np.zeros(dynamic), np.zeros((dynamic, 2)))
    model = DepthModel(scene, task.observations, task.settings)
    model.start(positions, yaws, tilts)
    if deadline_s is not None and time.monotonic() > deadline_s:
        raise ConfigError("budget_s", f"reading the depth image for {dynamic} objects took "
                                      f"{time.monotonic() - started:.3g} s, all the budget leaves the depth chain; "
                                      "raise the budget, bin or crop the image, or send fewer objects")
    sampling, batches = time.monotonic(), 0  # the projection from the sampler's own pace, the reading apart

    def check(done: int, total: int) -> None:
        nonlocal batches
        batches += 1
        if deadline_s is None:
            return
        if time.monotonic() > deadline_s:
            raise OutOfTime
        if batches % BUDGET_CHECK_BATCHES == 0 and done >= WARM_UP_SHARE * total:
            _refuse_far_over(started, sampling, deadline_s, done, total, dynamic)

    tilted = resting_on_another(scene) & (task.settings.prior_tilt_sd_rad > 0)
    try:
        return sample_depth_posterior(model, positions, yaws, tilts, tilted, task.settings, task.rng, check)
    except OutOfTime:  # before the chain kept a state: nothing to answer with
        raise ConfigError("budget_s", f"the depth chain over {dynamic} objects reached the end of its "
                                      f"{deadline_s - started:.3g} s before it kept a state; raise the budget or "
                                      "send fewer objects") from None


def _refuse_far_over(started: float, sampling: float, deadline_s: float, done: int, total: int, objects: int) -> None:
    """Refused when the chain, at the pace of its ``done`` scorings since ``sampling`` began, would
    take far more than the budget leaves it (``montecarlo.far_over_budget``)."""
    now = time.monotonic()
    projected = projected_end(sampling, done, total)
    # refused only far over, once warmed up: nearer, the chain runs and the deadline ends it with fewer states
    if far_over_budget(projected - sampling, deadline_s - sampling):
        raise ConfigError("budget_s", f"the depth chain over {objects} objects needs ~{projected - started:.3g} s "
                                      f"({total} scorings of the image; {done} took {now - sampling:.3g} s), far more "
                                      f"than the {deadline_s - started:.3g} s the budget leaves it; raise the "
                                      "budget or send fewer objects")


@dataclass(frozen=True)
class DepthPerceivedScenes:
    """k scenes from the depth posterior, with how well the chain mixed, and the scene refined: every
    dynamic object at its posterior mean pose (``refined``), with its covariance in ``to_dict``."""

    scenes: tuple[Scene, ...]
    posterior: DepthPosterior
    chain_samples: int
    burn_in: int
    refined: Scene
    given: Scene | None = None  # the scene as the detector published it (the prior's centre)

    def with_samples(self, k: int) -> "DepthPerceivedScenes":
        """k scenes spread over the same chain (a robot question asks for another k than the
        prediction the chain was run for): no new chain."""
        if self.given is None or k > len(self.posterior.positions_m):
            raise ConfigError("samples", f"the depth chain keeps {len(self.posterior.positions_m)} states, fewer than "
                                         f"the {k} samples asked; ask for fewer")
        return dataclasses.replace(self, scenes=_thinned_scenes(self.given, self.posterior, k))

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
                "kept_states": len(self.posterior.positions_m), "stopped_by": self.posterior.stopped_by,
                "roughly_independent": self.effective_sample_size >= 0.5 * len(self.scenes),
                "objects": self.objects(), "camera_offsets": self.posterior.camera_offsets()}

    def objects(self) -> dict[str, dict[str, Any]]:
        """Per dynamic object: the refined pose (posterior mean), how many pixels read show it there (0:
        the image says nothing of it, its pose is the detector's prior), the posterior covariance of
        (x, y, z, yaw) and the SDs on its diagonal, and its tilt from the published orientation about
        the scene's x and y axes with their SDs (0 and 0 where taken as published: an object resting
        on the support)."""
        covariance, spread = self.posterior.covariance(), self.posterior.spread()
        tilts = self.posterior.tilts()
        refined = {b.name: b for b in self.refined.dynamic_objects}
        out = {}
        pixels = self.posterior.pixels if self.posterior.pixels is not None else [None] * len(covariance)
        for i, (name, c, seen) in enumerate(zip(self.posterior.names, covariance, pixels)):
            body = refined[name]
            out[name] = {"position_m": list(body.position_m), "orientation_xyzw": list(body.orientation_xyzw),
                         "pixels": None if seen is None else int(seen),
                         "covariance_x_y_z_yaw": c.tolist(), **spread[name],
                         "tilt_rad": tilts[:, i].mean(axis=0).tolist(), "tilt_sd_rad": tilts[:, i].std(axis=0).tolist()}
        return out


def _thinned_scenes(given: Scene, posterior: DepthPosterior, k: int) -> tuple[Scene, ...]:
    """k scenes spread evenly over the chain: ``given`` with its objects at each kept pose."""
    return tuple(scene_at_pose(given, p, y, t) for p, y, t in zip(*posterior.thinned(k)))


#: objects are set down from at least this far above their supports (a posterior sure of its heights
#: still leaves them apart by the contact's own scale)
SET_DOWN_FLOOR_M = 0.001


def with_heights_estimated(scene: Scene, posterior: DepthPosterior, settings: DepthSettings) -> Scene:
    """``scene`` saying that its objects' heights are the posterior's estimates: each sample's objects
    are set down onto what is under them from up to ``settings.set_down_sds`` SDs of the least certain
    height above it (``Scene.set_down_m``; an image leaves a stack's heights millimetres apart, and a
    block that drops them strikes its support: a standing tower would look less stable than it is)."""
    if settings.set_down_sds == 0:
        return scene
    spread = float(posterior.positions_m[:, :, 2].std(axis=0).max(initial=0.0))
    within = min(MAX_SET_DOWN_M, SET_DOWN_FLOOR_M + settings.set_down_sds * spread)
    return dataclasses.replace(scene, set_down_m=max(scene.set_down_m, within))


def perceive_depth(scene: Scene, k: int, observations: tuple[DepthObservation, ...], settings: DepthSettings,
                   rng: np.random.Generator, deadline_s: float | None = None,
                   map_fn: MapFn | None = None) -> DepthPerceivedScenes:
    """k scenes spread over the depth posterior of ``scene`` (the detector's guess) given the images."""
    posterior = run_depth_chain(scene, observations, settings, rng, deadline_s, k, map_fn)
    scene = with_heights_estimated(scene, posterior, settings)
    objects = len(scene.dynamic_objects)
    return DepthPerceivedScenes(scenes=_thinned_scenes(scene, posterior, k), posterior=posterior,
                                chain_samples=settings.chain_samples(objects, k),
                                burn_in=settings.burn_in(objects), refined=scene_at_pose(scene, *posterior.mean()),
                                given=scene)


def perceive_depth_for(scene: Scene, k: int, observations: tuple[DepthObservation, ...], seed: int,
                       settings: DepthSettings | None = None, budget_s: float | None = None,
                       map_fn: MapFn | None = None) -> DepthPerceivedScenes:
    """``perceive_depth`` as a prediction with this ``seed`` runs it (the CLI, the node): its chains on
    a random stream of their own, apart from the samples', within ``budget_s`` seconds when given,
    through ``map_fn`` when given (the prediction's worker pool)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, DEPTH_STREAM]))
    deadline = None if budget_s is None else time.monotonic() + budget_s
    return perceive_depth(scene, k, observations, settings or DepthSettings(), rng, deadline, map_fn)
