"""What each variant does to the scene, over all samples and over those in which the scene as it
is stands; a question's answers together."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import ModelConfig
from ..sampling.estimate import circular_mean, wilson_interval
from ..sampling.perturb import is_deterministic
from ..query import QUERIES, QuerySpec, Samples
from ..scene.bodies import Scene
from .kinds import Action, Place, Push
from ..results.outcome import RolloutResult, SampleOutcome


# -- the answers ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VariantAnswer:
    """What one variant of a question does to the scene.

    any_fall_probability: P(at least one object falls), objects the action removed not counted;
        with its 95% Wilson interval.
    object_fall_probability: per remaining (or added) object; None when the question did not ask
        what falls (``ask(what_falls=False)``: its rollouts end at the first fall, which decides
        "does anything fall?" exactly but leaves open what else would have).
    simulated: False when the answer was read from the scene's own samples because the action
        cannot change anything (a removal that nothing rests on).
    samples / failed_samples: samples used / samples whose rollout failed (budget cuts are neither).
    """

    label: str
    action: Action
    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    object_fall_probability: dict[str, float] | None
    direction_rad: float | None
    samples: int
    failed_samples: int
    simulated: bool = True
    not_simulated: tuple[str, ...] = ()  # objects the action cannot reach, left out of its rollouts
    #: per object, P(it falls with the action and would not have without): sample s of the variant
    #: against sample s of the scene as is (common random numbers make this pairing meaningful);
    #: None when what falls was not asked
    caused_fall_probability: dict[str, float] | None = None
    #: the same answer over only the samples in which the scene as it is stands (nothing falls without
    #: the action): what the action does, apart from what falls anyway; None without an "as is" variant
    given_stands: "GivenStands | None" = None
    #: per object, P(it ends off the table: its centre below the top); asked with fell_off
    fell_off_probability: dict[str, float] | None = None
    any_fell_off_probability: float | None = None
    #: answered sequentially (``decide.Sequential``): what the rule decided ("safe", "unsafe",
    #: "ranked out", "best"; None: undecided) and why sampling stopped ("decided"; "cap"; "undecidable":
    #: no outcome of the samples left before the cap could decide it, ``decide``; "budget");
    #: the variant was then simulated only in samples where the scene as it is stands, so its
    #: probabilities are over those (equal to ``given_stands``)
    decision: str | None = None
    stopped_by: str | None = None
    samples_drawn: int | None = None  # samples 0..n-1 were drawn for it (it ran in those that stood)
    #: asked with contact pairs: per pair "A:B", P(they touch within the horizon), its 95% interval,
    #: and the median first-contact time over the samples in which they touch (engine/query/contact.py)
    contact_probability: dict[str, float] | None = None
    contact_probability_ci95: dict[str, list[float]] | None = None
    contact_time_s: dict[str, float | None] | None = None
    #: asked with other queries (``ask(queries=...)``): their answer fields, as a prediction's
    #: (``Query.aggregate`` over the variant's samples); written flat into the variant's JSON
    query_answers: dict[str, Any] | None = None
    #: the self-check of the variant's samples (``engine.checking.fidelity``): "verified", "escalated" (the
    #: answer is the reference physics'), "contradicted", "unverified" (not checked: the default for
    #: questions), "reference" (the settings are the reference's own); None: not simulated.
    #: ``self_check``: what it did (FidelityReport.to_dict)
    fidelity: str | None = None
    self_check: dict | None = None

    def to_dict(self) -> dict:
        off = {} if self.fell_off_probability is None else {
            "fell_off_probability": self.fell_off_probability, "any_fell_off_probability": self.any_fell_off_probability}
        return {"label": self.label, "any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "object_fall_probability": self.object_fall_probability, "direction_rad": self.direction_rad,
                "samples": self.samples, "failed_samples": self.failed_samples, "simulated": self.simulated,
                "not_simulated": list(self.not_simulated), "caused_fall_probability": self.caused_fall_probability,
                "given_stands": None if self.given_stands is None else self.given_stands.to_dict(), **off,
                **({} if self.stopped_by is None else {"decision": self.decision, "stopped_by": self.stopped_by,
                                                       "samples_drawn": self.samples_drawn}),
                **({} if self.contact_probability is None else {
                    "contact_probability": self.contact_probability,
                    "contact_probability_ci95": self.contact_probability_ci95, "contact_time_s": self.contact_time_s}),
                **{k: list(v) if isinstance(v, tuple) else v for k, v in (self.query_answers or {}).items()},
                **({} if self.fidelity is None else {"fidelity": self.fidelity, "self_check": self.self_check})}


@dataclass(frozen=True)
class GivenStands:
    """A variant's answer conditioned on the scene standing as it is: over the ``samples`` samples in
    which nothing fell without the action (common random numbers pair sample s of every variant),
    P(anything falls with the action) with its 95% Wilson interval, and per object. None values when
    no sample stood (the scene falls by itself whatever is done)."""

    samples: int
    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    object_fall_probability: dict[str, float] | None  # None: what falls was not asked

    def to_dict(self) -> dict:
        return {"samples": self.samples, "any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "object_fall_probability": self.object_fall_probability}


def _listed(interval: tuple[float, float] | None) -> list[float] | None:
    """An interval as JSON writes it."""
    return None if interval is None else list(interval)


#: the queries every question answers in fields of its own (what falls, where, what fell off, what
#: touched); any other registered query asked of a question answers in ``query_answers``
QUESTION_QUERIES = frozenset({"fall", "any_fall", "direction", "bump", "contact"})


def draws_noise(scene: Scene, action: Action, model: ModelConfig) -> bool:
    """The action has randomness of its own: a push's uncertainty, a placed object's noise."""
    if isinstance(action, Push):
        return bool(action.direction_sigma_rad or action.speed_sigma_fraction)
    if isinstance(action, Place):
        return not is_deterministic(dataclasses.replace(scene, objects=(action.body,)), model)
    return False


def ran(outcome: SampleOutcome) -> RolloutResult:
    """A variant's rollout in one sample (actions are asked with one push magnitude)."""
    return outcome.rollouts[-1]


def fell(result: RolloutResult) -> bool:
    """Anything fell in this rollout: from the per-object flags, or from the yes/no answer where
    only that was asked (the rollout then ended at the first fall)."""
    return bool(np.any(result.fallen)) if result.fallen is not None else bool(result.value("any_fell"))


def aggregate_variant(label: str, action: Action, results: list[SampleOutcome], simulated: bool = True, *,
                      deterministic: bool = False, scene: Scene | None = None,
                      query: QuerySpec | None = None) -> VariantAnswer:
    """``deterministic``: nothing was drawn, so the one sample's answer is exact (a point, not an
    interval). ``scene``, ``query``: the question's, for the answers its queries aggregate themselves
    (contact)."""
    ok = [r for r in results if r.ok]
    failed = [r for r in results if not r.ok and not r.budget_stopped and not r.skipped]
    if not ok:
        return VariantAnswer(label, action, None, None, {}, None, 0, len(failed), simulated)
    names = ok[0].names
    anything = float(np.mean([fell(ran(r)) for r in ok]))
    objects = None
    if ran(ok[0]).fallen is not None:
        fallen = np.array([ran(r).fallen for r in ok], bool)
        objects = {n: float(p) for n, p in zip(names, fallen.mean(axis=0))}
    directions = np.array([ran(r).get("direction_rad") for r in ok if ran(r).get("direction_rad") is not None])
    interval = (anything, anything) if deterministic else wilson_interval(anything, len(ok))
    off = {}
    if ran(ok[0]).get("fell_off") is not None:
        fell_off = np.array([ran(r).get("fell_off") for r in ok], bool)
        off = dict(fell_off_probability={n: float(p) for n, p in zip(names, fell_off.mean(axis=0))},
                   any_fell_off_probability=float(fell_off.any(axis=1).mean()))
    if query is not None and "contact" in query.queries:
        contact = QUERIES["contact"].aggregate(Samples(scene, query, ok, deterministic, names))
        off.update({name: contact[name] for name in ("contact_probability", "contact_probability_ci95",
                                                     "contact_time_s")})
    others = {} if query is None else {
        name: q for name, q in QUERIES.items() if name in query.queries and name not in QUESTION_QUERIES}
    if others:  # every other asked query answers as it does in a prediction
        off["query_answers"] = {}
        for q in others.values():
            off["query_answers"].update(q.aggregate(Samples(scene, query, ok, deterministic, names)))
    return VariantAnswer(label, action, anything, interval, objects, circular_mean(directions), len(ok), len(failed),
                         simulated, **off)


def stood(alone: SampleOutcome) -> bool:
    """The scene as it is ran without failing and nothing in it fell."""
    return alone.ok and not fell(ran(alone))


def aggregate_given(results: list[SampleOutcome], *, deterministic: bool) -> GivenStands:
    """A variant's results over the samples in which the scene stands as it is."""
    answer = aggregate_variant("", None, results, deterministic=deterministic)
    return GivenStands(answer.samples, answer.any_fall_probability, answer.any_fall_probability_ci95,
                       answer.object_fall_probability)


@dataclass(frozen=True)
class Answers:
    """The variants of one question, in the order asked, and what they cost."""

    scene: str
    variants: tuple[VariantAnswer, ...]
    samples_requested: int
    wall_s: float
    stopped_by: str = "samples"
    #: label -> [(sample index, the variant's result with its trajectory)] for recorded samples
    recorded: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)
    #: the scene left alone (None when no variant is "as is")
    alone: "Alone | None" = None

    def to_dict(self) -> dict:
        return {"scene": self.scene, "variants": [v.to_dict() for v in self.variants],
                "samples_requested": self.samples_requested, "wall_s": self.wall_s, "stopped_by": self.stopped_by,
                "alone": None if self.alone is None else self.alone.to_dict()}


@dataclass(frozen=True)
class Alone:
    """The scene left alone: P(anything falls by itself) with its 95% interval, the samples in which
    it stands (those every ``given_stands`` answer is over), and ``unstable``: it falls by itself
    more often than ``safe_below`` even at the low end of the interval. Whatever the robot does
    then, things may fall that its action did not make fall."""

    any_fall_probability: float | None
    any_fall_probability_ci95: tuple[float, float] | None
    samples_standing: int
    unstable: bool

    def to_dict(self) -> dict:
        return {"any_fall_probability": self.any_fall_probability,
                "any_fall_probability_ci95": _listed(self.any_fall_probability_ci95),
                "samples_standing": self.samples_standing, "unstable": self.unstable}


def caused(per_sample: list[list[SampleOutcome]], variant: int, as_is: int) -> dict[str, float] | None:
    """Per object of the variant: the fraction of paired samples in which it fell with the action
    and not in the scene as is (None: what falls was not asked)."""
    pairs = [(s[variant], s[as_is]) for s in per_sample if s[variant].ok and s[as_is].ok]
    if not pairs or any(ran(outcome).fallen is None for outcome in pairs[0]):
        return None
    names = pairs[0][0].names
    counts = dict.fromkeys(names, 0)
    for with_action, without in pairs:
        before = dict(zip(without.names, ran(without).fallen))
        for name, fallen in zip(with_action.names, ran(with_action).fallen):
            counts[name] += bool(fallen) and not before.get(name, False)
    return {n: c / len(pairs) for n, c in counts.items()}
