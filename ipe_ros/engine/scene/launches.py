"""Uncertain launches: the speed and direction of what moves at t = 0, as uncertain as its position.

A scene may start an object moving (a pushed domino, a thrown ball). A person watching, or a robot
that measured it, knows that speed and direction only roughly; the paper's position noise leaves them
exact. With a ``LaunchSpread`` each sample scales every moving object's initial velocity (linear and
angular alike: the same push, stronger or weaker) by a log-normal factor of log SD ``speed_log_sd`` and
turns it about the vertical by a normal angle of SD ``direction_sd_rad``. Each object's two draws come
from a stream of its own (keyed by its name, as ``scene.properties.draw_uncertain``'s), so turning the
spread on leaves every other draw as it was, and the same object launches alike in a question's
variants. The ground truth takes launches as given.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, shown
from .bodies import Scene

#: above this log SD a launch's speed spans more than a factor of ~20 within 2 SD: a units slip
MAX_SPEED_LOG_SD = 1.5
#: the stream key's first element: 2 is the uncertain properties'
_STREAM = 3


@dataclass(frozen=True)
class LaunchSpread:
    """Model-wide noise on what moves at t = 0 (0: exact): the speed's log SD and the direction's SD
    (radians, about the vertical)."""

    speed_log_sd: float = 0.0
    direction_sd_rad: float = 0.0

    def __post_init__(self) -> None:
        for name, top in (("speed_log_sd", MAX_SPEED_LOG_SD), ("direction_sd_rad", math.pi)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or not 0 <= value <= top:
                raise ConfigError(name, f"must be a number in [0, {top:g}] (0: exact), got {shown(value)}")


def launch_spread(speed_log_sd: float, direction_sd_rad: float) -> LaunchSpread | None:
    """The spread, or None when both are off (a request without it is keyed and answered as before)."""
    spread = LaunchSpread(speed_log_sd, direction_sd_rad)
    return None if spread == LaunchSpread() else spread


def launched(scene: Scene, spread: LaunchSpread | None) -> tuple[str, ...]:
    """The names of the dynamic objects whose launch a sample draws (none without a spread)."""
    if spread is None:
        return ()
    return tuple(b.name for b in scene.dynamic_objects if b.moving)


def draw_launch(name: str, spread: LaunchSpread, seed: np.random.SeedSequence) -> tuple[float, float]:
    """(speed factor, turn in radians) of object ``name`` in the sample of ``seed``."""
    key = (_STREAM, zlib.crc32(name.encode("utf-8", "backslashreplace")))
    z_speed, z_turn = np.random.default_rng(np.random.SeedSequence(seed.entropy, spawn_key=seed.spawn_key + key)) \
        .standard_normal(2)
    return float(math.exp(spread.speed_log_sd * z_speed)), float(spread.direction_sd_rad * z_turn)


def with_drawn_launches(scene: Scene, spread: LaunchSpread | None, seed: np.random.SeedSequence,
                        owners: frozenset[str] | None = None) -> tuple[Scene, tuple[tuple[str, float], ...]]:
    """The scene with each launched object's velocities scaled and turned by its draws, and the draws
    as ("name.launch_speed_factor", f), ("name.launch_turn_rad", a) (``SampleInputs.properties``'
    form). ``owners``: only these objects (None: all)."""
    names = [n for n in launched(scene, spread) if owners is None or n in owners]
    if not names:
        return scene, ()
    drawn = {n: draw_launch(n, spread, seed) for n in names}
    recorded: list[tuple[str, float]] = []

    def turned(body):
        if body.name not in drawn:
            return body
        factor, turn = drawn[body.name]
        recorded.extend(((f"{body.name}.launch_speed_factor", factor), (f"{body.name}.launch_turn_rad", turn)))
        c, s = math.cos(turn), math.sin(turn)
        rotate = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return dataclasses.replace(
            body, linear_velocity_m_s=tuple(float(v) for v in factor * rotate @ np.asarray(body.linear_velocity_m_s)),
            angular_velocity_rad_s=tuple(float(v) for v in factor * rotate @ np.asarray(body.angular_velocity_rad_s)))

    return dataclasses.replace(scene, objects=tuple(turned(b) for b in scene.objects)), tuple(recorded)
