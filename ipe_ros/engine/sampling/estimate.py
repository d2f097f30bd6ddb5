"""Aggregation over samples (paper Eq. S5): the answer, its common fields and each query's own.

Samples are the independent units: when several push magnitudes are simulated per sample, their
results are averaged within the sample first (each query's ``aggregate``, engine/query).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Generic, Optional, Sequence, TypeVar

from ..query import QUERIES, QuerySpec, Samples, answer_fields
from ..query.any_fall import sample_any_fall  # noqa: F401 - re-exported
from ..query.fall import sample_fall_fraction  # noqa: F401 - re-exported
from ..query.far import sample_far_m  # noqa: F401 - re-exported
from .influence import property_influence
from ..results.outcome import SampleOutcome
from ..scene.bodies import Scene
from ..results.stats import Z95, circular_mean, half_circle_decisiveness, mean_interval, wilson_interval  # noqa: F401

# kept importable from here: the per-sample values and the statistics the answers are made of
__all__ = ["Prediction", "Z95", "aggregate", "circular_mean", "half_circle_decisiveness", "mean_interval",
           "sample_any_fall", "sample_fall_fraction", "sample_far_m", "wilson_interval"]


T = TypeVar("T")
Interval = Optional[tuple[float, float]]
PerObject = Optional[dict[str, float]]


class QueryValue(Generic[T]):
    """A built-in query's answer field on ``Prediction``, typed: its value in ``answers`` (None when
    its query was not asked). A plugin query's fields are read with ``Prediction.value``."""

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, prediction, owner=None) -> T:
        if prediction is None:
            return self  # type: ignore[return-value] - the class's own attribute
        return prediction.answers.get(self.name)


@dataclass(frozen=True)
class Prediction:
    """The IPE's answer for one scene: what every answer has, and one answer per asked query.

    ``answers`` holds the asked queries' fields (engine/query: one module per query, each listing
    its fields); each built-in query's field is a typed attribute (``QueryValue``), None when its
    query was not asked; a plugin query's, ``value(field)``. The built-in ones:

    fall_fraction: expected fraction of dynamic boxes that fall (Exps. 1, 3), with its 95% interval
        ``fall_fraction_ci95`` (Wilson; a point for the deterministic ground truth) and
        ``object_fall_probability`` per box.
    any_fall_probability: probability that at least one box falls, ``any_fall_probability_ci95``.
    direction_rad / direction_decisiveness: circular mean of the fall directions (Exps. 2, 4), the
        largest share of them inside one half circle.
    far_m: expected largest horizontal distance of a fallen box from the tower base (Exp. S2).
    fell_off_fraction_by_group / bump_ratio: what falls off a bumped table (Exp. 5).
    contact_probability / contact_time_s: P(A touches B) per asked pair, median first contact.
    rest_probability / max_final_speed_m_s: P(everything at rest at the end), largest speed left.
    final_pose: per object, mean and spread of its final position and yaw.
    tipped_probability / tipped_object_probability: P(some object ends tipped over), per object.

    stopped_by: what ended sampling: "samples" (all k), "ci_width" / "deadline" (anytime sampling),
        or "budget" (the compute budget ran out: ``samples`` says how many were used; the samples cut
        off are ``budget_skipped_samples``, neither used nor counted as failed).
    """

    scene: str
    samples: int
    samples_requested: int
    failed_samples: int
    failure_reasons: tuple[str, ...]
    deterministic: bool
    answers: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0
    stopped_by: str = "samples"  # "samples" (all k drawn), "ci_width", "deadline" (anytime sampling), "budget"
    budget_skipped_samples: int = 0
    max_penetration_fraction: float | None = None
    max_energy_gain_j: float | None = None
    #: rollouts whose collapse steps made energy and were undone (run on at the fine step instead)
    collapse_undone_rollouts: int = 0
    #: the self-check's verdict (engine.checking.fidelity.VERDICTS): "verified", "escalated", "contradicted",
    #: "unverified" or "reference"; ``refined_samples``: rollouts rerun at the reference because they
    #: ended unhealthy; ``self_check``: what ran at which settings (FidelityReport.to_dict()).
    fidelity: str | None = None
    refined_samples: int = 0
    self_check: dict[str, Any] | None = None
    request: dict[str, Any] = field(default_factory=dict)
    #: per uncertain mass, friction or restitution, strongest first: how much the samples drawing it
    #: above its median differ from those below (``sampling.influence``); None: none uncertain
    property_influence: tuple[dict, ...] | None = None
    outcomes: tuple[SampleOutcome, ...] = field(default=(), repr=False, compare=False)
    #: the perception's posterior the samples started from (``engine.perceptions``; None: the
    #: model's own noise); summarised in ``request["perception"]``, kept whole for recordings
    perceived: Any = field(default=None, repr=False, compare=False)

    # the built-in queries' answers (engine/query/*.py, ``fields``), typed; a test keeps them complete
    fall_fraction = QueryValue[Optional[float]]()
    fall_fraction_ci95 = QueryValue[Interval]()
    object_fall_probability = QueryValue[PerObject]()
    any_fall_probability = QueryValue[Optional[float]]()
    any_fall_probability_ci95 = QueryValue[Interval]()
    direction_rad = QueryValue[Optional[float]]()
    direction_decisiveness = QueryValue[Optional[float]]()
    direction_rollouts = QueryValue[Optional[int]]()
    far_m = QueryValue[Optional[float]]()
    far_m_ci95 = QueryValue[Interval]()
    fell_off_fraction_by_group = QueryValue[PerObject]()
    bump_group = QueryValue[Optional[str]]()
    bump_ratio = QueryValue[Optional[float]]()
    bump_rollouts = QueryValue[Optional[int]]()
    contact_probability = QueryValue[PerObject]()
    contact_probability_ci95 = QueryValue[Optional[dict[str, list[float]]]]()
    contact_time_s = QueryValue[Optional[dict[str, Optional[float]]]]()
    contact_at_start = QueryValue[Optional[list[str]]]()
    rest_probability = QueryValue[Optional[float]]()
    rest_probability_ci95 = QueryValue[Interval]()
    max_final_speed_m_s = QueryValue[Optional[float]]()
    final_pose = QueryValue[Optional[dict[str, dict[str, Any]]]]()
    tipped_probability = QueryValue[Optional[float]]()
    tipped_probability_ci95 = QueryValue[Interval]()
    tipped_object_probability = QueryValue[PerObject]()

    def __post_init__(self) -> None:
        unknown = sorted(set(self.answers) - set(answer_fields()))
        if unknown:
            raise TypeError(f"{unknown[0]}: not a field of any query (engine/query)")

    def value(self, name: str) -> Any:
        """The answer field ``name`` of any registered query (a plugin's too), None when its query was
        not asked; a ValueError for a name no query answers."""
        if name not in answer_fields():
            raise ValueError(f"{name!r} is not a field of any registered query (engine/query); ask one of "
                             f"{', '.join(answer_fields())}")
        return self.answers.get(name)

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready fields (everything but the raw outcomes and the perceived scenes; every query's fields, None where
        it was not asked)."""
        out: dict[str, Any] = {}
        for name in self.__dataclass_fields__:
            if name == "answers":
                for key in answer_fields():
                    value = self.answers.get(key)
                    out[key] = list(value) if isinstance(value, tuple) else value
            elif name not in ("outcomes", "perceived"):
                out[name] = getattr(self, name)
        out["failure_reasons"] = list(out["failure_reasons"])
        if self.property_influence is None:  # a scene with every property exact answers as it always did
            del out["property_influence"]
        else:
            out["property_influence"] = list(self.property_influence)
        return out


def aggregate(scene: Scene, outcomes: Sequence[SampleOutcome], *, query: QuerySpec, deterministic: bool,
              samples_requested: int, wall_s: float, request: dict[str, Any]) -> Prediction:
    """Combine per-sample outcomes into a :class:`Prediction` (failed samples are counted, not used)."""
    ok = [o for o in outcomes if o.ok]
    skipped = [o for o in outcomes if o.budget_stopped]
    failed = [o for o in outcomes if not o.ok and not o.budget_stopped]
    reasons = tuple(dict.fromkeys(o.error or "unknown" for o in failed))[:5]
    base = dict(scene=scene.name, samples=len(ok), samples_requested=samples_requested,
                failed_samples=len(failed), failure_reasons=reasons, deterministic=deterministic,
                wall_s=wall_s, request=request, outcomes=tuple(outcomes), budget_skipped_samples=len(skipped))
    if skipped:
        base["stopped_by"] = "budget"
    if not ok:
        return Prediction(**base)
    rollouts = [r for o in ok for r in o.rollouts]
    samples = Samples(scene=scene, spec=query, outcomes=ok, deterministic=deterministic)
    answers: dict[str, Any] = {}
    for name, asked in QUERIES.items():  # in the registry's order
        if name in query.queries:
            answers.update(asked.aggregate(samples))
    return Prediction(**base, answers=answers, property_influence=property_influence(scene, ok),
                      max_penetration_fraction=float(max(r.penetration_fraction for r in rollouts)),
                      max_energy_gain_j=float(max(r.energy_gain_j for r in rollouts)),
                      collapse_undone_rollouts=sum(r.collapse_undone for r in rollouts))
