"""``rest``: is everything at rest at the end? The probability that every dynamic object ends
slower than its parameter ``speed_sizes_per_s`` (the scene's smallest extent per second) and
``spin_rad_s``, and the largest speed any object still has at the end.

The end is the horizon, or earlier where early termination found everything at rest for its whole
window; asked this, that reading of rest is made at least as strict as the query's, so a rollout
ended early is at rest by the query's reading too.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..checks import positive
from .base import Query, Reading, Samples


@dataclass(frozen=True)
class RestParameters:
    """At rest: slower than ``speed_sizes_per_s`` and ``spin_rad_s`` (the strict reading the
    self-check's reference uses)."""

    speed_sizes_per_s: float = field(default=0.05, metadata={
        "meaning": "at rest below this speed, in the scene's smallest extents per second"})
    spin_rad_s: float = field(default=0.05, metadata={"meaning": "and below this spin, rad/s"})

    def __post_init__(self) -> None:
        positive(self.speed_sizes_per_s, "rest.speed_sizes_per_s")
        positive(self.spin_rad_s, "rest.spin_rad_s")


class Rest(Query):
    name = "rest"
    fields = ("rest_probability", "rest_probability_ci95", "max_final_speed_m_s")
    summary = "P(everything at rest at the end) and the largest speed left"
    Parameters = RestParameters

    def early_stop(self, early_stop, spec):
        own = spec.parameters_of(self.name)
        return dataclasses.replace(early_stop, speed_sizes_per_s=min(early_stop.speed_sizes_per_s, own.speed_sizes_per_s),
                                   angular_rad_s=min(early_stop.angular_rad_s, own.spin_rad_s))

    def read(self, reading: Reading) -> dict[str, Any]:
        scale = float(reading.smallest_extents_m.min())
        speeds, spins = reading.final_speeds_m_s, reading.final_spins_rad_s
        own = reading.spec.parameters_of(self.name)
        at_rest = bool(np.all(speeds < own.speed_sizes_per_s * scale) and np.all(spins < own.spin_rad_s))
        return {"rest": {"at_rest": at_rest, "max_speed_m_s": float(speeds.max(initial=0.0))}}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        p = float(samples.per_sample(lambda r: r.value("rest")["at_rest"]).mean())
        fastest = max(r.value("rest")["max_speed_m_s"] for r in samples.rollouts)
        return {"rest_probability": p, "rest_probability_ci95": samples.fraction_interval(p),
                "max_final_speed_m_s": float(fastest)}

    def flags(self, rollout) -> dict[str, list[float]]:
        return {} if rollout.get("rest") is None else {"rest": [float(rollout.value("rest")["at_rest"])]}

    def describe(self, prediction) -> list[str]:
        lo, hi = prediction.rest_probability_ci95
        return [f"P(everything at rest at the end): {prediction.rest_probability:.3f} [{lo:.2f}, {hi:.2f}]; "
                f"fastest left: {prediction.max_final_speed_m_s:.3g} m/s"]

    def sample_columns(self, outcome) -> dict[str, float]:
        return {"at_rest": float(np.mean([r.value("rest")["at_rest"] for r in outcome.rollouts]))}


QUERY = Rest()
