"""The IPE fitted to people: the grid evaluated once, cross-validated, then fitted on every stimulus.

The result is a parameter set (``parameter_set``) that ``ipe predict --inputs-from``, ``ipe ask
--inputs-from`` and the node's ``inputs_from`` load, with its provenance: the defaults are never
changed by a fit.

Intervals: each parameter's profile log-likelihood over its grid values (the best of the other
parameters and of the mapping at each value); the values within chi2(1, 0.95) / 2 = 1.92 of the
maximum, scaled by the responses' overdispersion (Pearson chi2 over its degrees of freedom, when
above 1: people differ between stimuli more than a binomial around any model says, and the model's
own Monte Carlo adds noise). An interval is as fine as the grid: its ends are grid values.
"""

from __future__ import annotations

import datetime
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ... import __version__
from ...engine import ConfigError, Scene
from ...engine.errors import shown
from .crossval import FoldResult, Scores, cross_validate, pooled, train
from ...engine.input_sets import request_arguments_of
from .grid import Evaluation, evaluate, grid_points
from .mapping import ResponseMapping
from .readout import Readout
from .responses import Responses

PARAMETER_SET_FORMAT = "ipe_ros.inputs/1"
CHI2_1_95 = 3.841458820694124


@dataclass(frozen=True)
class FitSettings:
    """What a fit was asked: the grid (each parameter's values), the inputs held fixed, k per stimulus
    and point, the seed (samples and folds), the folds, the preset."""

    grid: tuple[tuple[str, tuple[float, ...]], ...]
    fixed: tuple[tuple[str, float], ...] = ()
    samples: int = 16
    seed: int = 0
    folds: int = 5
    preset: str = "default"

    @classmethod
    def of(cls, grid: Mapping[str, Sequence[float]], fixed: Mapping[str, float] | None = None, **kw) -> "FitSettings":
        return cls(tuple((k, tuple(float(v) for v in vs)) for k, vs in grid.items()),
                   tuple((k, float(v)) for k, v in (fixed or {}).items()), **kw)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.grid)

    def to_dict(self) -> dict:
        return {"grid": {k: list(v) for k, v in self.grid}, "fixed": dict(self.fixed), "samples": self.samples,
                "seed": self.seed, "folds": self.folds, "preset": self.preset}


@dataclass(frozen=True)
class FitResult:
    readout: Readout
    responses: Responses
    evaluations: tuple[Evaluation, ...]
    reference: int
    folds: tuple[FoldResult, ...]
    cv: Scores
    cv_reference: Scores
    chosen: int
    mapping: ResponseMapping
    loglik: np.ndarray  # per grid point, every stimulus, its best mapping
    overdispersion: float
    intervals: dict[str, tuple[float, float]]
    settings: FitSettings

    @property
    def parameters(self) -> dict[str, float]:
        return self.evaluations[self.chosen].values

    def profile(self, name: str) -> tuple[list[float], list[float]]:
        return _profile(self.evaluations, self.loglik, name)


def _profile(evaluations: Sequence[Evaluation], loglik: np.ndarray, name: str) -> tuple[list[float], list[float]]:
    """Parameter ``name``'s grid values and, at each, the best log-likelihood over the others."""
    values = sorted({e.values[name] for e in evaluations})
    return values, [max(ll for e, ll in zip(evaluations, loglik) if e.values[name] == v) for v in values]


def check_grid(grid: Mapping[str, Sequence[float]], fixed: Mapping[str, float]) -> None:
    if not grid:
        raise ConfigError("grid", "give at least one parameter to fit, e.g. --grid sigma=0,0.01,0.02,0.04")
    for name, values in grid.items():
        if name in fixed:
            raise ConfigError("grid", f"{name} is both fitted and fixed: give it once")
        if len(values) < 2 or len(set(values)) != len(values):
            raise ConfigError("grid", f"{name}: give two or more different values, got {shown(list(values))}")
        for v in values:
            request_arguments_of({name: v})


def evaluate_grid(scenes: Sequence[Scene], readout: Readout, grid: Mapping[str, Sequence[float]], *,
                  reference: Mapping[str, float], fixed: Mapping[str, float] | None = None, samples: int = 16,
                  seed: int = 0, preset_name: str = "default", map_fn=None) -> tuple[tuple[Evaluation, ...], int]:
    """The model at every grid point (and at ``reference``, the point the fit is held against, where
    it is not on the grid), and the reference's index."""
    fixed = dict(fixed or {})
    check_grid(grid, fixed)
    if set(reference) - set(grid):
        raise ConfigError("reference", f"names {sorted(set(reference) - set(grid))[0]}, which the grid does not vary")
    points = grid_points(grid)
    reference_point = tuple((name, float(reference.get(name, values[0]))) for name, values in grid.items())
    if reference_point not in points:
        points.append(reference_point)
    cache: dict = {}
    evaluations = tuple(evaluate(scenes, readout, p, fixed=fixed, samples=samples, seed=seed, preset_name=preset_name,
                                 map_fn=map_fn, cache=cache) for p in points)
    return evaluations, points.index(reference_point)


def fit(scenes: Sequence[Scene], responses: Responses, readout: Readout, grid: Mapping[str, Sequence[float]], *,
        reference: Mapping[str, float], fixed: Mapping[str, float] | None = None, samples: int = 16,
        seed: int = 0, folds: int = 5, preset_name: str = "default", map_fn=None) -> FitResult:
    """Fit ``grid``'s parameters and the response mapping to ``responses`` (in ``scenes``' order:
    ``responses.matched``). ``reference``: the point the fit is held against (the paper's parameters;
    evaluated besides the grid where it is not on it)."""
    check_grid(grid, dict(fixed or {}))
    if not 2 <= folds <= len(scenes):
        raise ConfigError("folds", f"must be in [2, {len(scenes)}] (the stimuli), got {folds}")
    if tuple(s.name for s in scenes) != responses.stimuli:
        raise ValueError("fit: the responses must be matched to the scenes (responses.matched)")
    evaluations, ref = evaluate_grid(scenes, readout, grid, reference=reference, fixed=fixed, samples=samples,
                                     seed=seed, preset_name=preset_name, map_fn=map_fn)
    return fit_evaluations(evaluations, ref, responses, readout,
                           FitSettings.of(grid, fixed, samples=samples, seed=seed, folds=folds, preset=preset_name))


def fit_evaluations(evaluations: Sequence[Evaluation], reference: int, responses: Responses, readout: Readout,
                    settings: FitSettings) -> FitResult:
    """The fit from the grid's evaluations: cross-validated, then on every stimulus with intervals."""
    p_models = np.array([e.p_model for e in evaluations])
    results = cross_validate(p_models, responses, reference, settings.folds, settings.seed, settings.samples)
    lls, mappings = train(p_models, responses, np.arange(p_models.shape[1]), settings.samples)
    chosen = int(np.argmax(lls))
    names = settings.names
    dispersion = _overdispersion(mappings[chosen].p_yes(p_models[chosen]), responses, len(names) + 3)
    intervals = {name: _interval(*_profile(evaluations, lls, name), dispersion) for name in names}
    return FitResult(readout, responses, tuple(evaluations), reference, tuple(results), pooled(results, responses),
                     pooled(results, responses, reference=True), chosen, mappings[chosen], lls, dispersion, intervals,
                     settings)


def _overdispersion(p_yes: np.ndarray, responses: Responses, fitted: int) -> float:
    n, yes = responses.responders, responses.yes_counts
    chi2 = np.sum((yes - n * p_yes) ** 2 / np.maximum(n * p_yes * (1 - p_yes), 1e-9))
    return float(max(1.0, chi2 / max(1, len(n) - fitted)))


def _interval(values: list[float], profile: list[float], dispersion: float) -> tuple[float, float]:
    top = max(profile)
    inside = [v for v, ll in zip(values, profile) if 2 * (top - ll) <= CHI2_1_95 * dispersion]
    return min(inside), max(inside)


def parameter_set(result: FitResult, *, scenes_path: str, responses_path: str) -> dict:
    """The file ``--inputs-from`` loads: the fitted inputs, the response mapping, and where they came from."""
    return {
        "format": PARAMETER_SET_FORMAT,
        "inputs": {**dict(result.settings.fixed), **result.parameters},
        "response_mapping": result.mapping.to_dict(),
        "provenance": {
            "made_by": f"ipe fit (ipe_ros {__version__})",
            "date": datetime.date.today().isoformat(),
            "scenes": scenes_path, "responses": responses_path, "stimuli": len(result.responses.stimuli),
            "readout": str(result.readout), **{k: v for k, v in result.settings.to_dict().items() if k != "fixed"},
            "intervals_95": {k: list(v) for k, v in result.intervals.items()},
            "overdispersion": result.overdispersion,
            "reference": result.evaluations[result.reference].values,
            "cross_validated_r": _finite(result.cv.r), "reference_cross_validated_r": _finite(result.cv_reference.r),
            "note": "inputs fitted to people's responses, not the package's defaults; the response mapping turns "
                    "the model's probability into people's P(yes) and is not applied by ipe predict",
        },
    }


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def write_parameter_set(path: str | Path, content: dict) -> None:
    Path(path).write_text(json.dumps(content, indent=1) + "\n")
