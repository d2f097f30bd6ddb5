"""When a question is decided: stopping rules for answering variants sample by sample.

A question that compares variants with a threshold (is this removal safe? does j fall without i?)
or with each other (which spot is best?) need not run every variant to the full k: samples are
drawn in batches, and a variant stops as soon as its 95% Wilson interval - the interval its answer
reports - lies on one side of the threshold, or (ranking) entirely above another candidate's. Sample
i keeps seed i whatever stops when, so a sequential answer equals the fixed-k answer cut at the
samples it used. The rules read counts only (``Tally``): they are the statistics, not the physics.

A variant also stops, undecided, once no outcome of the samples left before the cap could decide
it (curtailment, ``undecidable``): whatever they would show, the fixed-k run's decision there is
"undecided" too. Two safe spots tied at no fall stop there instead of running to the cap.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ConfigError
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


def _lowest_high(count: int, n: int, more: int) -> float:
    """The lowest high end of the interval after up to ``more`` further samples: none of them falls
    (for every number of them: a variant runs only in the samples where the scene as it is stands).
    1.0 with no sample at all."""
    return min((_interval(count, n + extra)[1] for extra in range(more + 1) if n + extra), default=1.0)


def _highest_low(count: int, n: int, more: int) -> float:
    """The highest low end of the interval after up to ``more`` further samples: all of them fall."""
    return max((_interval(count + extra, n + extra)[0] for extra in range(more + 1) if n + extra), default=0.0)


def _reachable(count: int, n: int, more: int, level: float) -> set[str]:
    """The sides of ``level`` the interval could lie on after up to ``more`` further samples."""
    return ({"below"} if _lowest_high(count, n, more) < level else set()) | \
        ({"above"} if _highest_low(count, n, more) > level else set())


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

    def undecidable(self, tallies: dict[str, Tally], active: set[str], more: int) -> set[str]:
        """The active variants that ``more`` samples could not decide either way."""
        return {label for label in active
                if not _reachable(tallies[label].any_falls, tallies[label].samples, more, self.level)}


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

    def undecidable(self, tallies: dict[str, Tally], active: set[str], more: int) -> set[str]:
        """The active removals whose safety, or an object's edge, ``more`` samples could not decide."""
        def open_for_good(t: Tally) -> bool:
            return not _reachable(t.any_falls, t.samples, more, self.safe_below) or any(
                not _reachable(c, t.samples, more, self.threshold) for c in t.object_falls.values())
        return {label for label in active if open_for_good(tallies[label])}


@dataclass(frozen=True)
class Ranking:
    """Least likely to make anything fall first: a candidate is out ("ranked out") once the low end of
    its interval is above the high end of another candidate's; the last one in is "best". Candidates
    equally good within their intervals (two safe spots) are tied: they run until no further sample
    could rank any of them out (``undecidable``), at most to the cap."""

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

    def undecidable(self, tallies: dict[str, Tally], active: set[str], more: int) -> set[str]:
        """All active candidates when none of them could be ranked out whatever ``more`` samples show
        (and so none could be left alone as best): they are tied for good. Otherwise none: one
        candidate's further samples narrow the interval that may rank another out."""
        if len(active) < 2:
            return set()
        # the lowest high end each candidate could reach (those done sampling: their own)
        lowest_high = {label: _lowest_high(t.any_falls, t.samples, more if label in active else 0)
                       for label, t in tallies.items()}
        for label in active:
            t = tallies[label]
            others = [high for other, high in lowest_high.items() if other != label]
            if others and _highest_low(t.any_falls, t.samples, more) > min(others):
                return set()
        return set(active)


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
