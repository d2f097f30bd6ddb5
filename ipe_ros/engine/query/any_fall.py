"""``any_fall``: the probability that at least one object falls (the yes/no question). A rollout
asked only this ends at the first fall."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Query, Reading, Samples
from .fall import fallen_below_z_m


def sample_any_fall(outcome) -> float:
    """One sample's "did anything fall?" (1 or 0), averaged over its push magnitudes."""
    return float(np.mean([float(r.value("any_fell")) for r in outcome.rollouts]))


class AnyFall(Query):
    name = "any_fall"
    fields = ("any_fall_probability", "any_fall_probability_ci95")
    summary = "probability that anything falls (its rollouts end at the first fall)"
    decided_by_first_fall = True

    def decided_below_z(self, scene, spec, initial_m):
        return fallen_below_z_m(scene, spec, initial_m)

    def read(self, reading: Reading) -> dict[str, Any]:
        return {"any_fell": bool(reading.fallen.any())}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        anything = float(np.mean([sample_any_fall(o) for o in samples.outcomes]))
        return {"any_fall_probability": anything, "any_fall_probability_ci95": samples.fraction_interval(anything)}

    def flags(self, rollout) -> dict[str, Any]:
        return {} if rollout.get("any_fell") is None else {"any_fell": [float(rollout.value("any_fell"))]}


QUERY = AnyFall()
