"""What one Monte Carlo sample leaves behind: its rollouts' final states and query values
(:class:`RolloutResult`) and the sample's own record (:class:`SampleOutcome`). Plain data, read by
the queries, the estimate, the self-check and the store; made by ``rollout``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RolloutResult:
    """One simulated push magnitude of one sample. Arrays follow ``scene.dynamic_objects``.

    The built-in queries' values have fields of their own (None when not asked): ``fallen`` (fall,
    direction, far), ``any_fell``, ``direction_rad``, ``far_m``, ``fell_off`` and ``bump_ratio``
    (bump); every other query's are in ``extra`` (name, value) pairs, read with ``value(name)``.
    """

    phi_m_s2: float
    final_positions_m: np.ndarray
    final_orientations_xyzw: np.ndarray
    fallen: np.ndarray | None
    direction_rad: float | None
    far_m: float | None
    fell_off: np.ndarray | None
    bump_ratio: float | None
    trajectory: list | None = None
    simulated_s: float = 0.0  # simulated time; below the horizon when the rollout ended early
    any_fell: bool | None = None  # the any_fall query: did at least one body fall?
    energy_gain_j: float = 0.0  # the most energy gained beyond what the push and initial velocities put in
    penetration_fraction: float = 0.0  # the deepest any body ends inside another, / its smallest extent
    #: its collapse steps made energy and were undone (config.CollapseSettings.max_created_energy_fraction)
    collapse_undone: bool = False
    extra: tuple[tuple[str, object], ...] = ()

    def value(self, name: str):
        """A query's value in this rollout (KeyError naming it when it was not asked)."""
        for key, value in self.extra:
            if key == name:
                return value
        if name in OWN_FIELDS:
            return getattr(self, name)
        raise KeyError(f"{name}: not a value of this rollout (was its query asked?)")


#: the query values a RolloutResult keeps as fields of its own; every other query's go to ``extra``
OWN_FIELDS = frozenset({"fallen", "any_fell", "direction_rad", "far_m", "fell_off", "bump_ratio"})


@dataclass(frozen=True)
class SampleOutcome:
    """The result of one sample: its initial (noisy, separated) state and one result per phi value.

    A robot question's variant has one of these per sample too (``actions.variants``): its
    rollouts' arrays then follow ``names`` (the variant's objects: one removed, one added), and a
    variant not run in a sample (the scene fell as it is, or the variant was decided) is ``skipped``.
    """

    index: int
    ok: bool
    error: str | None
    push_direction_rad: float
    initial_positions_m: np.ndarray | None
    initial_orientations_xyzw: np.ndarray | None
    rollouts: tuple[RolloutResult, ...] = ()
    budget_stopped: bool = False  # cut off by the compute budget: neither used nor a failure
    worker_lost: bool = False  # its worker process died twice: a failure of the machine, not of the sample
    names: tuple[str, ...] | None = None  # the objects the rollouts' arrays follow (None: the task scene's)
    skipped: bool = False  # not run (a question's variant in a sample it did not need): neither used nor a failure
