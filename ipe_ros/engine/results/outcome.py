"""What one Monte Carlo sample leaves behind: its rollouts' final states and query values
(:class:`RolloutResult`) and the sample's own record (:class:`SampleOutcome`). Plain data, read by
the queries, the estimate, the self-check and the store; made by ``rollout``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

#: a rollout ending with a body deeper than this fraction of its smallest extent inside another, or
#: having gained more energy than this fraction of the scene's energy scale, ended unhealthy (the
#: self-check's defaults; ``SimSettings.rigid_when_unhealthy``)
HEALTHY_END_PENETRATION_FRACTION = 0.05
HEALTHY_ENERGY_GAIN_FRACTION = 0.01


@dataclass(frozen=True)
class RolloutResult:
    """One simulated push magnitude of one sample: the common fields every rollout has, and every
    asked query's values in one mapping (``values``: value name -> plain value, in the query
    registry's order; arrays follow ``scene.dynamic_objects``, or a question variant's ``names``).
    Read a value with ``value(name)`` (KeyError when its query was not asked) or ``get(name)``."""

    phi_m_s2: float
    final_positions_m: np.ndarray
    final_orientations_xyzw: np.ndarray
    values: Mapping[str, Any] = field(default_factory=dict)
    trajectory: list | None = None
    simulated_s: float = 0.0  # simulated time; below the horizon when the rollout ended early
    energy_gain_j: float = 0.0  # the most energy gained beyond what the push and initial velocities put in
    penetration_fraction: float = 0.0  # the deepest any body ends inside another, / its smallest extent
    #: its collapse steps made energy and were undone (config.CollapseSettings.max_created_energy_fraction)
    collapse_undone: bool = False

    def value(self, name: str) -> Any:
        """A query's value in this rollout (KeyError naming it when it was not asked)."""
        try:
            return self.values[name]
        except KeyError:
            raise KeyError(f"{name}: not a value of this rollout (was its query asked?)") from None

    def get(self, name: str, default: Any = None) -> Any:
        return self.values.get(name, default)

    @property
    def fallen(self) -> np.ndarray | None:
        """Which bodies fell (bool per body): the paper's predicate, which the fall, direction and far
        queries and every robot question read; None when none of them was asked."""
        return self.values.get("fallen")


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
    #: this sample rerun at the reference in the same task, because its rollout ended unhealthy
    #: (``rollout.Refine``); the self-check takes it out before the answer is made
    refined: SampleOutcome | None = None
    #: why this sample's rollout in multibodies was replaced by its rerun in plain rigid bodies at the
    #: same step ("energy", "penetration", "failed"; ``SimSettings.rigid_when_unhealthy``), or None
    rerun_rigid: str | None = None
    #: the uncertain properties' values this sample drew, ("owner.property", value) (``perturb.draw_sample``)
    properties: tuple[tuple[str, float], ...] = ()

    def unhealthy(self, energy_scale_j: float, max_end_penetration_fraction: float,
                  max_energy_gain_fraction: float) -> str | None:
        """Why this fast rollout cannot be trusted as it ended ("failed", "penetration", "energy"), or
        None when it can: a body ending deeper than the fraction of its smallest extent inside
        another, or energy gained beyond the fraction of the scene's ``energy_scale_j``."""
        if self.budget_stopped or self.worker_lost or self.skipped:
            return None  # not the physics' doing (or not run): counted as before
        if not self.ok:
            return "failed"
        for r in self.rollouts:
            if r.penetration_fraction > max_end_penetration_fraction:
                return "penetration"
            if r.energy_gain_j > max_energy_gain_fraction * energy_scale_j:
                return "energy"
        return None


def rigid_reruns(outcomes) -> int:
    """How many of these outcomes are reruns in plain rigid bodies (``SampleOutcome.rerun_rigid``)."""
    return sum(o.rerun_rigid is not None for o in outcomes)


def energy_scale_of(scene) -> float:
    """The scene's energy scale (weight x size + initial kinetic energy), never zero: what a
    rollout's energy gain is measured against."""
    from ..simulation.health import energy_scale_j  # here: the simulation package loads pybullet; plain data need not

    return max(energy_scale_j(scene), math.ulp(1.0))
