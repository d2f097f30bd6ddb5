"""``tipped``: will it tip over? P(some object ends turned more than ``tipped.threshold_deg`` away
from how it stood), and each object's probability.

The fall query asks whether an object's centre dropped (by the fall threshold of its smallest
extent): the paper's predicate for blocks in a tower. An object that tips over in place, a mug
onto its side or a bottle lying down, may drop its centre by less than that and is then not
"fallen"; what a robot asks of it is whether it still stands as it stood. Tipped: the up direction,
seen from the object, turned by more than the threshold between the start and the end (a turn
about the vertical alone, a box spinning on the floor, is not tipping; nor is a ball rolling, or a
can rolling on its side: a turn about a body's own axis of symmetry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ConfigError, shown
from ..scene.shapes import Capsule, Cylinder, Sphere
from .base import Query, Reading, Samples


@dataclass(frozen=True)
class TippedParameters:
    """Tipped: the object's up direction turned by more than ``threshold_deg``."""

    threshold_deg: float = field(default=45.0, metadata={
        "meaning": "degrees by which an object's up direction must turn to count as tipped over"})

    def __post_init__(self) -> None:
        value = self.threshold_deg
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not 0.0 < value < 180.0:
            raise ConfigError("tipped.threshold_deg", f"must be in (0, 180) degrees, got {shown(value)}")


def up_in_body(orientations_xyzw: np.ndarray) -> np.ndarray:
    """Per body, the world's up direction in the body's own frame (R^T e_z: the third row of R)."""
    q = np.asarray(orientations_xyzw, float).reshape(-1, 4)
    x, y, z, w = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)


def tipped_by_deg(initial_xyzw: np.ndarray, final_xyzw: np.ndarray, shapes_: tuple | None = None) -> np.ndarray:
    """Per body, the angle (degrees) between the up direction it started and ended with, in its
    frame, up to the body's own symmetry (``shapes_``, per body; None: none): a sphere has no up, so
    it never tips (a ball rolls); a cylinder's or a capsule's turn about its own axis is no tipping
    (a can rolls on its side), so for them the change of its axis' tilt from the vertical."""
    before, after = up_in_body(initial_xyzw), up_in_body(final_xyzw)
    turned = np.degrees(np.arccos(np.clip(np.sum(before * after, axis=1), -1.0, 1.0)))
    for i, shape in enumerate(shapes_ or ()):
        if isinstance(shape, Sphere):
            turned[i] = 0.0
        elif isinstance(shape, (Cylinder, Capsule)):  # the axis is z: its tilt is acos(up_z)
            tilt = np.degrees(np.arccos(np.clip([before[i, 2], after[i, 2]], -1.0, 1.0)))
            turned[i] = abs(tilt[1] - tilt[0])
    return turned


class Tipped(Query):
    name = "tipped"
    fields = ("tipped_probability", "tipped_probability_ci95", "tipped_object_probability")
    summary = "P(some object ends tipped over: turned more than tipped.threshold_deg from how it stood), and each one's"
    Parameters = TippedParameters

    def read(self, reading: Reading) -> dict[str, Any]:
        turned = tipped_by_deg(reading.initial_orientations_xyzw, reading.final_orientations_xyzw,
                               tuple(b.shape for b in reading.scene.dynamic_objects))
        return {"tipped": turned > reading.spec.parameters_of(self.name).threshold_deg}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        p = float(samples.per_sample(lambda r: bool(np.any(r.value("tipped")))).mean())
        per_object = np.mean([r.value("tipped") for r in samples.rollouts], axis=0)
        return {"tipped_probability": p, "tipped_probability_ci95": samples.fraction_interval(p),
                "tipped_object_probability": {n: float(v) for n, v in zip(samples.names, per_object)}}

    def flags(self, rollout) -> dict[str, Any]:
        tipped = rollout.get("tipped")
        return {} if tipped is None else {"tipped": np.asarray(tipped, float)}

    def describe(self, prediction) -> list[str]:
        lo, hi = prediction.tipped_probability_ci95
        most = max((prediction.tipped_object_probability or {}).items(), key=lambda kv: kv[1], default=None)
        return [f"P(something tips over): {prediction.tipped_probability:.3f} [{lo:.2f}, {hi:.2f}]"
                + ("" if most is None or most[1] == 0 else f"; most likely {most[0]} ({most[1]:.2f})")]

    def sample_columns(self, outcome) -> dict[str, float]:
        return {"tipped": float(np.mean([np.any(r.value("tipped")) for r in outcome.rollouts]))}


QUERY = Tipped()
