"""The questions built on ``ask``: what falls if objects are removed, what supports what, an
order to clear the scene, where to place a new object, what a push does; and a question given as
data is a ``question.Question``."""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..scene import limits
from ..config import ModelConfig, SimSettings
from ..sampling.decide import Ranking, SafeBelow, Sequential, Supports
from ..errors import ConfigError
from ..sampling.montecarlo import check_budget, far_over_budget
from ..predict import Context, Request, rollout_cost
from ..query import QUERIES, QuerySpec
from ..query.parameters import spec_parameters
from ..query.spec import check_names
from ..scene.bodies import Body, Scene
from ..scene.validation import validate_body
from .answers import Answers, VariantAnswer
from .ask import ask
from .answers import QUESTION_QUERIES
from .geometry import geometry_world, dependents, resting_on
from .kinds import (DEFAULT_SAFE_BELOW, DEFAULT_SUPPORT_THRESHOLD, NO_OBJECTS, Action, Place, Push, Region, Remove,
                    check_level)



# -- the questions ----------------------------------------------------------------------------------------
def remove(scene: Scene, names: list[str] | None, model: ModelConfig, settings: SimSettings,
           safe_below: float | None = None, sequential: bool = True, what_falls: bool | None = None,
           **kw) -> Answers:
    """P(anything else falls) and per-object probabilities if each named object (None: every
    dynamic object, one at a time) is taken away; the scene as it is comes first. ``safe_below``:
    "is it safe to take?" - each removal decided safe or unsafe at this level, sampled until decided
    (``sequential``; False: the full k for every removal). ``what_falls``: also which objects fall
    (default: without ``safe_below`` only; the decision reads "does anything fall?", and rollouts
    that need not say what else falls end at the first fall, ``ask``)."""
    rule = None
    if safe_below is not None:
        check_level("safe_below", safe_below)
        rule = Sequential(SafeBelow(safe_below)) if sequential else None
    if what_falls is None:
        what_falls = safe_below is None
    return _ask(scene, _removals(scene, names), model, settings, sequential=rule, what_falls=what_falls, **kw)


def check_extra_queries(queries: tuple[str, ...]) -> None:
    """A question's other queries: registered ones, none of those the question answers itself."""
    for name in queries:
        if name in QUESTION_QUERIES:
            raise ConfigError("queries", f"{name} is answered by the question itself (fell_off, contact, what_falls "
                                         "ask for it); list other queries: "
                              + ", ".join(q for q in QUERIES if q not in QUESTION_QUERIES))
    if queries:
        check_names(frozenset(queries))


def question_spec(*, what_falls: bool = True, directions: bool = False, fell_off: bool = False,
                  contact: tuple[tuple[str, str], ...] = (), queries: tuple[str, ...] = (),
                  query_parameters: Mapping[str, Any] | None = None,
                  fall_threshold_fraction: float = 0.125) -> QuerySpec:
    """The ``QuerySpec`` a question asks (``ask``'s ``request.query``): what falls (``fall``) or only
    whether anything does (``any_fall``), where (``direction``), what falls off the table (``bump``),
    contacts, and other registered queries with their parameters (``"<query>.<field>"``)."""
    check_extra_queries(tuple(queries))
    asked = frozenset({"fall" if what_falls else "any_fall"} | ({"direction"} if directions else set())
                      | ({"bump"} if fell_off else set()) | ({"contact"} if contact else set()) | set(queries))
    return QuerySpec(queries=asked, fall_threshold_fraction=fall_threshold_fraction, contact_pairs=tuple(contact),
                     parameters=spec_parameters(asked, query_parameters or {}))


def _ask(scene: Scene, actions: list[Action], model: ModelConfig, settings: SimSettings, *, seed: int = 0,
         map_fn=None, budget_s: float | None = None, fall_threshold_fraction: float = 0.125, record_every: int = 0,
         record_samples: int = 0, directions: bool = False, fell_off: bool = False,
         sequential: Sequential | None = None, on_progress=None, contact: tuple[tuple[str, str], ...] = (),
         check=None, what_falls: bool = True, queries: tuple[str, ...] = (), query_parameters=None,
         perceived=None) -> Answers:
    """The questions' keywords (``ipe ask``'s options, ``~/ask``'s fields) as ``ask``'s request and
    context: the question's queries in its QuerySpec (``question_spec``), unchecked and unbudgeted
    unless asked."""
    spec = question_spec(what_falls=what_falls, directions=directions, fell_off=fell_off, contact=tuple(contact),
                         queries=tuple(queries), query_parameters=query_parameters,
                         fall_threshold_fraction=fall_threshold_fraction)
    request = Request(model=model, settings=settings, query=spec, seed=seed, stop=sequential, budget_s=budget_s,
                      check=check)
    return ask(scene, actions, request, Context(map_fn=map_fn, record_every=record_every,
                                                record_samples=record_samples, on_progress=on_progress,
                                                perceived=perceived))


def _removals(scene: Scene, names: list[str] | None) -> list[Action]:
    """The scene as it is, then each named object (None: every dynamic one) taken away on its own."""
    if names is not None and not names:
        raise ConfigError("objects", NO_OBJECTS)
    names = [b.name for b in scene.dynamic_objects] if names is None else list(names)
    return [None] + [Remove((n,)) for n in names]


#: Estimated seconds to lower one candidate placement onto what is below it (measured 2-8 ms).
PLACEMENT_GEOMETRY_S = 0.01


class _Deadline:
    """A question's wall-clock budget, started when it is asked: everything before the simulation
    (geometry for placements, earlier steps of a clearing order) spends from it too."""

    def __init__(self, budget_s: float | None):
        check_budget(budget_s)
        self.budget_s = budget_s
        self.at_unix_s = None if budget_s is None else time.time() + budget_s

    def remaining_s(self) -> float | None:
        return None if self.at_unix_s is None else self.at_unix_s - time.time()

    def passed(self) -> bool:
        return self.at_unix_s is not None and time.time() >= self.at_unix_s


def _check_variants(scene: Scene, variants: int, model: ModelConfig, settings: SimSettings, budget_s: float | None,
                    what: str, field: str, placements: int = 0) -> None:
    """Refuse up front, before any geometry or simulation: more variants than a question may ask,
    or one sample of each (plus lowering the placements) estimated far beyond the budget."""
    if variants > limits.MAX_QUESTION_VARIANTS:
        raise ConfigError(field, f"{what} make {variants} variants, more than the {limits.MAX_QUESTION_VARIANTS} one "
                                 "question may ask about; split the search into several questions")
    if budget_s is not None:
        seconds = rollout_cost(scene, model, settings).seconds * (variants + 1) + placements * PLACEMENT_GEOMETRY_S
        if far_over_budget(seconds, budget_s):
            raise ConfigError("budget_s", f"one sample of these {variants + 1} variants takes up to ~{seconds:.3g} s, "
                                          f"far more than the budget of {budget_s:g} s; ask fewer variants or raise the "
                                          "budget")


@dataclass(frozen=True)
class SupportGraph:
    """What holds what, apart from what falls anyway: every P below is over the samples in which the
    scene as it is stands (``answers.alone.samples_standing`` of them; common random numbers pair
    the samples). ``edges``: (supporter, supported, P) where P, at or above ``threshold``, is the
    probability that the supported object falls without the supporter; ``safe``: objects whose
    removal leaves P(anything else falls) below ``safe_below`` (the upper end of its 95% interval
    reported with it). ``answers.alone.unstable``: the scene falls by itself too often to leave
    alone; with no sample standing, there are no edges and nothing is safe."""

    scene: str
    edges: tuple[tuple[str, str, float], ...]
    safe: tuple[tuple[str, float, float], ...]
    threshold: float
    safe_below: float
    answers: Answers

    def to_dict(self) -> dict:
        return {"scene": self.scene, "edges": [list(e) for e in self.edges],
                "safe_to_remove": [{"name": n, "p_anything_falls": p, "ci95_high": hi} for n, p, hi in self.safe],
                "threshold": self.threshold, "safe_below": self.safe_below, "answers": self.answers.to_dict()}


def support_graph(scene: Scene, model: ModelConfig, settings: SimSettings, threshold: float = DEFAULT_SUPPORT_THRESHOLD,
                  safe_below: float = DEFAULT_SAFE_BELOW, sequential: bool = True, **kw) -> SupportGraph:
    """``sequential``: sample each removal until its edges and its safety are decided (False: the
    full k for every removal)."""
    for name, value in (("threshold", threshold), ("safe_below", safe_below)):
        check_level(name, value)
    answers = _ask(scene, _removals(scene, None), model, settings,
                  sequential=Sequential(Supports(threshold, safe_below)) if sequential else None, **kw)
    edges, safe = [], []
    for variant in answers.variants[1:]:
        (removed,) = variant.action.names
        given = variant.given_stands
        if given is None or given.any_fall_probability is None:
            continue
        # "removing i makes j fall": j falls without i in the samples where nothing falls with it
        for name, p in given.object_fall_probability.items():
            if p >= threshold:
                edges.append((removed, name, p))
        if given.any_fall_probability < safe_below:
            safe.append((removed, given.any_fall_probability, given.any_fall_probability_ci95[1]))
    return SupportGraph(scene.name, tuple(edges), tuple(safe), threshold, safe_below, answers)


@dataclass(frozen=True)
class ClearStep:
    name: str
    p_anything_falls: float
    ci95: tuple[float, float]


@dataclass(frozen=True)
class ClearOrder:
    """Objects in the order to take them away, each step's risk, and the total
    1 - prod(1 - risk): the chance that some step makes something fall."""

    scene: str
    steps: tuple[ClearStep, ...]
    total_risk: float
    target: str | None
    stopped_by: str = "done"  # "budget": the steps so far are all the budget held (the order is incomplete)

    def to_dict(self) -> dict:
        return {"scene": self.scene, "target": self.target, "total_risk": self.total_risk, "stopped_by": self.stopped_by,
                "steps": [{"remove": s.name, "p_anything_falls": s.p_anything_falls, "ci95": list(s.ci95)}
                          for s in self.steps]}


def clear_order(scene: Scene, model: ModelConfig, settings: SimSettings, target: str | None = None,
                sequential: bool = True, **kw) -> ClearOrder:
    """Greedy disassembly: at each step take away the object whose removal is least likely to make
    anything else fall (ties: the highest first). With ``target``, only the target and what rests
    on it (directly or through others) are candidates, and the sequence ends when the target is gone.
    ``sequential``: each step samples its candidates until all but the least risky are ranked out."""
    if target is not None and target not in {b.name for b in scene.dynamic_objects}:
        raise ConfigError("target", f"no dynamic object named {target!r} in {scene.name!r}")
    deadline = _Deadline(kw.pop("budget_s", None))  # one budget for every step, not one each
    steps: list[ClearStep] = []
    current = scene
    stopped_by = "done"
    while True:
        candidates = [b.name for b in current.dynamic_objects]
        if target is not None:
            resting = resting_on(current)
            candidates = [target] + sorted(dependents(resting, target))
        if len(current.dynamic_objects) == 1:
            only = current.dynamic_objects[0].name
            steps.append(ClearStep(only, 0.0, (0.0, 0.0)))
            break
        if deadline.passed():
            stopped_by = "budget"
            break
        try:
            # each step is ranked on "does anything fall?" alone
            answers = _ask(current, _removals(current, candidates), model, settings, budget_s=deadline.remaining_s(),
                          sequential=Sequential(Ranking()) if sequential else None, what_falls=False, **kw)
        except ConfigError as exc:
            if exc.field != "budget_s" or not steps:  # the first step must fit: refused as any question
                raise
            stopped_by = "budget"  # what is left of the budget does not hold the next step
            break
        if answers.stopped_by == "budget":  # a step decided on fewer samples than asked is not decided
            stopped_by = "budget"
            break
        heights = {b.name: b.centre_of_mass_m[2] for b in current.dynamic_objects}
        best = min(answers.variants[1:], key=lambda v: (_rank_key(v), -heights[v.action.names[0]]))
        (name,) = best.action.names
        steps.append(ClearStep(name, best.any_fall_probability or 0.0, best.any_fall_probability_ci95 or (0.0, 1.0)))
        current = _without(current, name)
        if kw.get("perceived") is not None:  # the posterior's scenes lose it too
            kw["perceived"] = PerceivedAfter(tuple(_without(s, name) for s in kw["perceived"].scenes))
        if name == target or not current.dynamic_objects:
            break
    total = 1 - float(np.prod([1 - s.p_anything_falls for s in steps]))
    return ClearOrder(scene.name, tuple(steps), total, target, stopped_by)


def _without(scene: Scene, name: str) -> Scene:
    return dataclasses.replace(scene, objects=tuple(b for b in scene.objects if b.name != name))


@dataclass(frozen=True)
class PerceivedAfter:
    """A posterior's scenes after the steps taken so far (``clear_order``: objects taken away)."""

    scenes: tuple[Scene, ...]


def place(scene: Scene, bodies: list[Body], model: ModelConfig, settings: SimSettings, sequential: bool = True,
          what_falls: bool = False, **kw) -> Answers:
    """P(anything falls, the new object included) for each candidate placement (one object each);
    the scene as it is comes first. ``sequential``: sample the candidates until all but the least
    risky are ranked out (ties run until no further sample could separate them, at most k).
    ``what_falls``: also which objects fall (the ranking reads "does anything fall?" alone; without
    it every rollout ends at its first fall, ``ask``)."""
    return _ask(scene, [None] + [Place(b) for b in bodies], model, settings,
               sequential=Sequential(Ranking()) if sequential else None, what_falls=what_falls, **kw)


def resting_height_m(scene: Scene, body: Body, x_m: float, y_m: float, orientation_xyzw) -> float:
    """z of ``body``'s frame when it is lowered at (x, y) with this orientation until it touches
    what is below (the support or an object), found by bisection on its distance to everything
    else: exact for any shape, a ball's top included."""
    return _Lowering(scene, body).height_m(x_m, y_m, orientation_xyzw)


class _Lowering:
    """One geometry world of the scene with ``body`` in it, moved from spot to spot (building the
    world is most of the cost of one spot)."""

    def __init__(self, scene: Scene, body: Body):
        from ..simulation import world as world_module

        self._world_module, self.scene, self.body = world_module, scene, body
        self.world = geometry_world(scene)
        self.size = max(body.extents_m)
        self.top = max([scene.support.top_m] + [float(b.position_m[2]) + max(b.extents_m)
                                                for b in scene.objects]) + self.size
        self.handle = world_module.add_fixed_body(self.world, dataclasses.replace(body, static=True),
                                                  (0.0, 0.0, self.top), (0.0, 0.0, 0.0, 1.0))
        self.touch = 1e-3 * min(body.extents_m)  # rest this close above the surface

    def height_m(self, x_m: float, y_m: float, orientation_xyzw) -> float:
        def clear_at(z: float) -> bool:
            self._world_module.move_body(self.world, self.handle, (x_m, y_m, z), orientation_xyzw)
            return self._world_module.gap_to_others_m(self.world, self.handle, 2 * self.size) >= self.touch

        low, high = self.scene.support.top_m - 2 * self.size, self.top
        if clear_at(low):  # nothing below at all (off a table's edge with no floor): not a place
            raise ConfigError("position_m", f"nothing under ({x_m:g}, {y_m:g}) to rest {self.body.name!r} on")
        for _ in range(50):
            middle = (low + high) / 2
            if clear_at(middle):
                high = middle
            else:
                low = middle
        return float(high)


def _lowered(scene: Scene, body: Body, spots, deadline: _Deadline) -> list[Body]:
    """``body`` at each (x, y, yaw_rad) spot, lowered onto what is below; the question's budget
    checked between spots."""
    validate_body(body, "object")  # before pybullet sees its shape (the scene check comes after lowering)
    lowering = _Lowering(scene, body)
    bodies = []
    for x, y, yaw in spots:
        if deadline.passed():
            raise ConfigError("budget_s", f"lowering {len(spots)} candidate placements onto the scene took the whole "
                                          f"budget of {deadline.budget_s:g} s ({len(bodies)} done); ask fewer "
                                          "candidates or raise the budget")
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        bodies.append(dataclasses.replace(body, position_m=(x, y, lowering.height_m(x, y, q)), orientation_xyzw=q))
    return bodies


def best_place(scene: Scene, body: Body, region: Region, model: ModelConfig, settings: SimSettings,
               candidates: int = 16, yaws: int = 1, **kw) -> tuple[list[tuple[Body, VariantAnswer]], Answers]:
    """Candidate poses on a grid over ``region`` (about ``candidates`` of them, times ``yaws``
    orientations), each lowered onto what is below; returned most stable first: least likely to make
    anything fall in the samples where the scene as it is stands (``_rank_key``)."""
    for name, value in (("candidates", candidates), ("yaws", yaws)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(name, f"must be an integer >= 1, got {value!r}")
    n = max(1, int(round(math.sqrt(candidates))))
    deadline = _Deadline(kw.pop("budget_s", None))
    _check_variants(scene, n * n * yaws, model, settings, deadline.budget_s,
                    f"{n} x {n} candidates x {yaws} yaws", "candidates", placements=n * n * yaws)
    xs = np.linspace(*region.x_m, n)
    ys = np.linspace(*region.y_m, n)
    yaw_values = np.linspace(*region.yaw_rad, yaws) if yaws > 1 else [region.yaw_rad[0]]
    bodies = _lowered(scene, body, [(float(x), float(y), float(yaw))
                                    for x, y, yaw in itertools.product(xs, ys, yaw_values)], deadline)
    answers = place(scene, bodies, model, settings, budget_s=deadline.remaining_s(), **kw)
    ranked = sorted(zip(bodies, answers.variants[1:]), key=lambda bv: _rank_key(bv[1]))
    return ranked, answers


def _rank_key(variant: VariantAnswer) -> tuple:
    """Least likely to make anything fall first, over the samples in which the scene as it is
    stands (what the ranking rule decides on: a sequential answer simulates only those, a fixed-k
    one all, and what falls anyway is common to every candidate); a sequential answer's ranked-out
    ones last. Over all samples where no sample stood."""
    given = variant.given_stands
    p = given.any_fall_probability if given is not None and given.any_fall_probability is not None \
        else variant.any_fall_probability
    return (variant.decision == "ranked out", 1.0 if p is None else p)


def push(scene: Scene, pushes: list[Push], model: ModelConfig, settings: SimSettings, **kw) -> Answers:
    """What falls, and in which direction, when each push is made; the scene as it is comes first."""
    return _ask(scene, [None] + list(pushes), model, settings, directions=True, **kw)


def place_at(scene: Scene, body: Body, spots, model: ModelConfig, settings: SimSettings,
             **kw) -> tuple[list[tuple[Body, VariantAnswer]], Answers]:
    """``place`` at each (x, y, yaw_rad) spot, the body lowered onto what is below it there."""
    spots = list(spots)
    deadline = _Deadline(kw.pop("budget_s", None))
    _check_variants(scene, len(spots), model, settings, deadline.budget_s, f"{len(spots)} spots", "at",
                    placements=len(spots))
    bodies = _lowered(scene, body, spots, deadline)
    answers = place(scene, bodies, model, settings, budget_s=deadline.remaining_s(), **kw)
    return list(zip(bodies, answers.variants[1:])), answers


def placements_to_dict(scene: Scene, rows: list[tuple[Body, VariantAnswer]], answers: Answers) -> dict:
    """A placement question's JSON answer: the scene as is, then each candidate pose with its answer."""
    return {"scene": scene.name, "as_is": answers.variants[0].to_dict(), "wall_s": answers.wall_s,
            "alone": None if answers.alone is None else answers.alone.to_dict(),
            "stopped_by": answers.stopped_by,
            "candidates": [{"position_m": list(b.position_m), "orientation_xyzw": list(b.orientation_xyzw),
                            **v.to_dict()} for b, v in rows]}
