"""An optional table of human responses: CSV with columns ``stimulus,response`` (one row per response;
other columns such as ``subject`` are ignored).

The paper's judgments are not public; a user who has some (or new ones) passes them with
``ipe experiment NAME --human FILE --human-scale SCALE``, and the reports then give the paper's
model-people correlations with bootstrap intervals and the estimate of k.

Scales: ``1-7`` (rescaled linearly to [0, 1], as the SI does), ``unit`` (already in [0, 1]),
``degrees`` or ``radians`` (directions: circular means and circular variances), ``metres``
(How far?).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .stats import circular_mean, circular_variance

SCALES = ("1-7", "unit", "degrees", "radians", "metres")


@dataclass(frozen=True)
class HumanResponses:
    """Per stimulus: the mean response (circular for angles), its variance about that mean (circular
    variance for angles) and the number of responses. ``angular``: responses are radians."""

    mean: dict[str, float]
    variance: dict[str, float]
    count: dict[str, int]
    angular: bool


def load_human_responses(path: str | Path, scale: str) -> HumanResponses:
    if scale not in SCALES:
        raise ValueError(f"--human-scale: must be one of {', '.join(SCALES)}, got {scale!r}")
    path = Path(path)
    if not path.exists():
        raise ValueError(f"--human: no such file {str(path)!r}")
    values: dict[str, list[float]] = {}
    with path.open(newline="") as handle:
        reader = csv.DictReader(handle)
        missing = [c for c in ("stimulus", "response") if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"--human: {path.name} lacks the column(s) {', '.join(missing)}; "
                             "it needs a header with 'stimulus' and 'response'")
        for line, row in enumerate(reader, start=2):
            try:
                value = float(row["response"])
            except (TypeError, ValueError):
                raise ValueError(f"--human: {path.name} line {line}: response {row['response']!r} is not a number") from None
            if not math.isfinite(value):
                raise ValueError(f"--human: {path.name} line {line}: response must be finite")
            if scale == "1-7":
                if not 1 <= value <= 7:
                    raise ValueError(f"--human: {path.name} line {line}: response {value:g} is outside the 1-7 scale")
                value = (value - 1) / 6
            elif scale == "unit" and not 0 <= value <= 1:
                raise ValueError(f"--human: {path.name} line {line}: response {value:g} is outside [0, 1]")
            elif scale == "degrees":
                value = math.radians(value)
            values.setdefault(row["stimulus"].strip(), []).append(value)
    if not values:
        raise ValueError(f"--human: {path.name} holds no responses")
    angular = scale in ("degrees", "radians")
    mean, variance = {}, {}
    for name, v in values.items():
        arr = np.array(v)
        if angular:
            mean[name], variance[name] = float(circular_mean(arr)), float(circular_variance(arr))
        else:
            mean[name] = float(arr.mean())
            variance[name] = float(arr.var(ddof=1)) if len(arr) > 1 else math.nan
    return HumanResponses(mean=mean, variance=variance, count={n: len(v) for n, v in values.items()},
                          angular=angular)
