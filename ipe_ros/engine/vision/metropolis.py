"""One Metropolis-Hastings driver for single-update chains, its moves pluggable (emcee's split of
sampler and proposal).

A :class:`Kernel` proposes one update (drawing what it moves, with the chain's ``rng``) and returns
the log acceptance ratio (target and proposal terms); the driver draws the uniform that decides,
tells the kernel (``accept``), lets it adapt or make moves of its own (``after``), and keeps what
``keep`` returns for every sample after burn-in. ``check(sample)`` runs before each update (a
budget's deadline). The vision chain (``mcmc``) is a kernel; a new perception's chain is one more.
The depth chain (``depth_chain``) scores its proposals in batches, which this driver's one update
at a time cannot, and has a sampler of its own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np


class Kernel(Protocol):
    def propose(self, sample: int, rng: np.random.Generator) -> float:
        """Draw update ``sample``'s proposal; its log acceptance ratio."""

    def accept(self) -> None:
        """Take the pending proposal."""

    def after(self, sample: int, accepted: bool, rng: np.random.Generator) -> None:
        """After each update: adapt, or make moves of the kernel's own."""


@dataclass(frozen=True)
class Run:
    """What a chain kept: ``kept[i]`` after update ``burn_in + i``; every update's outcome."""

    kept: list
    accepted: np.ndarray  # (updates,) bool, burn-in included

    @property
    def acceptance_rate(self) -> float:
        return float(self.accepted.mean()) if len(self.accepted) else 0.0


def run_metropolis(kernel: Kernel, updates: int, burn_in: int, rng: np.random.Generator, keep: Callable[[], Any],
                   check: Callable[[int], None] | None = None) -> Run:
    """``updates`` Metropolis-Hastings updates of ``kernel``; what ``keep()`` says after each one past
    ``burn_in``."""
    accepted = np.zeros(updates, bool)
    kept = []
    for sample in range(updates):
        if check is not None:
            check(sample)
        ratio = kernel.propose(sample, rng)
        if np.log(rng.random()) < ratio:
            kernel.accept()
            accepted[sample] = True
        kernel.after(sample, bool(accepted[sample]), rng)
        if sample >= burn_in:
            kept.append(keep())
    return Run(kept, accepted)


def thinned_index(samples: int, k: int) -> np.ndarray:
    """k sample indices spread evenly over a chain of ``samples`` (k <= samples)."""
    return np.linspace(0, samples - 1, k).round().astype(int)
