"""Each action checked against the scene before anything is simulated: the objects it names exist
and may be moved, a placed body fits the scene's rules, a push is horizontal, lands on the object
and gives it no more spin than a scene may start with (pybullet's own inertia, as the rollout uses);
and which variants the validated envelope covers (``validated_variants``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..checking.envelope import validated_for_all
from ..checking.fidelity import SelfCheck
from ..config import ModelConfig, SimSettings
from ..scene import limits
from ..errors import ConfigError
from ..scene.bodies import Scene
from ..scene.validation import validate_scene
from .geometry import geometry_world
from .kinds import Action, Place, Push, Remove, applied
from .variants import push_velocities


def check_action(scene: Scene, action: Action, path: str) -> None:
    names = {b.name for b in scene.objects}
    if isinstance(action, Remove):
        if not action.names:
            raise ConfigError(f"{path}.names", "name at least one object to remove")
        for name in action.names:
            if name not in names:
                raise ConfigError(f"{path}.names", f"no object named {name!r} in {scene.name!r}")
            if next(b for b in scene.objects if b.name == name).static:
                raise ConfigError(f"{path}.names", f"{name!r} is static (fixed geometry) and cannot be removed")
        if not [b for b in scene.dynamic_objects if b.name not in action.names]:
            raise ConfigError(f"{path}.names", "removing these leaves nothing that could fall")
    elif isinstance(action, Place):
        if action.body.name in names:
            raise ConfigError(f"{path}.body.name", f"{action.body.name!r} is already in the scene; give the new object "
                                                   "a name of its own")
        if action.body.static:
            raise ConfigError(f"{path}.body.static", "a placed object must be dynamic")
        validate_scene(dataclasses.replace(scene, objects=scene.objects + (action.body,)))
    elif isinstance(action, Push):
        if action.name not in {b.name for b in scene.dynamic_objects}:
            raise ConfigError(f"{path}.name", f"no dynamic object named {action.name!r} in {scene.name!r}")
        v = np.asarray(action.velocity_m_s, float)
        if v.shape != (3,) or not np.all(np.isfinite(v)) or abs(v[2]) > 0 or not np.any(v):
            raise ConfigError(f"{path}.velocity_m_s", f"must be a finite horizontal velocity (vz = 0), not zero, "
                                                      f"got {list(action.velocity_m_s)}")
        if np.linalg.norm(v) > 100:
            raise ConfigError(f"{path}.velocity_m_s", "a push faster than 100 m/s is a projectile, not a push")
        if action.point_m is not None:
            _check_push_point(scene, action, f"{path}.point_m")
        if not (0 <= action.direction_sigma_rad <= math.pi) or not (0 <= action.speed_sigma_fraction <= 1):
            raise ConfigError(f"{path}", "direction_sigma_rad must be in [0, pi] and speed_sigma_fraction in [0, 1]")
    elif action is not None:
        raise ConfigError(path, f"not an action: {type(action).__name__}")


def _check_push_point(scene: Scene, push: Push, path: str) -> None:
    """The point pushed lies on the object (within its bounding sphere, 1 mm of slack), and the spin
    the push implies there stays within what a scene may start with (limits.MAX_SPIN_RAD_S)."""
    point = np.asarray(push.point_m, float)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ConfigError(path, "must be 3 finite numbers (metres, scene frame) or null")
    i, body = next((i, b) for i, b in enumerate(scene.dynamic_objects) if b.name == push.name)
    centre = np.asarray(body.centre_of_mass_m, float)
    reach = 0.5 * float(np.linalg.norm(body.extents_m)) + 1e-3
    distance = float(np.linalg.norm(point - centre))
    if distance > reach:
        raise ConfigError(path, f"{list(push.point_m)} is {distance:.3g} m from the centre of mass of {push.name!r}, "
                                f"outside its reach of {reach:.3g} m; push a point on the object")
    inertia = geometry_world(scene).inertia_kg_m2[i]  # pybullet's own, as the rollout will use
    _, spin = push_velocities(push, np.random.default_rng(0), centre, np.asarray(body.orientation_xyzw, float),
                               inertia, body.resolved_mass_kg)
    worst = float(np.linalg.norm(spin)) * (1 + push.speed_sigma_fraction * 4)  # the push's own noise, to 4 SD
    if worst > limits.MAX_SPIN_RAD_S:
        raise ConfigError(path, f"pushed there at this speed {push.name!r} would spin at up to {worst:.4g} rad/s, more "
                                f"than the {limits.MAX_SPIN_RAD_S:g} rad/s a scene may start with; push nearer its "
                                "centre of mass or slower")


def validated_variants(scenes: list[Scene], actions: list[Action], model: ModelConfig, settings: SimSettings,
                       check: SelfCheck | None) -> list[str]:
    """Per simulated variant, why it needs no verification, or "": every scene its samples start from
    (the scene, or each perceived one), with the action applied (``kinds.applied``), lies inside the
    validated envelope (``checking.envelope``), as a prediction's scene would. A block placed on a
    standing tower, lowered onto it, or the top block taken off it, leaves boxes at rest; a removal
    that leaves a block hanging, or a push, does not. A sequential question is judged by the k it
    asks, as a prediction at a fixed k: its decisions read intervals over the samples drawn, and the
    fast physics' bias on such a scene is what the envelope's evidence rules out."""
    if check is None or not check.enabled or check.always_verify:
        return [""] * len(actions)
    starts = list({id(s): s for s in scenes}.values())  # a posterior's scenes, each once
    return [validated_for_all([applied(s, action) for s in starts], model, settings) for action in actions]
