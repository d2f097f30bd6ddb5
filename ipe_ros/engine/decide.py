"""When a question is decided: stopping rules for answering variants sample by sample.

A question that compares variants with a threshold (is this removal safe? does j fall without i?)
or with each other (which spot is best?) need not run every variant to the full k: samples are
drawn in batches, and a variant stops as soon as its 95% Wilson interval - the interval its answer
reports - lies on one side of the threshold, or (ranking) entirely above another candidate's. Sample
i keeps seed i whatever stops when, so a sequential answer equals the fixed-k answer cut at the
samples it used. The rules read counts only (``Tally``): they are the statistics, not the physics.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import ConfigError
from .estimate import wilson_interval

#: samples drawn per variant between two looks at the rules
DEFAULT_BATCH_SAMPLES = 4


@dataclass(frozen=True)
class Tally:
    """One variant's outcomes so far, over the samples in which the scene as it is stands."""

    samples: int
    any_falls: int
    object_falls: dict[str, int]


def _interval(count: int, n: int) -> tuple[float, float]:
    return wilson_interval(count / n, n)


def _side(count: int, n: int, level: float) -> str | None:
    """"below" / "above" when the interval lies entirely on that side of ``level``; else None."""
    if n == 0:
        return None
    low, high = _interval(count, n)
    return "below" if high < level else "above" if low > level else None


@dataclass(frozen=True)
class SafeBelow:
    """Safe to do: P(anything falls) below ``level`` ("safe") or above it ("unsafe")."""

    level: float

    def decide(self, tallies: dict[str, Tally], active: set[str]) -> dict[str, str]:
        out = {}
        for label in active:
            side = _side(tallies[label].any_falls, tallies[label].samples, self.level)
            if side is not None:
                out[label] = "safe" if side == "below" else "unsafe"
        return out


@dataclass(frozen=True)
class Supports:
    """The support graph: a removal is decided when it is decided safe or unsafe and every remaining
    object's P(falls without it) is decided above or below ``threshold`` (an edge or none)."""

    threshold: float
    safe_below: float

    def decide(self, tallies: dict[str, Tally], active: set[str]) -> dict[str, str]:
        safe = SafeBelow(self.safe_below).decide(tallies, active)
        return {label: verdict for label, verdict in safe.items()
                if all(_side(c, tallies[label].samples, self.threshold) is not None
                       for c in tallies[label].object_falls.values())}


@dataclass(frozen=True)
class Ranking:
    """Least likely to make anything fall first: a candidate is out ("ranked out") once the low end of
    its interval is above the high end of another candidate's; the last one in is "best". Candidates
    equally good within their intervals (two safe spots) run to the cap: they are tied."""

    def decide(self, tallies: dict[str, Tally], active: set[str]) -> dict[str, str]:
        bounds = {label: _interval(t.any_falls, t.samples) for label, t in tallies.items() if t.samples}
        if not bounds:
            return {}
        best_high = min(high for _, high in bounds.values())
        out = {label: "ranked out" for label in active if label in bounds and bounds[label][0] > best_high}
        left = active - set(out)
        if len(left) == 1 and len(active) > 1:
            out[next(iter(left))] = "best"
        return out


Rule = SafeBelow | Supports | Ranking


@dataclass(frozen=True)
class Sequential:
    """Answer variants in batches of ``batch_samples`` samples until ``rule`` decides each (or the
    question's k, its cap, is reached)."""

    rule: Rule
    batch_samples: int = DEFAULT_BATCH_SAMPLES

    def __post_init__(self) -> None:
        if isinstance(self.batch_samples, bool) or not isinstance(self.batch_samples, int) or self.batch_samples < 1:
            raise ConfigError("batch_samples", f"must be an integer >= 1, got {self.batch_samples!r}")
