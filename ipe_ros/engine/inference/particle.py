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
from ..sampling.rollout import SampleTask, run_sample
from ..scene import shapes
from ..scene.bodies import Scene
from .likelihood import Fit, fit

#: the rollout's answer is its trajectory: the query that waits for rest and reads where bodies are
TRAJECTORY_SPEC = QuerySpec(queries=frozenset({"final_pose"}))
#: no noise of the model's own: the candidates' values and velocities are the only differences
EXACT_MODEL = ModelConfig(sigma_m=0.0, samples=1, object_noise=False)


@dataclass(frozen=True)
class ParticleTask:
    """One candidate: ``scene`` holds its property values and initial velocities.

    ``tracks``: the observed objects' frames (``likelihood.Track``), factored once for all candidates."""

    index: int
    scene: Scene
    settings: SimSettings
    tracks: tuple
    yaw_sd_rad: float | None
    model_error_fraction: float
    deadline_unix_s: float | None = None


@dataclass(frozen=True)
class ParticleOutcome:
    index: int
    ok: bool
    error: str | None = None
    fit: Fit | None = None
    budget_stopped: bool = False
    worker_lost: bool = False


def run_particle(task: ParticleTask) -> ParticleOutcome:
    sample = SampleTask(scene=task.scene, model=EXACT_MODEL, settings=task.settings, query=TRAJECTORY_SPEC, index=task.index,
                        seed=np.random.SeedSequence(task.index), record_every=1, deadline_unix_s=task.deadline_unix_s)
    outcome = run_sample(sample)
    if not outcome.ok:
        return ParticleOutcome(task.index, False, outcome.error, budget_stopped=outcome.budget_stopped)
    trajectory = outcome.rollouts[0].trajectory
    times = np.array([frame[0] for frame in trajectory])
    positions = np.stack([frame[1] for frame in trajectory])  # (T, n, 3) centres of mass
    orientations = np.stack([frame[2] for frame in trajectory])
    index = {b.name: i for i, b in enumerate(task.scene.dynamic_objects)}
    rolled = {}
    for seen in task.tracks:
        i = index[seen.name]
        rolled[seen.name] = (times, origins_of(task.scene.dynamic_objects[i], positions[:, i], orientations[:, i]),
                             orientations[:, i])
    return ParticleOutcome(task.index, True, fit=fit(task.tracks, rolled, task.yaw_sd_rad, task.model_error_fraction))


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
    support = scene.support
    changes = {prop: value for (name, prop), value in assigned.items() if name == "support"}
    if changes:
        support = dataclasses.replace(support, **changes)
    objects = []
    for body in scene.objects:
        fields = {prop: float(value) for (name, prop), value in assigned.items() if name == body.name}
        if "mass_kg" in fields:
            fields["density_kg_m3"] = None
        if body.name in velocities:
            fields["linear_velocity_m_s"] = tuple(float(v) for v in velocities[body.name])
        objects.append(dataclasses.replace(body, **fields) if fields else body)
    return dataclasses.replace(scene, objects=tuple(objects), support=support)
