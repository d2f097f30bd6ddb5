"""``direction``: where things fall (paper Exps. 2, 4): the circular mean of the rollouts' mean
horizontal displacement of the fallen objects, and how decisive it is (the largest share of those
directions inside one half circle)."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import predicates
from ..results.stats import circular_mean, half_circle_decisiveness
from .base import Query, Reading, Samples
from .fall import fallen_flags


class Direction(Query):
    name = "direction"
    fields = ("direction_rad", "direction_decisiveness", "direction_rollouts")
    summary = "direction of the fall and its decisiveness"

    def read(self, reading: Reading) -> dict[str, Any]:
        fallen = reading.fallen
        return {"fallen": fallen,
                "direction_rad": predicates.fall_direction_rad(reading.initial_m, reading.final_m, fallen)}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        angles = np.array([r.get("direction_rad") for r in samples.rollouts if r.get("direction_rad") is not None])
        return {"direction_rad": circular_mean(angles), "direction_decisiveness": half_circle_decisiveness(angles),
                "direction_rollouts": int(len(angles))}

    def flags(self, rollout) -> dict[str, Any]:
        return fallen_flags(rollout)


QUERY = Direction()
