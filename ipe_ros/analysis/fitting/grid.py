"""The model evaluated at every point of a parameter grid, on common random numbers.

Each stimulus keeps one seed for every point (``runs.stimulus_seed``), so its k samples draw the
same standard normals at every sigma and the same launch draws at every launch SD: two points'
difference is the parameters', not the Monte Carlo's. A stimulus that a parameter cannot change
(nothing moves at t = 0, so launch noise draws nothing) is simulated once for every value of it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ...engine import Scene
from ...engine.input_sets import request_arguments_of
from ...engine.request import build_request
from ..reporting import progress
from ..runs import run_model
from .readout import Readout

#: a fit varies or holds the model's inputs (``engine.input_sets.MODEL_INPUTS``) by their node
#: parameter names, which the parameter set file uses too; these two only change what moves at t = 0
_LAUNCH = ("launch_speed_log_sd", "launch_direction_sd_deg")


@dataclass(frozen=True)
class Evaluation:
    """The model at one grid point: P(yes) per stimulus, what it cost."""

    point: tuple[tuple[str, float], ...]
    p_model: np.ndarray
    rollouts: int
    wall_s: float
    failed_samples: int

    @property
    def values(self) -> dict[str, float]:
        return dict(self.point)


def grid_points(grid: Mapping[str, Sequence[float]]) -> list[tuple[tuple[str, float], ...]]:
    """Every combination of the grid's values, the first parameter slowest."""
    points: list[tuple[tuple[str, float], ...]] = [()]
    for name, values in grid.items():
        points = [p + ((name, float(v)),) for p in points for v in values]
    return points


def evaluate(scenes: Sequence[Scene], readout: Readout, point: tuple[tuple[str, float], ...], *,
             fixed: Mapping[str, float], samples: int, seed: int, preset_name: str, map_fn=None,
             cache: dict | None = None) -> Evaluation:
    """P(yes) per scene at ``point`` (with the ``fixed`` inputs), each scene on its own seed;
    ``cache`` (shared across points) holds per-stimulus values for the points that cannot change
    them (see the module's docstring)."""
    cache = {} if cache is None else cache
    start = time.perf_counter()
    values = {**fixed, **dict(point)}
    request = build_request(**request_arguments_of(values), samples=samples, queries=(readout.query,),
                            contact=readout.contact, preset_name=preset_name, seed=seed, self_check=False)
    keys = [(s.name, _effective(s, values)) for s in scenes]
    todo = [i for i, k in enumerate(keys) if k not in cache]
    rollouts = failed = 0
    if todo:
        run = run_model(_label(point), [scenes[i] for i in todo], request.model, request.settings, request.query,
                        seed, map_fn)
        for i, prediction in zip(todo, run.predictions):
            cache[keys[i]] = readout.value(prediction)
            rollouts += prediction.samples
            failed += prediction.failed_samples
    p_model = np.array([cache[k] for k in keys])
    wall = time.perf_counter() - start
    progress(f"  fit: {_label(point)}: {rollouts} rollouts in {wall:.1f} s")
    return Evaluation(point, p_model, rollouts, wall, failed)


def _effective(scene: Scene, values: Mapping[str, float]) -> tuple:
    """The values that can change this scene's answer: launch noise only where something moves."""
    moves = any(b.moving for b in scene.dynamic_objects)
    return tuple(sorted((k, v) for k, v in values.items() if moves or k not in _LAUNCH))


def _label(point) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in point) or "the model"
