"""One candidate's rollout against the frames: what the workers run for an inference.

The parent draws each candidate's values (``amis``); ``run_particle`` (module-level, picklable)
builds the scene with them, rolls it out through the prediction's own sample path
(``sampling.rollout.run_sample``: separation, islands, reruns, the budget, failures counted) and
returns only the fit, not the trajectory.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import ModelConfig, SimSettings
from ..query import QuerySpec
from ..results.outcome import SampleOutcome
from ..sampling.rollout import SampleTask, run_sample
from ..scene import shapes
from ..scene.bodies import Scene
from ..scene.properties import with_properties
from .likelihood import Fit, Predicted, fit, interpolate_positions

#: the rollout's answer is its trajectory: the query that waits for rest and reads where bodies are
TRAJECTORY_SPEC = QuerySpec(queries=frozenset({"final_pose"}))
#: two rollouts that part by more than this many times their first frame's distance are chaotic
CHAOS_AMPLIFICATION = 3.0
#: no noise of the model's own: the candidates' values and velocities are the only differences
EXACT_MODEL = ModelConfig(sigma_m=0.0, samples=1, object_noise=False)


@dataclass(frozen=True)
class ParticleTask:
    """One candidate: ``scene`` holds its property values and initial velocities.

    ``tracks``: the observed objects' frames (``likelihood.Track``), the same for all candidates."""

    index: int
    scene: Scene
    settings: SimSettings
    tracks: tuple
    yaw_sd_rad: float | None
    #: the physics' error's fractions to weigh it at (likelihood.MODEL_ERROR_GRID, or one fixed)
    model_errors: tuple[float, ...]
    #: the initial state's noise integrated over: up to ``replicates`` rollouts from the scene's
    #: poses moved by N(0, initial_sd_m^2) horizontally, each from its own child of ``seed``
    initial_sd_m: float = 0.0
    replicates: int = 1
    seed: np.random.SeedSequence | None = None
    deadline_unix_s: float | None = None


@dataclass(frozen=True)
class ParticleOutcome:
    index: int
    ok: bool
    error: str | None = None
    fit: Fit | None = None
    budget_stopped: bool = False
    worker_lost: bool = False
    replicates: int = 0  # rollouts run for it


def run_particle(task: ParticleTask) -> ParticleOutcome:
    """The candidate's fit: one rollout where the start is exact, else two, and up to ``replicates``
    where those two part by more than CHAOS_AMPLIFICATION times what they started apart (chaos: see
    likelihood), whose spread then widens the fit."""
    noisy = task.initial_sd_m > 0 and task.replicates > 1
    model = dataclasses.replace(EXACT_MODEL, sigma_m=task.initial_sd_m if noisy else 0.0)
    seeds = task.seed.spawn(task.replicates) if noisy else [np.random.SeedSequence(task.index)]
    runs, chaotic = [], False
    for r, seed in enumerate(seeds):
        outcome = trajectory_sample(task.scene, task.settings, model=model, seed=seed, index=task.index,
                                    deadline_unix_s=task.deadline_unix_s)
        if not outcome.ok:
            return ParticleOutcome(task.index, False, outcome.error, budget_stopped=outcome.budget_stopped)
        runs.append(_at_frames(task, outcome.rollouts[0].trajectory))
        if r == 1:
            chaotic = not _agree(task, runs)
            if not chaotic:
                break
    predicted = {}
    for seen in task.tracks:
        positions = np.stack([run[seen.name][0] for run in runs])  # (replicates, m, 3)
        spread = np.sqrt(np.mean(positions.var(axis=0, ddof=1), axis=1)) if chaotic else None
        predicted[seen.name] = Predicted(positions.mean(axis=0), spread, runs[0][seen.name][1])
    return ParticleOutcome(task.index, True, fit=fit(task.tracks, predicted, task.yaw_sd_rad, task.model_errors),
                           replicates=len(runs))


def trajectory_sample(scene: Scene, settings: SimSettings, *, model: ModelConfig = EXACT_MODEL,
                      seed: np.random.SeedSequence | None = None, index: int = 0,
                      deadline_unix_s: float | None = None) -> SampleOutcome:
    """``scene`` rolled out through the prediction's own sample path, every step recorded: a
    candidate's replicate, an observation made at known properties, a recording's rollout."""
    return run_sample(SampleTask(scene=scene, model=model, settings=settings, query=TRAJECTORY_SPEC, index=index,
                                 seed=np.random.SeedSequence(index) if seed is None else seed, record_every=1,
                                 deadline_unix_s=deadline_unix_s))


def body_paths(scene: Scene, trajectory) -> tuple[np.ndarray, dict[str, tuple[np.ndarray, np.ndarray]]]:
    """A recorded trajectory as (its times (T,), dynamic body name -> (its frame's origins (T, 3),
    orientations (T, 4))): where a tracker would have seen each body."""
    times = np.array([frame[0] for frame in trajectory])
    centres = np.stack([frame[1] for frame in trajectory])  # (T, n, 3) centres of mass
    orientations = np.stack([frame[2] for frame in trajectory])
    return times, {body.name: (origins_of(body, centres[:, i], orientations[:, i]), orientations[:, i])
                   for i, body in enumerate(scene.dynamic_objects)}


def _agree(task: ParticleTask, runs: list) -> bool:
    """The first two replicates part by at most ``CHAOS_AMPLIFICATION`` times what they started
    apart (or the tracker's noise, where less): the candidate's motion is not chaotic."""
    for seen in task.tracks:
        apart = np.linalg.norm(runs[0][seen.name][0] - runs[1][seen.name][0], axis=1)
        if apart.max() > CHAOS_AMPLIFICATION * max(apart[0], seen.sd_m):
            return False
    return True


def _at_frames(task: ParticleTask, trajectory) -> dict:
    """Per observed object, its simulated (origins, orientations) at the frames' times."""
    times, paths = body_paths(task.scene, trajectory)
    out = {}
    for seen in task.tracks:
        origins, orientations = paths[seen.name]
        nearest = np.clip(np.searchsorted(times, seen.times_s), 0, len(times) - 1)
        out[seen.name] = (interpolate_positions(times, origins, seen.times_s), orientations[nearest])
    return out


def lost_particle(task: ParticleTask, reason: str) -> ParticleOutcome:
    return ParticleOutcome(task.index, False, f"WorkerLost: {reason}", worker_lost=True)


def origins_of(body, centres_m: np.ndarray, orientations_xyzw: np.ndarray) -> np.ndarray:
    """The body frame's origins (what a tracker reports) from its centres of mass."""
    local = shapes.centre_of_mass_m(body.shape)
    if not np.any(local):
        return centres_m
    return centres_m - np.stack([shapes.rotation_matrix(q) @ local for q in orientations_xyzw])


def with_values(scene: Scene, assigned: dict, velocities: dict) -> Scene:
    """The scene with ``assigned`` ((body name or "support", property) -> value) and ``velocities``
    (body name -> (vx, vy, vz), m/s) in place."""
    scene = with_properties(scene, assigned)
    if not velocities:
        return scene
    return dataclasses.replace(scene, objects=tuple(
        dataclasses.replace(b, linear_velocity_m_s=tuple(float(v) for v in velocities[b.name]))
        if b.name in velocities else b for b in scene.objects))
