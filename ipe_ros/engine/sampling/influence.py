"""Which uncertain property moves the answer most: what a robot should measure next.

Each sample drew its own mass, friction or restitution where the scene (or the model's spread) left
them uncertain (``perturb.draw_sample``). A property's influence is the outcome's difference between
the samples that drew it above its median and those that drew it at or below: per object, the fall
probability where the fall predicate was read, else the horizontal distance travelled; the object
that differs most is named. A difference within about two of its standard errors is sampling noise.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..scene.bodies import Scene
from ..results.outcome import SampleOutcome

#: the fewest samples on each side of the median for a difference to be reported
MIN_SAMPLES_PER_SIDE = 2


def property_influence(scene: Scene, outcomes: Sequence[SampleOutcome]) -> tuple[dict, ...] | None:
    """Per uncertain property, strongest first: its median, the object it moves most, that object's
    outcome below and above the median, their difference and its standard error. None where no
    property was uncertain (or too few samples ran to tell)."""
    ok = [o for o in outcomes if o.ok and o.properties and o.rollouts]
    if not ok:
        return None
    names = [name for name, _ in ok[0].properties]
    ok = [o for o in ok if [name for name, _ in o.properties] == names]
    outcome, what = _per_object_outcome(ok)
    values = np.array([[value for _, value in o.properties] for o in ok])
    objects = [b.name for b in scene.dynamic_objects]
    rows = []
    for j, name in enumerate(names):
        median = float(np.median(values[:, j]))
        above = values[:, j] > median
        if min(above.sum(), (~above).sum()) < MIN_SAMPLES_PER_SIDE:
            continue
        high, low = outcome[above], outcome[~above]
        difference = high.mean(axis=0) - low.mean(axis=0)
        k = int(np.argmax(np.abs(difference)))
        se = np.sqrt(high[:, k].var(ddof=1) / len(high) + low[:, k].var(ddof=1) / len(low))
        rows.append({"property": name, "median": median, "object": objects[k], "outcome": what,
                     "below_median": float(low[:, k].mean()), "above_median": float(high[:, k].mean()),
                     "difference": float(difference[k]), "difference_se": float(se)})
    if not rows:
        return None
    return tuple(sorted(rows, key=lambda row: -abs(row["difference"])))


def _per_object_outcome(outcomes: list[SampleOutcome]) -> tuple[np.ndarray, str]:
    """(samples, objects): each object's fall (averaged over the sample's rollouts) where the fall
    predicate was read, else its horizontal travel in metres."""
    if all(r.fallen is not None for o in outcomes for r in o.rollouts):
        return np.array([np.mean([np.asarray(r.fallen, float) for r in o.rollouts], axis=0) for o in outcomes]), \
            "fall_probability"
    return np.array([np.mean([np.linalg.norm(r.final_positions_m[:, :2] - o.initial_positions_m[:, :2], axis=1)
                              for r in o.rollouts], axis=0) for o in outcomes]), "travel_m"
