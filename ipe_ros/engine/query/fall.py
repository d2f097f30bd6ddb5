"""``fall``: the expected fraction of dynamic objects that fall, and each one's probability
(paper Exps. 1, 3). An object has fallen when its centre dropped by more than the fall threshold
(``QuerySpec.fall_threshold_fraction`` of its smallest extent)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import Query, Reading, Samples, smallest_extents_m


def fallen_below_z_m(scene, spec, initial_m: np.ndarray) -> np.ndarray:
    """The height below which a body's centre has fallen: decided, whatever it does next."""
    return initial_m[:, 2] - spec.fall_threshold_fraction * smallest_extents_m(scene)


def fallen_flags(rollout) -> dict[str, Any]:
    """Which bodies fell, as the self-check compares it (fall, direction and far all read it)."""
    return {} if rollout.fallen is None else {"fallen": rollout.fallen}


def sample_fall_fraction(outcome) -> float:
    """One sample's fraction of fallen boxes, averaged over its push magnitudes (samples are the units)."""
    return float(np.mean([r.fallen.mean() for r in outcome.rollouts]))


class Fall(Query):
    name = "fall"
    fields = ("fall_fraction", "fall_fraction_ci95", "object_fall_probability")
    summary = "expected fraction of objects that fall, and each one's probability"

    def decided_below_z(self, scene, spec, initial_m):
        return fallen_below_z_m(scene, spec, initial_m)

    def read(self, reading: Reading) -> dict[str, Any]:
        return {"fallen": reading.fallen}

    def flags(self, rollout) -> dict[str, Any]:
        return fallen_flags(rollout)

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        fall = float(np.array([sample_fall_fraction(o) for o in samples.outcomes]).mean())
        per_object = np.mean([r.fallen for r in samples.rollouts], axis=0)
        return {"fall_fraction": fall, "fall_fraction_ci95": samples.fraction_interval(fall),
                "object_fall_probability": {n: float(p) for n, p in zip(samples.names, per_object)}}


QUERY = Fall()
