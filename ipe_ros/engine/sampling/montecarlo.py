"""The one Monte Carlo loop: how every answer's samples are run.

A prediction (fixed k or anytime), a robot question's variants (all at once or sequentially until
decided) and the self-check's reruns are each a *plan*: a generator that yields the tasks it wants
run next, is sent their outcomes in the same order, and returns its result once it needs nothing
more (emcee's ``sample()`` turned inside out: the plan decides what to draw, the loop runs it).
``MonteCarlo`` is the loop, and the one home of what every plan shares: the child seeds, the
injected ``map_fn(fn, tasks, on_lost=...)`` with its answer for a worker lost twice, the budget's
deadline stamped on every task, and the clock. ``together`` makes one plan of several, whose rounds
share one map call (several answers' samples, or every variant's self-check, keep the workers busy).

Which samples run never depends on the worker count or on scheduling: sample i always gets the i-th
child of ``SeedSequence(seed)``. Only the budget's cut-offs and an anytime deadline depend on time.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Callable, Generator, Sequence, TypeVar

import numpy as np

from ..errors import ConfigError, shown

T = TypeVar("T")
R = TypeVar("R")

#: A plan: yields lists of tasks, is sent their outcomes (a list, in order), returns its result.
Plan = Generator[list, list, Any]
#: ``map_fn(fn, tasks, on_lost=on_lost)``: ``WorkerPool.map``, ``DaskMap.map``, a store's map.
MapFn = Callable[..., list]


def check_seed(seed) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ConfigError("seed", f"must be an integer >= 0, got {shown(seed)}")


def child_seeds(seed: int, k: int) -> list[np.random.SeedSequence]:
    """Sample i's seed: the i-th child of ``SeedSequence(seed)``, whatever k is."""
    check_seed(seed)
    return np.random.SeedSequence(seed).spawn(k)


#: a cost projected before or early in the work refuses it only when this many times over the budget:
#: a projection is a guess (a fixed pace per body and step, or the pace of a warming-up start on a busy
#: machine); nearer the budget the work runs, and the deadline ends it with what it did (issue 75)
FAR_OVER_BUDGET = 3.0


def far_over_budget(projected_s: float, budget_s: float | None) -> bool:
    """The projected cost is far beyond the budget (``FAR_OVER_BUDGET`` times): refuse up front."""
    return budget_s is not None and projected_s > FAR_OVER_BUDGET * budget_s


def check_budget(budget_s: float | None) -> None:
    if budget_s is not None and (isinstance(budget_s, bool) or not isinstance(budget_s, (int, float))
                                 or not math.isfinite(budget_s) or budget_s <= 0):
        raise ConfigError("budget_s", f"must be a finite number of seconds > 0 (or none), got {shown(budget_s)}")


def check_some_sample_finished(outcomes: Sequence, budget_s: float | None) -> None:
    """An answer needs samples: when the budget cut off every sample (none finished), that is an
    error saying so (ConfigError naming budget_s), never an answer whose every probability is null."""
    if any(o.ok for o in outcomes) or not any(o.budget_stopped for o in outcomes):
        return
    cut = sum(o.budget_stopped for o in outcomes)
    failed = sum(not o.ok and not o.budget_stopped for o in outcomes)
    raise ConfigError("budget_s", f"no sample finished within the budget of {budget_s:g} s ({cut} cut off"
                                  + (f", {failed} failed" if failed else "") + "); raise the budget, or ask for fewer "
                                  "samples, objects or contact pairs")


class MonteCarlo:
    """Runs plans (``drive``): each round's tasks go to ``fn`` through ``map_fn`` (in this process
    without one), a task whose worker was lost twice is answered by ``on_lost(task, reason)``, and
    every task carries the budget's deadline (``deadline_unix_s``, wall-clock so that workers share
    it), which starts when this loop is made. ``fn`` is module-level, so workers can run it."""

    def __init__(self, fn: Callable[[T], R], on_lost: Callable[[T, str], R], map_fn: MapFn | None = None,
                 budget_s: float | None = None):
        check_budget(budget_s)
        self.fn, self.on_lost, self.map_fn = fn, on_lost, map_fn
        self.started_s = time.perf_counter()
        self.deadline_unix_s = None if budget_s is None else time.time() + budget_s

    def elapsed_s(self) -> float:
        return time.perf_counter() - self.started_s

    def run(self, tasks: list) -> list:
        """The tasks' outcomes, in order (one map call)."""
        if self.deadline_unix_s is not None:
            tasks = [dataclasses.replace(t, deadline_unix_s=self.deadline_unix_s) for t in tasks]
        if self.map_fn is None:
            return [self.fn(t) for t in tasks]
        return self.map_fn(self.fn, tasks, on_lost=self.on_lost)

    def drive(self, plan: Plan) -> Any:
        """Run the plan to its end; its result."""
        return drive(plan, self.run)


def drive(plan: Plan, run: Callable[[list], list]) -> Any:
    """The loop itself: each round, what the plan yields goes to ``run`` and the outcomes back to
    the plan (a round asking for nothing is answered at once), until it returns."""
    try:
        tasks = next(plan)
        while True:
            tasks = plan.send(run(tasks) if tasks else [])
    except StopIteration as done:
        return done.value


def together(plans: Sequence[Plan]) -> Plan:
    """Several plans as one: each round asks for every unfinished plan's tasks at once (in the
    plans' order) and hands each its own outcomes; returns the plans' results, in order."""
    results: list = [None] * len(plans)
    pending: dict[int, list] = {}

    def advance(n: int, sent: list | None) -> None:
        try:
            pending[n] = plans[n].send(sent)
        except StopIteration as done:
            pending.pop(n, None)
            results[n] = done.value

    for n in range(len(plans)):
        advance(n, None)
    while pending:
        order = sorted(pending)
        outcomes = yield [task for n in order for task in pending[n]]
        at = 0
        for n in order:
            count = len(pending[n])
            advance(n, outcomes[at:at + count])
            at += count
    return results


def mapped(plan: Plan, convert: Callable[[Any], Any]) -> Plan:
    """The plan, with each outcome passed through ``convert`` before the plan sees it (a plan
    written for one kind of outcome driven by a loop that runs another)."""
    try:
        tasks = next(plan)
        while True:
            outcomes = yield tasks
            tasks = plan.send([convert(o) for o in outcomes])
    except StopIteration as done:
        return done.value
