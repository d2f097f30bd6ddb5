"""A query from outside the engine, with a parameter (tests/test_query_plugin.py): this module and
its one registration are all it takes. Importing the module registers it; worker processes import
it too (``engine.query.spec.plugin_modules``).

``tilt``: P(some object ends tilted more than ``tilt.threshold_deg`` from how it started), and per
object.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ipe_ros.engine import ConfigError
from ipe_ros.engine.query import QUERIES, Query, Reading, Samples, register


@dataclass(frozen=True)
class TiltParameters:
    threshold_deg: float = field(default=30.0, metadata={"meaning": "degrees from its start beyond which an "
                                                                    "object counts as tilted"})

    def __post_init__(self) -> None:
        if not 0.0 < self.threshold_deg < 180.0:
            raise ConfigError("tilt.threshold_deg", f"must be in (0, 180) degrees, got {self.threshold_deg!r}")


class Tilt(Query):
    name = "tilt"
    fields = ("tilt_probability", "tilted_object_probability")
    summary = "P(some object ends tilted beyond tilt.threshold_deg from how it started)"
    Parameters = TiltParameters

    def read(self, reading: Reading) -> dict[str, Any]:
        before, after = _z_axes(reading.initial_orientations_xyzw), _z_axes(reading.final_orientations_xyzw)
        angle_deg = np.degrees(np.arccos(np.clip(np.sum(before * after, axis=1), -1.0, 1.0)))
        return {"tilted": angle_deg > reading.spec.parameters_of(self.name).threshold_deg}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        tilted = np.array([r.value("tilted") for r in samples.rollouts])
        return {"tilt_probability": float(samples.per_sample(lambda r: r.value("tilted").any()).mean()),
                "tilted_object_probability": {n: float(p) for n, p in zip(samples.names, tilted.mean(axis=0))}}

    def flags(self, rollout) -> dict[str, Any]:
        return {} if rollout.get("tilted") is None else {"tilted": rollout.value("tilted")}


def _z_axes(xyzw: np.ndarray) -> np.ndarray:
    """Each body's z axis in the world, from its orientation quaternion."""
    x, y, z, w = xyzw.T
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=1)


QUERY = QUERIES["tilt"] if "tilt" in QUERIES else register(Tilt())
