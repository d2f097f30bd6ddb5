"""Where the fast physics was validated: scenes inside this envelope skip the reference reruns.

The self-check reruns samples at the converged reference on every answer, and on the scenes `default`
was tuned for that buys nothing measurable: on the authors' 60 towers, unchecked `default` is 11.8x
`paper` at mean |dFF| 0.013, self-checked 6.8x at 0.012, per-sample agreement 99.3% either way
(benchmarks/README). A robot pays the check on every answer, so where the evidence says it cannot
change the answer, it is not run: a scene inside the envelope answers ``fidelity: "validated"``
(saying why in ``self_check.validated``), its unhealthy rollouts still refined and a refinement that
moves an outcome still confirmed and escalated as on any scene.

The envelope is the hull of what was measured and no more: a fixed k of at least 16 noisy samples
(the answer an average, not one rollout; anytime sampling may stop after a few, and is checked), boxes at rest on a floor, none thin, bouncy (any restitution) or slippery, masses within
10x and none more than 3x as heavy as a box that carries it, no push, the `default` preset. The zoo's ``stacks`` family
draws its scenes over exactly these ranges, and `default` unchecked meets the zoo's bars there
(benchmarks/zoo.py); outside them (a ball, a thrown box, thin plates, a bouncy floor, a table's edge,
a push) every answer is checked as before. ``SelfCheck(always_verify=True)`` (the CLI's
``--always-verify``, the node's ``always_verify``) checks inside it too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import PRESETS, ModelConfig, SimSettings
from ..sampling.perturb import dynamic_masses, is_deterministic, sample_properties
from ..scene.bodies import Floor, Scene, box_corners
from ..scene.shapes import BoxShape, rotation_matrix


@dataclass(frozen=True)
class Envelope:
    """The ranges the fast preset was validated over (each inclusive)."""

    preset: str = "default"
    #: the fewest samples: the envelope was validated on averages over samples (chaos flips a sample
    #: now and then either way); one sample is a whole answer, and the ground truth's one rollout of a
    #: tower balanced to 1.5% of a block toppled at `default` and stood at the reference
    min_samples: int = 16
    max_objects: int = 12
    min_extent_m: float = 0.02
    max_extent_m: float = 1.0
    max_aspect: float = 3.0  # longest / shortest side of each box: the authors' blocks are 3:1
    #: none: the authors' towers have none, and on 3-6 cm boxes a restitution of 0.06 made `default`
    #: topple a heavy box off a light one in 14 of 16 samples where `paper` never did (zoo stacks 2026/35;
    #: the same boxes at 0, or 4x larger, agree)
    max_restitution: float = 0.0
    min_friction: float = 0.4
    max_friction: float = 1.0
    #: heaviest / lightest dynamic box, under the model's mu (a light box on a heavy stack, a heavy
    #: stack beside a light one; benchmarks/results/zoo_stacks/carried.md)
    max_mass_ratio: float = 10.0
    #: a box over any box that carries it (directly or through others), under the model's mu: where
    #: a stack collapses, the collapse steps knock a light box out from under heavier ones more
    #: often than `paper` does (zoo stacks 2026/0, a 29 g box under 108-216 g ones: 0.34-0.41 more
    #: often at 7.5x, 0.13-0.38 at 4.8x, 0.13-0.22 at 2-3x, as chaos does at 1x;
    #: benchmarks/results/zoo_stacks/mass_ratio.md)
    max_carried_ratio: float = 3.0
    max_sigma_fraction: float = 0.25  # horizontal position noise, of the smallest box side
    max_tilt_rad: float = 0.05  # each box lies on a face: one of its axes this close to vertical
    #: each box rests: its lowest point this close (of its smallest side, beyond the scene's set_down_m)
    #: to the floor or to the top of a box under it, not dropped or hanging
    rest_gap_fraction: float = 0.05
    max_horizon_s: float = 2.0
    gravity_m_s2: float = 9.81
    gravity_tolerance: float = 0.01  # of the magnitude; horizontal parts 0


VALIDATED = Envelope()


def outside(scene: Scene, model: ModelConfig, settings: SimSettings, envelope: Envelope = VALIDATED) -> str | None:
    """None when the prediction lies inside ``envelope``, else the first reason it does not."""
    if settings != PRESETS[envelope.preset]:
        return f"the preset is not {envelope.preset}"
    if model.samples < envelope.min_samples or is_deterministic(scene, model):
        return f"fewer than {envelope.min_samples} noisy samples"
    if settings.horizon_for(scene.horizon_s) > envelope.max_horizon_s:
        return "the horizon is longer than validated"
    support = scene.support
    if not isinstance(support, Floor):
        return "the support is not a floor"
    if scene.static_objects:
        return "the scene has static objects"
    gx, gy, gz = scene.gravity_m_s2
    if gx or gy or abs(-gz - envelope.gravity_m_s2) > envelope.gravity_tolerance * envelope.gravity_m_s2:
        return "gravity is not the validated one"
    if model.pushes:
        return "the model pushes the support"
    if sample_properties(scene, model):  # drawn values may lie outside the ranges below
        return "masses, frictions or restitutions are uncertain"
    bodies = scene.dynamic_objects
    if len(bodies) > envelope.max_objects:
        return f"more than {envelope.max_objects} objects"
    frictions = [support.friction]
    restitutions = [support.restitution]
    for body in bodies:
        if not isinstance(body.shape, BoxShape):
            return f"{body.name} is not a box"
        extents = body.shape.extents_m
        if min(extents) < envelope.min_extent_m or max(extents) > envelope.max_extent_m:
            return f"{body.name}'s size is outside the validated range"
        if max(extents) > envelope.max_aspect * min(extents) * (1 + 1e-6):  # the authors' 3:1, in single precision
            return f"{body.name} is thinner than validated"
        if any(body.linear_velocity_m_s) or any(body.angular_velocity_rad_s):
            return f"{body.name} is moving"
        sigma = np.atleast_1d(body.position_sigma_m if body.position_sigma_m is not None else model.sigma_m)
        if sigma.max() > envelope.max_sigma_fraction * min(extents) or (len(sigma) == 3 and sigma[2] > 0):
            return f"{body.name}'s position noise is larger than validated"
        if np.abs(rotation_matrix(body.orientation_xyzw)[2]).max() < math.cos(envelope.max_tilt_rad):
            return f"{body.name} does not lie on a face"
        frictions.append(body.friction)
        restitutions.append(body.restitution)
    if not envelope.min_friction <= min(frictions) <= max(frictions) <= envelope.max_friction:
        return "a friction is outside the validated range"
    if max(restitutions) > envelope.max_restitution:
        return "a restitution is above the validated range"
    supports = _resting_on(scene, envelope)
    if isinstance(supports, str):
        return f"{supports} is not resting on the floor or a box"
    masses = dynamic_masses(scene, model.mu)
    if not math.isfinite(masses.max() / masses.min()) or masses.max() > envelope.max_mass_ratio * masses.min() * (1 + 1e-9):
        return f"masses differ by more than {envelope.max_mass_ratio:g}x"
    for upper, lower in _carried(supports):
        if masses[upper] > envelope.max_carried_ratio * masses[lower] * (1 + 1e-9):
            return (f"{bodies[upper].name} is more than {envelope.max_carried_ratio:g}x as heavy as "
                    f"{bodies[lower].name}, which carries it")
    return None


def _resting_on(scene: Scene, envelope: Envelope) -> list[tuple[int, int]] | str:
    """Which box rests on which, as (upper, lower) indices into ``scene.dynamic_objects``: a box's
    lowest point on the top of a box whose footprint (bounding rectangle) meets its own, within the
    rest gap. The name of the first box that rests neither on the floor nor on a box, if any."""
    bodies = scene.dynamic_objects
    corners = [box_corners(b.shape.extents_m, b.position_m, b.orientation_xyzw) for b in bodies]
    pairs = []
    for i, (body, mine) in enumerate(zip(bodies, corners)):
        gap = envelope.rest_gap_fraction * min(body.shape.extents_m) + scene.set_down_m
        low = mine[:, 2].min()
        if abs(low - scene.support.height_m) <= gap:
            continue
        under = [j for j, c in enumerate(corners) if j != i
                 and abs(low - c[:, 2].max()) <= gap
                 and (c[:, :2].min(axis=0) <= mine[:, :2].max(axis=0)).all()
                 and (mine[:, :2].min(axis=0) <= c[:, :2].max(axis=0)).all()]
        if not under:
            return body.name
        pairs += [(i, j) for j in under]
    return pairs


def _carried(resting_on: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Every (upper, lower) pair of boxes where ``lower`` carries ``upper``, directly or through the
    boxes between them: a box under a stack meets every box of it when the stack comes down."""
    pairs = set(resting_on)
    while True:
        more = {(upper, lowest) for upper, middle in pairs for m, lowest in pairs if m == middle} - pairs
        if not more:
            return sorted(pairs)
        pairs |= more


def validated_because(scene: Scene, model: ModelConfig, settings: SimSettings) -> str | None:
    """What an answer inside the envelope says in ``self_check.validated`` (None: outside it)."""
    if outside(scene, model, settings) is not None:
        return None
    return (f"boxes at rest on a floor within the envelope `{settings.name}` was validated over against the "
            "reference (docs/model.md, 'Self-checking answers'): not rerun at the reference; unhealthy rollouts "
            "refined")


def validated_for_all(scenes, model: ModelConfig, settings: SimSettings) -> str:
    """``validated_because`` when every scene an answer's samples start from (each distinct one once)
    lies inside the envelope; "" when one does not, or none is given."""
    reason = ""
    for scene in {id(s): s for s in scenes}.values():
        why = validated_because(scene, model, settings)
        if why is None:
            return ""
        reason = why
    return reason
