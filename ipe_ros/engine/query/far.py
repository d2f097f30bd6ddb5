"""``far``: how far things fall (paper Exp. S2): the expected largest horizontal distance of a
fallen object from the tower's base."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import predicates
from ..results.stats import mean_interval
from .base import Query, Reading, Samples
from .fall import fallen_flags


def sample_far_m(outcome) -> float:
    """One sample's far distance, averaged over its push magnitudes."""
    return float(np.mean([r.value("far_m") for r in outcome.rollouts]))


class Far(Query):
    name = "far"
    fields = ("far_m", "far_m_ci95")
    summary = "expected largest distance of a fallen object from the base, metres"

    def read(self, reading: Reading) -> dict[str, Any]:
        fallen = reading.fallen
        return {"fallen": fallen,
                "far_m": predicates.far_m(reading.final_m, fallen, predicates.tower_base_xy_m(reading.scene))}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        per_sample = np.array([sample_far_m(o) for o in samples.outcomes])
        far = float(per_sample.mean())
        return {"far_m": far, "far_m_ci95": (far, far) if samples.deterministic else mean_interval(per_sample)}

    def flags(self, rollout) -> dict[str, Any]:
        return fallen_flags(rollout)


QUERY = Far()
