"""The Monte Carlo IPE (paper Eq. S5): one seed per sample, an injected map, aggregation.

Parallelism is a ``map`` argument (the builtin for in-process, ``WorkerPool.map`` for workers):
the sampler neither knows nor cares where samples run. Each sample i gets the i-th child of
``SeedSequence(seed)``, so a prediction is a function of (scene, settings, seed) alone.
"""

from __future__ import annotations

import time
from typing import Callable, Sequence

import numpy as np

from .config import ModelConfig, QuerySpec, SimSettings
from .errors import ConfigError
from .estimate import Prediction, aggregate
from .rollout import SampleOutcome, SampleTask, run_sample
from .scene import DEFAULT_MAX_OBJECTS, Scene, Table, validate_scene

MapFn = Callable[..., list]


def _lost(task: SampleTask, reason: str) -> SampleOutcome:
    return SampleOutcome(index=task.index, ok=False, error=f"WorkerLost: {reason}",
                         push_direction_rad=float("nan"), initial_positions_m=None,
                         initial_orientations_xyzw=None)


def make_tasks(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int,
               record_every: int = 0, record_samples: int | None = None) -> list[SampleTask]:
    """k tasks, one child seed each; the ground-truth model (sigma = phi = 0) needs only one.

    Trajectories (every ``record_every`` steps) are recorded for the first ``record_samples``
    samples only (None: all), since only the rollouts that rerun will show need them.
    """
    k = 1 if model.is_deterministic else model.samples
    seeds = np.random.SeedSequence(seed).spawn(k)
    recorded = k if record_samples is None else record_samples
    return [SampleTask(scene=scene, model=model, settings=settings, query=query, index=i, seed=s,
                       record_every=record_every if i < recorded else 0) for i, s in enumerate(seeds)]


def check_request(scene: Scene, query: QuerySpec, max_objects: int = DEFAULT_MAX_OBJECTS) -> None:
    """Reject what cannot be answered before any simulation starts."""
    validate_scene(scene, max_objects=max_objects)
    if query.wants("bump") and not isinstance(scene.support, Table):
        raise ConfigError("queries", "the bump query needs a table support (it counts boxes that fall "
                                     "off the table's edge); drop 'bump' or give the scene a table")


def predict(scene: Scene, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int = 0,
            map_fn: MapFn | None = None, record_every: int = 0, record_samples: int | None = None,
            max_objects: int = DEFAULT_MAX_OBJECTS) -> Prediction:
    """Run the IPE on one scene and aggregate (failed rollouts are counted in ``failed_samples``).

    ``record_every``/``record_samples``: record trajectories (for rerun) every N simulation steps
    for the first M samples; recording never changes the outcome.
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", f"must be an integer >= 0, got {seed!r}")
    check_request(scene, query, max_objects)
    tasks = make_tasks(scene, model, settings, query, seed, record_every, record_samples)
    start = time.perf_counter()
    if map_fn is None:
        outcomes: Sequence[SampleOutcome] = [run_sample(t) for t in tasks]
    else:
        outcomes = map_fn(run_sample, tasks, on_lost=_lost)
    wall_s = time.perf_counter() - start
    settings_echo = {
        "sigma_m": model.sigma_m, "phi_m_s2": list(model.phi_m_s2),
        "force_direction_rad": model.force_direction_rad, "mu": model.mu, "preset": settings.name,
        "time_step_s": settings.time_step_s, "horizon_s": settings.horizon_s,
        "solver_iterations": settings.solver_iterations, "seed": seed, "queries": sorted(query.queries),
    }
    return aggregate(scene, outcomes, queries=query.queries, bump_group=query.bump_group,
                     deterministic=model.is_deterministic, samples_requested=len(tasks),
                     wall_s=wall_s, settings=settings_echo)
