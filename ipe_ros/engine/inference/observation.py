"""``ipe_ros.observation/1``: what a tracker saw of a scene in motion, and what is unknown in it.

Read once, where it enters the engine (``observation_from_json``); every refusal is one line naming
the field (``ConfigError``/``SceneError``), as the scene reader's are. docs/inference.md spells it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ConfigError, SceneError, shown
from ..scene.bodies import QUATERNION_NORM_TOLERANCE, Scene
from ..scene.format import scene_from_dict
from ..scene.limits import MAX_JSON_CHARS, MAX_SPEED_M_S
from ..scene.properties import PROPERTIES, Prior, prior_from_dict

OBSERVATION_FORMAT = "ipe_ros.observation/1"
#: an inference simulates the whole window for every candidate: its cost grows with it
MAX_WINDOW_S = 10.0
MAX_FRAMES = 10_000
MAX_UNKNOWNS = 8
SUPPORT = "support"
_KEYS = {"format", "scene", "position_sd_m", "yaw_sd_rad", "frames", "unknowns", "actions"}
_REQUIRED = {"format", "scene", "position_sd_m", "frames", "unknowns"}


@dataclass(frozen=True)
class ObservedPose:
    """An object's pose in one frame; ``orientation_xyzw`` None where the tracker gave none (a ball)."""

    position_m: tuple[float, float, float]
    orientation_xyzw: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class Frame:
    t_s: float
    poses: tuple[tuple[str, ObservedPose], ...]  # (object name, pose); an occluded object is left out


@dataclass(frozen=True)
class Unknown:
    """One surface's (or mass's) value, for an object or for every dynamic object of a group."""

    property: str
    prior: Prior
    object: str | None = None
    group: str | None = None

    @property
    def label(self) -> str:
        return f"{self.object}.{self.property}" if self.object is not None else f"group:{self.group}.{self.property}"

    def applies_to(self, scene: Scene) -> tuple[str, ...]:
        """The names of the bodies (or "support") whose value this is."""
        if self.object is not None:
            return (self.object,)
        return tuple(b.name for b in scene.dynamic_objects if b.group == self.group)


@dataclass(frozen=True)
class Push:
    """The robot's push on ``object`` at ``at_s``: an impulse (its mass then shows) or a velocity change."""

    object: str
    impulse_N_s: tuple[float, float] | None = None  # noqa: N815 - the unit's spelling
    velocity_m_s: tuple[float, float] | None = None
    at_s: float = 0.0


@dataclass(frozen=True)
class Observation:
    """The scene at t = 0 (exact poses), the frames after it, the unknowns and the robot's pushes.

    ``unknown_velocity``: the dynamic objects whose initial velocity the scene left out (estimated
    from the frames, a nuisance the answer integrates over)."""

    scene: Scene
    frames: tuple[Frame, ...]
    position_sd_m: float
    yaw_sd_rad: float | None
    unknowns: tuple[Unknown, ...]
    actions: tuple[Push, ...] = ()
    unknown_velocity: tuple[str, ...] = ()

    @property
    def window_s(self) -> float:
        return self.frames[-1].t_s

    def track(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (m,), positions (m, 3), orientations (m, 4): NaN rows where a frame gave none) of
        the frames that saw ``name``."""
        times, positions, orientations = [], [], []
        for frame in self.frames:
            for seen, pose in frame.poses:
                if seen == name:
                    times.append(frame.t_s)
                    positions.append(pose.position_m)
                    orientations.append((math.nan,) * 4 if pose.orientation_xyzw is None else pose.orientation_xyzw)
        return (np.array(times, float), np.array(positions, float).reshape(-1, 3),
                np.array(orientations, float).reshape(-1, 4))


def observation_from_json(text: str) -> Observation:
    return observation_from_dict(parsed_json(text))


def parsed_json(text: str) -> Any:
    """The JSON value of ``text``, refused in one line when too long, malformed or holding NaN."""
    if len(text) > MAX_JSON_CHARS:
        raise ConfigError("observation", f"{len(text)} characters exceed the maximum of {MAX_JSON_CHARS}; "
                                         "send fewer frames")
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise ConfigError("observation", f"malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise ConfigError("observation", "nested too deeply to read") from None
    return data


def _reject_constant(token: str) -> None:
    raise ConfigError("observation", f"{token} is not a valid number; use finite numbers only")


def observation_from_dict(data: Any) -> Observation:
    if not isinstance(data, dict):
        raise ConfigError("observation", f"must be a JSON object, got {shown(data)}")
    if data.get("format") != OBSERVATION_FORMAT:
        raise ConfigError("format", f"must be {OBSERVATION_FORMAT!r}, got {shown(data.get('format'))}")
    missing, extra = sorted(_REQUIRED - set(data)), sorted(set(data) - _KEYS)
    if missing:
        raise ConfigError(missing[0], "required field missing")
    if extra:
        raise ConfigError(extra[0], f"unknown field; an observation has {', '.join(sorted(_KEYS))}")
    try:
        scene = scene_from_dict(data["scene"])
    except SceneError as exc:
        raise SceneError(f"scene.{exc.field}", exc.problem) from None
    position_sd = _number(data["position_sd_m"], "position_sd_m", 0.0, 1.0, above=True)
    yaw_sd = data.get("yaw_sd_rad")
    yaw_sd = None if yaw_sd is None else _number(yaw_sd, "yaw_sd_rad", 0.0, math.pi, above=True)
    dynamic = {b.name for b in scene.dynamic_objects}
    frames = _frames(data["frames"], dynamic)
    unknowns = _unknowns(data["unknowns"], scene, dynamic)
    actions = _actions(data.get("actions", []), dynamic, frames[-1].t_s)
    objects = data["scene"].get("objects", data["scene"].get("boxes", []))
    left_out = tuple(o["name"] for o in objects if not o.get("static", False) and "linear_velocity_m_s" not in o)
    for name in left_out:
        if len(_times_seen(frames, name)) < 2:
            raise ConfigError("scene.objects", f"{name!r} has no initial velocity and fewer than 2 frames see it; "
                                               "give its linear_velocity_m_s (0 for at rest) or frames of it")
    return Observation(scene, frames, position_sd, yaw_sd, unknowns, actions, left_out)


def _times_seen(frames, name) -> list[float]:
    return [f.t_s for f in frames if any(seen == name for seen, _ in f.poses)]


def _number(value, field, lo, hi, *, above=False) -> float:
    ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
    if not ok or value > hi or value < lo or (above and value == lo):
        raise ConfigError(field, f"must be a number in {'(' if above else '['}{lo:g}, {hi:g}], got {shown(value)}")
    return float(value)


def _vector(value, n, field) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n or not all(
            not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v) for v in value):
        raise ConfigError(field, f"must be {n} finite numbers, got {shown(value)}")
    return tuple(float(v) for v in value)


def _frames(items, dynamic: set[str]) -> tuple[Frame, ...]:
    if not isinstance(items, list) or not items:
        raise ConfigError("frames", "must be a non-empty list of {\"t_s\": ..., \"objects\": {...}}")
    if len(items) > MAX_FRAMES:
        raise ConfigError("frames", f"{len(items)} frames exceed the maximum of {MAX_FRAMES}; send every n-th frame")
    frames, last = [], 0.0
    for i, item in enumerate(items):
        path = f"frames[{i}]"
        if not isinstance(item, dict) or set(item) != {"t_s", "objects"}:
            raise ConfigError(path, f"must be {{\"t_s\": SECONDS, \"objects\": {{NAME: POSE}}}}, got {shown(item)}")
        t = _number(item["t_s"], f"{path}.t_s", 0.0, MAX_WINDOW_S, above=True)
        if t <= last:
            raise ConfigError(f"{path}.t_s", f"frames must be in time order after t = 0: {t:g} s follows {last:g} s")
        last = t
        seen = item["objects"]
        if not isinstance(seen, dict):
            raise ConfigError(f"{path}.objects", f"must map object names to poses, got {shown(seen)}")
        poses = []
        for name, pose in seen.items():
            at = f"{path}.objects.{name}"
            if name not in dynamic:
                raise ConfigError(at, f"no dynamic object {name!r} in the scene")
            if not isinstance(pose, dict) or "position_m" not in pose or set(pose) - {"position_m", "orientation_xyzw"}:
                raise ConfigError(at, "must be {\"position_m\": [X, Y, Z]} with an optional \"orientation_xyzw\"")
            orientation = pose.get("orientation_xyzw")
            if orientation is not None:
                orientation = _vector(orientation, 4, f"{at}.orientation_xyzw")
                if abs(math.sqrt(sum(v * v for v in orientation)) - 1) > QUATERNION_NORM_TOLERANCE:
                    raise ConfigError(f"{at}.orientation_xyzw", "must be a unit quaternion (x, y, z, w)")
            poses.append((name, ObservedPose(_vector(pose["position_m"], 3, f"{at}.position_m"), orientation)))
        frames.append(Frame(t, tuple(poses)))
    return tuple(frames)


def _unknowns(items, scene: Scene, dynamic: set[str]) -> tuple[Unknown, ...]:
    if not isinstance(items, list) or not items:
        raise ConfigError("unknowns", "must name at least one unknown property")
    if len(items) > MAX_UNKNOWNS:
        raise ConfigError("unknowns", f"{len(items)} unknowns exceed the maximum of {MAX_UNKNOWNS}")
    groups = {b.group for b in scene.dynamic_objects if b.group}
    values = {b.name: b for b in scene.dynamic_objects}
    out, covered = [], {}
    for i, item in enumerate(items):
        path = f"unknowns[{i}]"
        if not isinstance(item, dict) or set(item) - {"object", "group", "property", "prior"} \
                or ("object" in item) == ("group" in item) or not {"property", "prior"} <= set(item):
            raise ConfigError(path, "must be {\"object\" or \"group\": NAME, \"property\": ..., \"prior\": {...}}")
        prop = item["property"]
        if prop not in PROPERTIES:
            raise ConfigError(f"{path}.property", f"unknown property {shown(prop)}; choose from {', '.join(PROPERTIES)}")
        name, group = item.get("object"), item.get("group")
        if name is not None and name != SUPPORT and name not in dynamic:
            raise ConfigError(f"{path}.object", f"no dynamic object {shown(name)} in the scene (or \"support\")")
        if name == SUPPORT and prop == "mass_kg":
            raise ConfigError(f"{path}.property", "the support has no mass; its friction or restitution may be unknown")
        if group is not None and group not in groups:
            raise ConfigError(f"{path}.group", f"no dynamic object has group {shown(group)}")
        given = None
        if name in values:
            given = getattr(values[name], prop) if prop != "mass_kg" else values[name].resolved_mass_kg
        elif name == SUPPORT:
            given = getattr(scene.support, prop)
        else:
            first = next(b for b in scene.dynamic_objects if b.group == group)
            given = getattr(first, prop) if prop != "mass_kg" else first.resolved_mass_kg
        unknown = Unknown(prop, prior_from_dict(item["prior"], f"{path}.prior", prop, given), name, group)
        for body in unknown.applies_to(scene):
            if (body, prop) in covered:
                raise ConfigError(path, f"{body}'s {prop} is already unknown in unknowns[{covered[body, prop]}]")
            covered[body, prop] = i
        out.append(unknown)
    return tuple(out)


def _actions(items, dynamic: set[str], window_s: float) -> tuple[Push, ...]:
    if not isinstance(items, list):
        raise ConfigError("actions", "must be a list of pushes")
    out = []
    for i, item in enumerate(items):
        path = f"actions[{i}]"
        if not isinstance(item, dict) or item.get("kind") != "push":
            raise ConfigError(f"{path}.kind", "must be \"push\"")
        if set(item) - {"kind", "object", "at_s", "impulse_N_s", "velocity_m_s"} \
                or ("impulse_N_s" in item) == ("velocity_m_s" in item):
            raise ConfigError(path, "a push has \"object\", \"at_s\" and one of \"impulse_N_s\" or \"velocity_m_s\"")
        if item.get("object") not in dynamic:
            raise ConfigError(f"{path}.object", f"no dynamic object {shown(item.get('object'))} in the scene")
        at = _number(item.get("at_s", 0.0), f"{path}.at_s", 0.0, window_s)
        impulse, velocity = item.get("impulse_N_s"), item.get("velocity_m_s")
        push = Push(item["object"], None if impulse is None else _vector(impulse, 2, f"{path}.impulse_N_s"),
                    None if velocity is None else _vector(velocity, 2, f"{path}.velocity_m_s"), at)
        if velocity is not None and math.hypot(*push.velocity_m_s) > MAX_SPEED_M_S:
            raise ConfigError(f"{path}.velocity_m_s", f"must be at most {MAX_SPEED_M_S:g} m/s")
        out.append(push)
    return tuple(out)
