"""The IPE run over a stimulus set, kept per sample so that any analysis can re-aggregate it.

Units and the paper's parameters:
    sigma: the paper gives it in block short sides (tower blocks 0.2 m here, as in the stimulus
        files), so sigma_m = 0.2 * sigma_paper (0.2 sides -> 0.04 m).
    phi: the paper's phi is the magnitude of a horizontal force on the support for 0.2 s, in the
        units of its ODE scenes, with the support's mass unstated, so it has no exact conversion.
        The engine's phi is the support's acceleration in m/s^2 for 0.2 s. We calibrate one paper
        unit to 0.4 m/s^2 from the paper's own description of Exp. 5: phi = 22 "usually caused only
        one or a few blocks to fall off the table, and phi = 76 caused many or almost all to fall off".
        On the generated tables (8 blocks per scene on average, 12 configurations x tables T0 and T3,
        4 directions, k = 2) the mean number knocked off was 0.6 at 8 m/s^2, 3.1 at 11, 6.1 at 15,
        7.2 at 20 and 7.2 at 30, so 22 x 0.4 = 8.8 m/s^2 knocks off about one block and
        76 x 0.4 = 30 m/s^2 nearly all; 1 m/s^2 per unit would knock nearly all off at 22 already.
        The bump report re-checks this on every run. The towers' fitted phi = 0.2 is then
        0.08 m/s^2 for 0.2 s, a 1.6 mm nudge of the floor: "a light tap".
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.stats import circmean

from ..engine import ModelConfig, Prediction, QuerySpec, Scene, SimSettings, predict_many
from ..engine.sampling.estimate import sample_fall_fraction, sample_far_m
from ..engine.scene.generators import generate_towers
from ..engine.sampling.perturb import is_deterministic
from ..engine.results.outcome import SampleOutcome
from ..engine.scene.files import scenes_from_tower_csv
from ..engine.compute.store import ResumableMap
from .reporting import steps

#: Tower blocks' short side in the stimulus files (metres here): the paper's unit for sigma.
SHORT_SIDE_M = 0.2
#: m/s^2 of support acceleration per unit of the paper's phi (see the module docstring).
PHI_M_S2_PER_PAPER_UNIT = 0.4
#: The paper's grids (SI "Inputs"). Its text says phi "could take 12 possible values" and lists 11.
PAPER_SIGMAS = (0.0, 0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.40, 0.45, 0.5)
PAPER_TOWER_PHIS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.5, 2.0, 2.5, 3.0)
PAPER_BUMP_PHIS = (22.0, 25.6, 29.2, 32.8, 36.4, 40.0, 43.6, 47.2, 50.8, 54.4, 58.0, 61.6, 65.2, 68.8, 72.4, 76.0)
PAPER_MUS = (0.25, 1.0, 2.0, 2.5, 3.2, 4.0, 5.0, 6.3, 8.0, 10.0, 13.0, 16.0)
#: The paper's fitted values for Exps. 1-4.
PAPER_SIGMA, PAPER_PHI = 0.2, 0.2


def sigma_m(sides: float) -> float:
    return sides * SHORT_SIDE_M


def phi_m_s2(paper_phi: float) -> float:
    return paper_phi * PHI_M_S2_PER_PAPER_UNIT


@dataclass(frozen=True)
class Stimuli:
    """A named stimulus set and where it came from (the authors' file, or generated towers)."""

    label: str
    source: str
    scenes: tuple[Scene, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.scenes)


def load_tower_stimuli(filename: str, data_dir: Path, limit: int | None = None, *, seed: int = 0,
                       ratio: str | None = None) -> Stimuli:
    """The paper's towers from ``filename``; generated paper-style towers when the file is absent
    (the report says so). ``ratio`` keeps only scenes with that mass ratio (the ``@ratio=`` suffix)."""
    path = data_dir / filename
    if path.exists():
        scenes = scenes_from_tower_csv(path)
        if ratio is not None:
            scenes = [s for s in scenes if s.name.endswith(f"@ratio={ratio}")]
        source = str(path)
    else:
        scenes = generate_towers(seed, limit or 60)
        source = f"generated towers (seed {seed}): {path} is absent"
    if limit is not None:
        scenes = scenes[:limit]
    return Stimuli(label=filename, source=source, scenes=tuple(scenes))


def geometry_key(name: str) -> str:
    """The tower geometry a stimulus name stands for: 'tower_00013_0011001110@ratio=10' -> 'tower_00013'.

    Stimuli that share a geometry (state pairs, mass ratios) share their seed, hence their noise
    draws: their differences are then the masses' alone (common random numbers).
    """
    base = name.split("@", 1)[0]
    parts = base.split("_")
    if len(parts) == 3 and parts[0] == "tower" and set(parts[2]) <= {"0", "1"}:
        return "_".join(parts[:2])
    return base


def stimulus_seed(seed: int, name: str) -> int:
    """A per-stimulus seed from the run's seed and the stimulus's geometry (stable across runs)."""
    key = zlib.crc32(geometry_key(name).encode())
    return int(np.random.SeedSequence([seed, key]).generate_state(1)[0])


def _sample_direction(outcome: SampleOutcome) -> float:
    angles = [r.get("direction_rad") for r in outcome.rollouts if r.get("direction_rad") is not None]
    if not angles:
        return math.nan
    return float(circmean(angles, high=math.pi, low=-math.pi))


def _sample_bump(outcome: SampleOutcome) -> float:
    ratios = [r.get("bump_ratio") for r in outcome.rollouts if r.get("bump_ratio") is not None]
    return float(np.mean(ratios)) if ratios else math.nan


PER_SAMPLE: dict[str, Callable[[SampleOutcome], float]] = {
    "fall": sample_fall_fraction,
    "direction": _sample_direction,
    "far": sample_far_m,
    "bump": _sample_bump,
}


@dataclass(frozen=True)
class ModelRun:
    """One model variant over a stimulus set: a Prediction per stimulus (with its per-sample outcomes)."""

    label: str
    names: tuple[str, ...]
    predictions: tuple[Prediction, ...]

    def per_sample(self, query: str) -> list[np.ndarray]:
        """Per stimulus, the query's value in each good sample (NaN where a sample has none)."""
        value = PER_SAMPLE[query]
        return [np.array([value(o) for o in p.outcomes if o.ok], float) for p in self.predictions]

    def mean(self, query: str) -> np.ndarray:
        """Per stimulus, the model's judgment: the engine's own aggregate (NaN where undefined)."""
        field = {"fall": "fall_fraction", "direction": "direction_rad", "far": "far_m", "bump": "bump_ratio"}[query]
        return np.array([math.nan if getattr(p, field) is None else getattr(p, field) for p in self.predictions])

    @property
    def failed_samples(self) -> int:
        return sum(p.failed_samples for p in self.predictions)

    @property
    def wall_s(self) -> float:
        return sum(p.wall_s for p in self.predictions)


#: Samples handed to the map at once: predictions of several stimuli share one map (a worker never
#: idles at the end of one prediction, a cluster's round trip is paid once per map), and progress is
#: still reported every few stimuli. As many as a resumable run computes per call, so that a resumed
#: map's missing samples also go out together.
SAMPLES_PER_MAP = ResumableMap.DEFAULT_BATCH


def map_batches(stimuli: int, samples_each: int) -> list[range]:
    """Consecutive stimuli grouped so that one map gets about ``SAMPLES_PER_MAP`` samples (at least one
    stimulus per map)."""
    per_map = max(1, SAMPLES_PER_MAP // samples_each)
    return [range(i, min(i + per_map, stimuli)) for i in range(0, stimuli, per_map)]


def run_model(label: str, scenes, model: ModelConfig, settings: SimSettings, query: QuerySpec, seed: int,
              map_fn=None) -> ModelRun:
    """Predict every scene with its own stimulus seed (see ``stimulus_seed``)."""
    scenes = list(scenes)
    per_scene = max((1 if is_deterministic(s, model) else model.samples for s in scenes), default=1)
    batches = map_batches(len(scenes), per_scene)
    predictions = []
    for part in steps(batches, f"{label} ({len(scenes)} stimuli, {len(batches[0]) if batches else 0} per batch)",
                      every=1):
        predictions += predict_many([(scenes[i], model, stimulus_seed(seed, scenes[i].name)) for i in part],
                                    settings, query, map_fn)
    return ModelRun(label=label, names=tuple(s.name for s in scenes), predictions=tuple(predictions))
