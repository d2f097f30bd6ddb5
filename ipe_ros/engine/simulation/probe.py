"""Watching a rollout's parts without changing it: the hook the time-budget benchmark uses."""

from __future__ import annotations

import contextlib
from typing import Callable, Iterator

#: The step a pybullet step ran at: settling substeps, the fine step, or a collapse step.
PHASES = ("settle", "fine", "collapse")


class Probe:
    """Does nothing; subclass it to time or count (benchmarks/time_budget.py).

    ``part(name)`` wraps a part of a sample ("build", "depenetrate"); ``step(phase, run)`` must call
    ``run()`` exactly once: it is one pybullet step of the given phase.
    """

    @contextlib.contextmanager
    def part(self, name: str) -> Iterator[None]:
        yield

    def step(self, phase: str, run: Callable[[], None]) -> None:
        run()


NO_PROBE = Probe()
