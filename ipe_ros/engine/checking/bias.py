"""Which samples the self-check reruns at the reference, and what their differences say: the bias of
each yes/no outcome (fast "yes" and reference "no", less the other way round) estimated stratum by
stratum, and the samples that would decide it (``fidelity`` re-exports these; ``self_check`` uses them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np


#: the bias's credible interval leaves out this share of the posterior on each side (an 80% interval:
#: replayed on the zoo, 90% escalated too little to catch more than today's rule)
BIAS_TAIL = 0.2
_BIAS_DRAWS = 4000


@dataclass(frozen=True)
class Bias:
    """One yes/no outcome's bias over the answer's samples: the share of them the fast physics says
    "yes" and the reference "no", less the other way round, estimated stratum by stratum from the
    compared samples (``bias_estimates``).

    outcome: its index in ``outcome_flags``; estimate, low, high: the posterior mean and the credible
    interval (``BIAS_TAIL`` left out on each side); same_way: compared samples differing in the
    estimate's direction, net of those differing the other way; on_side: compared samples differing in
    the estimate's direction (all on the fast side that says it: "yes" for a positive bias), not net
    (the interval already weighs the other side's differences by the samples they stand for);
    strata: per fast side (0: "no", 1: "yes") the fast samples there, the compared ones among them
    and how many of those differ."""

    outcome: int
    estimate: float
    low: float
    high: float
    same_way: int
    strata: tuple[tuple[int, int, int], tuple[int, int, int]]
    on_side: int = 0

    def beyond(self, tolerance: float) -> bool:
        """Credibly larger than ``tolerance`` (either way)."""
        return self.low > tolerance or self.high < -tolerance

    def differing(self, counted: str = "net") -> int:
        """Compared samples that differ in the estimate's direction: ``same_way`` ("net") or
        ``on_side`` ("side"; ``SelfCheck.same_way``)."""
        return self.on_side if counted == "side" else self.same_way

    def escalates(self, tolerance: float, at_least: int, counted: str = "net") -> bool:
        """Credibly beyond ``tolerance`` on at least ``at_least`` differences in its direction
        (counted as ``differing`` counts them): the fast physics is contradicted."""
        return self.beyond(tolerance) and self.differing(counted) >= at_least

    def within(self, tolerance: float) -> bool:
        """Credibly no larger than ``tolerance``."""
        return -tolerance <= self.low and self.high <= tolerance


def bias_estimates(fast_flags: dict[int, np.ndarray], differences: dict[int, np.ndarray],
                   also: Sequence[int] = ()) -> list[Bias]:
    """Per yes/no outcome that differs in some compared sample (and each of ``also``, differing or
    not), its ``Bias`` over the answer's samples, from every good sample's fast flags (sample
    index -> 0/1) and the compared samples' differences (fast - reference).

    A fast physics that is wrong says "yes" where the reference says "no" on part of the samples
    whose fast outcome is "yes" (and the other way round), so the samples are split by their fast
    outcome. In each side the share that differs gets a posterior from its compared samples
    (Jeffreys' Beta(1/2, 1/2) prior: a side nobody looked at could hold any share), and the side's
    samples not compared yet differ by draws from it: the bias is that of these k samples, which
    the reference answers once every one is compared (so an interval narrows as a side is looked
    through, and is a point once all of it is). Chaos flips outcomes either way, and a collapsing
    block that both physics drop in a third of the samples differs in most samples targeted on one
    side; on both sides the flips cancel, and the interval stays wide until the other side has been
    looked at. Drawn from a fixed generator: the same samples give the same interval."""
    compared = {i: d for i, d in differences.items() if i in fast_flags}
    if not compared or not fast_flags:
        return []
    order = sorted(fast_flags)
    flags = np.array([fast_flags[i] for i in order], float)
    k = len(order)
    looked = np.array([fast_flags[i] for i in compared], bool)
    differ = np.array([compared[i] != 0 for i in compared], bool)
    net = np.sum(list(compared.values()), axis=0)
    rng = np.random.default_rng(20131)
    out = []
    width = differ.shape[1] if differ.ndim == 2 else 0
    for j in sorted(set(np.flatnonzero(differ.any(axis=0)).tolist()) | {int(j) for j in also if j < width}):
        draws, strata = np.zeros(_BIAS_DRAWS), []
        for side, sign in ((0, -1.0), (1, 1.0)):
            weight = int(np.sum(flags[:, j] == side))
            here = looked[:, j] == bool(side)
            seen, differing = int(here.sum()), int(differ[here, j].sum())
            strata.append((weight, seen, differing))
            share = rng.beta(differing + 0.5, seen - differing + 0.5, _BIAS_DRAWS)
            draws += sign * (differing + rng.binomial(weight - seen, share)) / k
        low, high = np.quantile(draws, [BIAS_TAIL, 1 - BIAS_TAIL])
        estimate = float(draws.mean())
        out.append(Bias(int(j), estimate, float(low), float(high), int(net[j] if estimate >= 0 else -net[j]),
                        (strata[0], strata[1]), strata[1 if estimate >= 0 else 0][2]))
    return out


def undecided_bias_samples(fast_flags: dict[int, np.ndarray], candidates: list[int], biases: list[Bias],
                           tolerance: float, count: int, at_least: int = 1, counted: str = "net") -> list[int]:
    """Which ``count`` of ``candidates`` (samples not yet rerun) to compare next where some
    outcome's bias is neither credibly beyond ``tolerance`` (with ``at_least`` same-way
    differences) nor credibly within it: for the widest such outcome, one sample from each fast side
    with samples left to look at in turn, in index order, the side whose unseen samples leave the
    bias most uncertain first (the predictive variance of how many of them differ), then any others.
    Both sides, not the more uncertain one alone: a bias on a small side escalates only once a second
    sample there differs, and a clean large side alone can never show it. [] when every bias is decided."""
    open_ = [b for b in biases if not b.escalates(tolerance, at_least, counted) and not b.within(tolerance)]
    rest = sorted(i for i in candidates if i in fast_flags)
    if not open_ or not rest or count <= 0:
        return []
    widest = max(open_, key=lambda b: (b.high - b.low, -b.outcome))
    j = widest.outcome

    def spread(side: int) -> float:  # the beta-binomial variance of the side's unseen differing samples
        weight, seen, differing = widest.strata[side]
        a, b, unseen = differing + 0.5, seen - differing + 0.5, weight - seen
        return unseen * a * b * (a + b + unseen) / ((a + b) ** 2 * (a + b + 1))

    by_side = {side: [i for i in rest if fast_flags[i].shape[0] > j and fast_flags[i][j] == side] for side in (0, 1)}
    sides = [side for side in sorted((0, 1), key=lambda side: -spread(side)) if by_side[side]]
    picked = [by_side[side][n] for n in range(count) for side in sides if n < len(by_side[side])]
    picked += [i for i in rest if i not in picked]
    return picked[:count]


def confirmation_samples(fast_flags: dict[int, np.ndarray], differences: dict[int, np.ndarray],
                         count: int) -> list[int]:
    """Which ``count`` samples to verify next, given the fast outcomes (sample index -> 0/1 flags)
    of the samples not yet verified and the differences found so far (sample -> fast - reference).

    A fast physics that makes some outcome come out "yes" where the reference says "no" can only
    show that on samples where the fast physics says "yes" (and the other way round): so the next
    samples are those whose fast outcome equals the fast side of the suspect difference (the outcome
    differing most often one way; among equals, the one with most such samples), in index order,
    then any others. Unbiased chaos flips either way on these samples as on any; a bias on a
    minority of samples is confirmed here instead of being diluted by samples that cannot show it.
    """
    rest = sorted(fast_flags)
    if count <= 0 or not rest:
        return []
    net = np.sum(list(differences.values()), axis=0) if differences else np.zeros(0)
    best: tuple[tuple[int, int], list[int]] | None = None
    for j in np.flatnonzero(net):
        fast_side = 1.0 if net[j] > 0 else 0.0
        candidates = [i for i in rest if fast_flags[i].shape == net.shape and fast_flags[i][j] == fast_side]
        key = (int(abs(net[j])), len(candidates))
        if best is None or key > best[0]:
            best = (key, candidates)
    picked = (best[1] if best else [])[:count]
    return picked + [i for i in rest if i not in picked][:count - len(picked)]


def coverage_samples(fast_flags: dict[int, np.ndarray], looked: Sequence[np.ndarray], at_least: int,
                     count: int) -> list[int]:
    """Which samples (at most ``count``) to verify so that the comparison could see any bias big
    enough to escalate, given the fast outcomes (sample index -> 0/1 flags) of the samples not yet
    verified and those of the samples already compared (``looked``).

    A bias that makes outcome j "yes" where the reference says "no" shows only on samples whose fast
    outcome j is "yes" (and the other way round). A side of an outcome that at least ``at_least``
    fast samples take (fewer could not escalate) and no compared sample took is uncovered; each pick
    is the sample covering the most uncovered fast samples (summed over the sides it takes; lowest
    index among equals), until every side is covered or ``count`` are picked.
    """
    shape = next(iter(fast_flags.values()), np.zeros(0)).shape
    rest = {i: f.astype(bool) for i, f in sorted(fast_flags.items()) if f.shape == shape}
    if count <= 0 or not rest or len(shape) != 1 or not shape[0]:
        return []
    seen = np.array([f for f in looked if f.shape == shape], bool).reshape(-1, *shape)
    flags = np.concatenate([np.array(list(rest.values())), seen])
    yes, no = flags.sum(axis=0), (~flags).sum(axis=0)
    weight_yes = np.where((yes >= at_least) & ~seen.any(axis=0), yes, 0)
    weight_no = np.where((no >= at_least) & ~(~seen).any(axis=0), no, 0)
    picked: list[int] = []
    while len(picked) < count:
        scores = {i: int(weight_yes[f].sum() + weight_no[~f].sum()) for i, f in rest.items() if i not in picked}
        best = max(scores, key=lambda i: (scores[i], -i), default=None)
        if best is None or scores[best] == 0:
            break
        picked.append(best)
        weight_yes[rest[best]] = 0
        weight_no[~rest[best]] = 0
    return picked
