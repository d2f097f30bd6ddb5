"""The IPE's input distributions (paper SI "Inputs"): pure functions of (scene, config, rng).

The draw order is fixed (position noise first, then the push direction), and both are always drawn,
so a sample's noisy scene depends on its seed and sigma only: never on phi, the preset, or which
queries were asked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import MODEL_LIGHT_DENSITY_KG_M3, ModelConfig
from .scene import Scene


@dataclass(frozen=True)
class SampleInputs:
    """One Monte Carlo draw of the model's inputs.

    Attributes:
        positions_m: (n_dynamic, 3) noisy centres of the dynamic boxes (before depenetration).
        masses_kg: (n_dynamic,) masses after the mass ratio mu.
        push_direction_rad: direction of the support's acceleration in the scene's xy plane.
    """

    positions_m: np.ndarray
    masses_kg: np.ndarray
    push_direction_rad: float


def dynamic_masses(scene: Scene, mu: float | None) -> np.ndarray:
    """Masses (kg) of the dynamic boxes under the model's heavy/light density ratio ``mu``.

    With ``mu`` None the scene's own masses are kept. Otherwise the model ignores the scene's masses:
    light boxes get MODEL_LIGHT_DENSITY_KG_M3 and "heavy" ones ``mu`` times that, so two scenes that
    differ only in which boxes are heavy get exactly the same masses under mu = 1.
    """
    boxes = scene.dynamic_boxes
    if mu is None:
        return np.array([b.resolved_mass_kg for b in boxes], dtype=float)
    return np.array([MODEL_LIGHT_DENSITY_KG_M3 * b.volume_m3 * (mu if b.is_heavy else 1.0) for b in boxes])


def draw_push_direction(model: ModelConfig, rng: np.random.Generator) -> float:
    """Uniform over the circle, or within +-cue_half_width of the cued direction."""
    u = rng.random()
    if model.force_direction_rad is None:
        return 2 * math.pi * u
    return model.force_direction_rad + (2 * u - 1) * model.cue_half_width_rad


def draw_sample_inputs(scene: Scene, model: ModelConfig, rng: np.random.Generator) -> SampleInputs:
    """Draw one sample: horizontal N(0, sigma) noise on every dynamic box, then a push direction."""
    boxes = scene.dynamic_boxes
    positions = np.array([b.position_m for b in boxes], dtype=float)
    noise = rng.standard_normal((len(boxes), 2))
    positions[:, :2] += model.sigma_m * noise
    direction = draw_push_direction(model, rng)
    return SampleInputs(positions_m=positions, masses_kg=dynamic_masses(scene, model.mu),
                        push_direction_rad=float(direction))
