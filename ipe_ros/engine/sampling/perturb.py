"""The IPE's input distributions (paper SI "Inputs"): pure functions of (scene, config, rng).

The draw order is fixed (horizontal position noise first, then the push direction; then vertical and
yaw noise, only when some body asks for them), and the first two are always drawn, so a sample's noisy
scene depends on its seed and the noise SDs only: never on phi, the preset, or which queries were
asked. Each body's noise is the model's sigma unless the body gives its own (``position_sigma_m``,
``yaw_sigma_rad``: 0 for a body known exactly, such as one the robot holds). Uncertain masses,
frictions and restitutions (a scene's priors, the model's ``property_spread``) and the launches of what
moves at t = 0 (the model's ``launch_spread``) are drawn from streams of their own
(``scene.properties.draw_uncertain``, ``scene.launches``), so turning them on leaves every other draw as it was.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..config import MODEL_LIGHT_DENSITY_KG_M3, ModelConfig
from ..scene.bodies import Scene
from ..scene.launches import launched, with_drawn_launches
from ..scene.properties import draw_uncertain, uncertain_properties, with_properties, without_priors
from ..scene.shapes import quaternion_product


@dataclass(frozen=True)
class SampleInputs:
    """One Monte Carlo draw of the model's inputs.

    Attributes:
        positions_m: (n_dynamic, 3) noisy centres of mass of the dynamic bodies (before depenetration).
        orientations_xyzw: (n_dynamic, 4) their orientations (turned by the yaw noise, if any).
        masses_kg: (n_dynamic,) masses after the mass ratio mu.
        push_direction_rad: direction of the support's acceleration in the scene's xy plane.
        properties: the uncertain properties' drawn values, ("owner.property", value) in
            ``sample_properties``' order (a mass in kg before mu; under mu its body's mass is scaled alike).
    """

    positions_m: np.ndarray
    orientations_xyzw: np.ndarray
    masses_kg: np.ndarray
    push_direction_rad: float
    properties: tuple[tuple[str, float], ...] = ()


def dynamic_masses(scene: Scene, mu: float | None) -> np.ndarray:
    """Masses (kg) of the dynamic bodies under the model's heavy/light density ratio ``mu``.

    With ``mu`` None the scene's own masses are kept. Otherwise the model ignores the scene's masses:
    light bodies get MODEL_LIGHT_DENSITY_KG_M3 and "heavy" ones ``mu`` times that, so two scenes that
    differ only in which bodies are heavy get exactly the same masses under mu = 1.
    """
    bodies = scene.dynamic_objects
    if mu is None:
        return np.array([b.resolved_mass_kg for b in bodies], dtype=float)
    return np.array([MODEL_LIGHT_DENSITY_KG_M3 * b.volume_m3 * (mu if b.is_heavy else 1.0) for b in bodies])


def position_sigmas_m(scene: Scene, model: ModelConfig) -> np.ndarray:
    """(n_dynamic, 3) position noise SDs: each body's own (unless ``model.object_noise`` is off),
    else the model's sigma horizontally."""
    out = np.zeros((len(scene.dynamic_objects), 3))
    for i, body in enumerate(scene.dynamic_objects):
        own = body.position_sigma_m if model.object_noise else None
        if own is None:
            out[i, :2] = model.sigma_m
        elif isinstance(own, (tuple, list)):
            out[i] = own
        else:
            out[i, :2] = own
    return out


def yaw_sigmas_rad(scene: Scene, model: ModelConfig) -> np.ndarray:
    """(n_dynamic,) yaw noise SDs: each body's own (none when ``model.object_noise`` is off)."""
    return np.array([(b.yaw_sigma_rad or 0.0) if model.object_noise else 0.0 for b in scene.dynamic_objects])


def is_deterministic(scene: Scene, model: ModelConfig) -> bool:
    """No noise at all for this scene: neither the model's (sigma = phi = 0, no vision) nor any body's
    own. One rollout then says everything; with a body's own noise and sigma = 0 it does not."""
    return model.is_deterministic and not position_sigmas_m(scene, model).any() and \
        not yaw_sigmas_rad(scene, model).any() and not sample_properties(scene, model) and \
        not launched(scene, model.launch_spread)


def sample_properties(scene: Scene, model: ModelConfig) -> tuple:
    """The properties each sample draws: (owner, property, prior), the scene's priors (unless
    ``model.object_noise`` is off: the ground truth takes the scene as given) and the model's spread."""
    if not model.object_noise:
        return () if model.property_spread is None else uncertain_properties(without_priors(scene), model.property_spread)
    return uncertain_properties(scene, model.property_spread)


def _yaw_quaternions(yaw_rad: np.ndarray) -> np.ndarray:
    """xyzw quaternions of turns by ``yaw_rad`` about +z."""
    return Rotation.from_rotvec(np.outer(yaw_rad, (0.0, 0.0, 1.0))).as_quat()


def draw_push_direction(model: ModelConfig, rng: np.random.Generator) -> float:
    """Uniform over the circle, or within +-cue_half_width of the cued direction."""
    u = rng.random()
    if model.force_direction_rad is None:
        return 2 * math.pi * u
    return model.force_direction_rad + (2 * u - 1) * model.cue_half_width_rad


def draw_sample_inputs(scene: Scene, model: ModelConfig, rng: np.random.Generator) -> SampleInputs:
    """Draw one sample: horizontal N(0, sigma) noise on every dynamic body, then a push direction,
    then vertical and yaw noise where bodies ask for them."""
    bodies = scene.dynamic_objects
    positions = np.array([b.centre_of_mass_m for b in bodies], dtype=float)
    orientations = np.array([b.orientation_xyzw for b in bodies], dtype=float)
    sigmas = position_sigmas_m(scene, model)
    noise = rng.standard_normal((len(bodies), 2))
    positions[:, :2] += sigmas[:, :2] * noise
    direction = draw_push_direction(model, rng)
    if sigmas[:, 2].any():
        positions[:, 2] += sigmas[:, 2] * rng.standard_normal(len(bodies))
    yaw_sigmas = yaw_sigmas_rad(scene, model)
    if yaw_sigmas.any():  # about each body's centre of mass
        turn = _yaw_quaternions(yaw_sigmas * rng.standard_normal(len(bodies)))
        orientations = quaternion_product(turn, orientations)
    return SampleInputs(positions_m=positions, orientations_xyzw=orientations,
                        masses_kg=dynamic_masses(scene, model.mu), push_direction_rad=float(direction))


def draw_sample(scene: Scene, model: ModelConfig, seed: np.random.SeedSequence) -> tuple[Scene, SampleInputs]:
    """One sample's scene and inputs from its ``seed``: ``draw_sample_inputs`` on the sample's main
    stream, then ``with_drawn_properties`` (the launches and properties, each on a stream of its own)."""
    return with_drawn_properties(scene, model, seed, draw_sample_inputs(scene, model, np.random.default_rng(seed)))


def with_drawn_properties(scene: Scene, model: ModelConfig, seed: np.random.SeedSequence, inputs: SampleInputs,
                          owners: frozenset[str] | None = None) -> tuple[Scene, SampleInputs]:
    """The scene and inputs with each launch (``scene.launches``) and each uncertain property's value
    drawn from its own stream of ``seed`` (``draw_uncertain``): launches, frictions and restitutions in
    the scene, masses in the inputs (a drawn mass over the scene's scales the body's mass, so under mu
    the model's mass is scaled alike).
    ``owners``: only these objects' (None: every object's and the support's)."""
    scene, launches = with_drawn_launches(scene, model.launch_spread, seed, owners)
    if launches:
        inputs = dataclasses.replace(inputs, properties=inputs.properties + launches)
    uncertain = tuple(u for u in sample_properties(scene, model) if owners is None or u[0] in owners)
    if not uncertain:
        return scene, inputs
    values = draw_uncertain(uncertain, seed)
    drawn = {(owner, prop): value for (owner, prop, _), value in zip(uncertain, values)}
    masses = inputs.masses_kg.copy()
    for i, body in enumerate(scene.dynamic_objects):
        mass = drawn.pop((body.name, "mass_kg"), None)
        if mass is not None:
            masses[i] *= mass / body.resolved_mass_kg
    named = tuple((f"{owner}.{prop}", value) for (owner, prop, _), value in zip(uncertain, values))
    return with_properties(scene, drawn), dataclasses.replace(inputs, masses_kg=masses, properties=named + inputs.properties)
