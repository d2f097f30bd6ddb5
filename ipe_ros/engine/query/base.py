"""What a query is: what it reads from each rollout, when a rollout has decided it, how its
outcomes aggregate over samples, and which answer fields it fills.

A query never steps the physics. The rollout asks every query of the request for:

- ``decided_below_z``: per body, the height below which its outcome is decided (a box that has
  fallen has fallen), or None when the query needs the rollout to run until everything is at rest
  (it reads where bodies end up). Early termination is built from these: by heights only when every
  asked query has them, else at rest.
- ``watch``: a :class:`StepWatch` that looks at the world after every step (events such as "A
  touched B"); a rollout whose every query is decided by its watches may end before rest.
- ``early_stop``: the reading of rest the query needs (``rest`` asks for a strict one).
- ``read``: the rollout's values (a dict of plain values), from its :class:`Reading`.
- ``aggregate``: the answer's fields from the good samples (:class:`Samples`).
- ``describe`` / ``sample_columns``: lines for the CLI, per-sample values for the recordings.
- ``Parameters``: its own parameters, a frozen dataclass (fields with defaults, units in their
  names, ``metadata={"meaning": ...}``; its ``__post_init__`` refuses bad values naming
  ``"<query>.<field>"``). Read in ``read``/``aggregate`` as ``spec.parameters_of(name)``; the CLI
  (``--<query>-<field>``) and the node (parameter ``<query>.<field>``) set them (``query.parameters``).

Modules register one instance each (``query.register``); the name is what requests, the CLI and
the node's parameters spell.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar, Sequence

import numpy as np

from . import predicates
from ..scene.bodies import Scene
from ..results.stats import wilson_interval

from .spec import QuerySpec

if TYPE_CHECKING:
    from ..config import EarlyStopSettings
    from ..results.outcome import RolloutResult, SampleOutcome


def smallest_extents_m(scene: Scene) -> np.ndarray:
    """Each dynamic body's smallest extent, in scene order (the unit of the fall threshold)."""
    return np.array([b.smallest_extent_m for b in scene.dynamic_objects])


@dataclass
class Reading:
    """One rollout as a query reads it. Arrays follow ``scene.dynamic_objects``.

    initial_m / final_m: (n, 3) centres of mass at t = 0 (after separation) and at the end, metres;
    initial_orientations_xyzw / final_orientations_xyzw: (n, 4) (the initial ones None where a
    caller has none); final_speeds_m_s / final_spins_rad_s: (n,) at the end;
    events: what each query's watch recorded, by query name; ended_s: simulated seconds (below the
    horizon when early termination ended the rollout).
    """

    scene: Scene
    spec: "QuerySpec"
    initial_m: np.ndarray
    final_m: np.ndarray
    final_orientations_xyzw: np.ndarray
    final_speeds_m_s: np.ndarray | None
    final_spins_rad_s: np.ndarray | None
    events: dict[str, Any] = field(default_factory=dict)
    ended_s: float = 0.0
    initial_orientations_xyzw: np.ndarray | None = None

    @cached_property
    def smallest_extents_m(self) -> np.ndarray:
        return smallest_extents_m(self.scene)

    @cached_property
    def fallen(self) -> np.ndarray:
        """Per body: its centre dropped by more than the fall threshold (paper SI)."""
        return predicates.fallen_mask(self.initial_m, self.final_m, self.smallest_extents_m,
                                      self.spec.fall_threshold_fraction)


@dataclass(frozen=True)
class Samples:
    """The good samples of one prediction, as aggregation reads them."""

    scene: Scene
    spec: "QuerySpec"
    outcomes: Sequence["SampleOutcome"]
    deterministic: bool  # one rollout says everything: intervals are points
    #: the objects the rollouts' arrays follow, when not the scene's (a question's variant)
    object_names: tuple[str, ...] | None = None

    @property
    def rollouts(self) -> list["RolloutResult"]:
        return [r for o in self.outcomes for r in o.rollouts]

    @property
    def names(self) -> list[str]:
        if self.object_names is not None:
            return list(self.object_names)
        return [b.name for b in self.scene.dynamic_objects]

    def per_sample(self, value) -> np.ndarray:
        """``value(rollout)`` averaged over each sample's push magnitudes (samples are the units)."""
        return np.array([np.mean([value(r) for r in o.rollouts]) for o in self.outcomes], float)

    def fraction_interval(self, p: float) -> tuple[float, float]:
        """95% Wilson interval of a mean of per-sample fractions; a point when deterministic."""
        return (p, p) if self.deterministic else wilson_interval(p, len(self.outcomes))


class StepWatch:
    """Looks at a world after every step of a rollout."""

    def start(self, world) -> None:
        """At t = 0, before the first step."""

    def after_step(self, world, t_s: float) -> None:
        """After a step that ended at ``t_s``."""

    @property
    def decided(self) -> bool:
        """Nothing later in the rollout can change what this watch records."""
        return False

    def events(self) -> Any:
        """What it recorded (plain values: they travel between processes)."""
        return None


class Query:
    """One question about a rollout's outcome (see the module doc). Subclasses set the class
    attributes and override what they need."""

    name: ClassVar[str]
    #: the answer fields this query fills (JSON names; None in an answer that did not ask it)
    fields: ClassVar[tuple[str, ...]]
    #: one line for help texts
    summary: ClassVar[str] = ""
    #: the whole rollout's answer is decided once any body has fallen (any_fall)
    decided_by_first_fall: ClassVar[bool] = False
    #: the query's own parameters: a frozen dataclass whose every field has a default (None: none)
    Parameters: ClassVar[type | None] = None

    def check(self, scene: Scene, spec: "QuerySpec") -> None:
        """Refuse, with a ConfigError naming the field, what this scene cannot answer."""

    def decided_below_z(self, scene: Scene, spec: "QuerySpec", initial_m: np.ndarray) -> np.ndarray | None:
        """Per body, the height below which its outcome is decided; None: run until rest."""
        return None

    def watch(self, scene: Scene, spec: "QuerySpec", world) -> StepWatch | None:
        return None

    def early_stop(self, early_stop: "EarlyStopSettings", spec: "QuerySpec") -> "EarlyStopSettings":
        """The rest reading a rollout needs for this query (default: the preset's)."""
        return early_stop

    def read(self, reading: Reading) -> dict[str, Any]:
        raise NotImplementedError

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        raise NotImplementedError

    def flags(self, rollout: "RolloutResult") -> dict[str, Sequence[float]]:
        """This query's yes/no outcomes in one rollout (1/0), which the self-check compares between
        the fast and the reference physics, by the value they come from (queries reading the same
        value, as fall, direction and far read ``fallen``, give it under the same name and it is
        compared once); {} when the query was not asked or has no yes/no outcome."""
        return {}

    def describe(self, prediction) -> list[str]:
        """Lines for a human reading the answer (the CLI's table lists the paper's queries itself)."""
        return []

    def sample_columns(self, outcome) -> dict[str, float]:
        """One good sample's values, by column name, for the recordings' per-sample charts."""
        return {}
