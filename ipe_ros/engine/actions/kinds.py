"""What a robot may do to a scene: remove objects, place a new one, push one (plain data; each is
checked against the scene in ``checks.py`` before anything is simulated)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Union

from ..errors import ConfigError
from ..scene.bodies import Body, Scene


#: P(anything else falls) below this makes an object safe to remove now.
DEFAULT_SAFE_BELOW = 0.05
#: Removing i makes j fall with at least this probability: i supports j.
DEFAULT_SUPPORT_THRESHOLD = 0.5
#: what a question's empty list of objects is told
NO_OBJECTS = "names no object; name at least one, or leave it out to ask about every one"


def check_level(name: str, value) -> None:
    """A decision's probability level (``safe_below``, ``threshold``) lies in (0, 1]."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 1:
        raise ConfigError(name, f"must be in (0, 1], got {value!r}")


# -- actions ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Remove:
    """Take these objects away at t = 0 (lifted straight up: deleted before anything moves)."""

    names: tuple[str, ...]

    @property
    def label(self) -> str:
        return "remove/" + "+".join(self.names)


@dataclass(frozen=True)
class Place:
    """Add ``body`` at its pose; its own ``position_sigma_m`` / ``yaw_sigma_rad`` (else the model's
    sigma) say how precisely the robot puts it there."""

    body: Body

    @property
    def label(self) -> str:
        return f"place/{self.body.name}@{','.join(f'{v:.3f}' for v in self.body.position_m)}"


@dataclass(frozen=True)
class Push:
    """Push one object horizontally: at t = 0 it moves at ``velocity_m_s`` (the velocity the push
    gives the point it is pushed at; ``point_m`` in the scene frame, None: its centre of mass, no
    spin). ``direction_sigma_rad`` and ``speed_sigma_fraction``: the push's own uncertainty."""

    name: str
    velocity_m_s: tuple[float, float, float]
    point_m: tuple[float, float, float] | None = None
    direction_sigma_rad: float = 0.0
    speed_sigma_fraction: float = 0.0

    @property
    def label(self) -> str:
        return f"push/{self.name}"


Action = Union[Remove, Place, Push, None]  # None: the scene as it is


def label_of(action: Action) -> str:
    """A variant's name in answers (and the key of its own random stream)."""
    return "as_is" if action is None else action.label


@dataclass(frozen=True)
class Region:
    """Where to look for a place: x and y ranges in the scene frame (metres), yaws (radians)."""

    x_m: tuple[float, float]
    y_m: tuple[float, float]
    yaw_rad: tuple[float, float] = (0.0, 0.0)


def applied(scene: Scene, action: Action) -> Scene:
    """The scene the action leaves at t = 0, before any noise: removed objects gone, a placed one
    added at its pose, a pushed one moving at the push's velocity (what the validated envelope is
    asked about a variant: ``ask``)."""
    if isinstance(action, Remove):
        return dataclasses.replace(scene, objects=tuple(b for b in scene.objects if b.name not in action.names))
    if isinstance(action, Place):
        return dataclasses.replace(scene, objects=scene.objects + (action.body,))
    if isinstance(action, Push):
        return dataclasses.replace(scene, objects=tuple(
            dataclasses.replace(b, linear_velocity_m_s=action.velocity_m_s) if b.name == action.name else b
            for b in scene.objects))
    return scene
