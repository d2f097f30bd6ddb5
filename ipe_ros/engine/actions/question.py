"""Robot questions as objects, one class per kind: each reads its JSON (``from_dict``), answers
itself (``answer``) and writes itself back (``to_dict``).
``question_from_dict`` picks the class once, by the JSON's ``"question"``; the node's ``~/ask`` and
``ipe ask`` (which builds the same objects from its options) answer through ``Question.answer``.

Every field is checked and named when wrong: JSON types where the JSON is read, the values
themselves where a question is made (so a question built in Python is checked alike).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

from ..scene import limits
from ..config import ModelConfig, SimSettings
from ..errors import ConfigError, shown
from ..query.contact import parse_pair
from ..query.parameters import spec_parameters
from ..query.spec import check_names
from ..scene.bodies import Body, Scene
from ..scene.validation import validate_body
from ..scene.format import object_from_dict, object_to_dict
from .answers import Answers
from .kinds import DEFAULT_SAFE_BELOW, DEFAULT_SUPPORT_THRESHOLD, NO_OBJECTS, Push, Region, check_level
from .questions import best_place, clear_order, place_at, placements_to_dict, push, remove, support_graph

#: the fields every question may carry, besides its kind's own
COMMON_FIELDS = frozenset({"id", "question", "samples", "scene", "fell_off", "sequential", "cancel_older",
                           "self_check"})


@dataclass(frozen=True)
class Reply:
    """A question's answer: ``data`` the JSON-ready reply, ``answers`` its variants (for a recording;
    None for clear, which asks once per step), ``result`` the full result (Answers, SupportGraph,
    ClearOrder, or the placements' (body, answer) rows) for text and pictures."""

    data: dict
    answers: Answers | None
    result: Any


@dataclass(frozen=True, kw_only=True)
class Question:
    """What every question carries. ``samples``: k (None: the asker's default); ``fell_off``: also
    which objects end off the table; ``sequential``: decision questions sample until decided (False:
    the full k); ``cancel_older``: the node drops older questions about the same scene for this one;
    ``self_check``: each variant checked against the reference physics (engine.checking.fidelity)."""

    kind: ClassVar[str] = ""
    #: the JSON fields of this kind, besides COMMON_FIELDS
    fields: ClassVar[frozenset[str]] = frozenset()

    request_id: str = ""
    samples: int | None = None
    fell_off: bool = False
    sequential: bool = True
    cancel_older: bool = False
    self_check: bool = False

    def answer(self, scene: Scene, model: ModelConfig, settings: SimSettings, **kw) -> Reply:
        """Answer on ``scene``. ``kw``: ``ask``'s keywords (seed, map_fn, budget_s, on_progress,
        record_every, record_samples, and ``check``: how a question asking for ``self_check`` is
        checked; without self_check, the fast physics alone)."""
        if self.samples is not None:
            model = dataclasses.replace(model, samples=self.samples)
        if self.fell_off:
            kw["fell_off"] = True
        if not self.self_check:
            kw["check"] = None
        return self._answer(scene, model, settings, kw)

    def _answer(self, scene: Scene, model: ModelConfig, settings: SimSettings, kw: dict) -> Reply:
        raise NotImplementedError

    def to_dict(self) -> dict:
        """The JSON that ``question_from_dict`` reads back to this question."""
        data = {"question": self.kind, "id": self.request_id, "fell_off": self.fell_off,
                "sequential": self.sequential, "cancel_older": self.cancel_older, "self_check": self.self_check}
        if self.samples is not None:
            data["samples"] = self.samples
        return {**data, **self._own_dict()}

    def _own_dict(self) -> dict:
        return {}


@dataclass(frozen=True, kw_only=True)
class _ContactAndWhatFalls(Question):
    """Questions whose variants may also report P(A touches B) (``contact``) and which objects fall
    (``what_falls``; None: the kind's default)."""

    contact: tuple[tuple[str, str], ...] = ()
    what_falls: bool | None = None
    #: other registered queries every variant answers (``ask(queries=...)``), and their parameters
    #: by name ("<query>.<field>")
    queries: tuple[str, ...] = ()
    query_parameters: tuple[tuple[str, Any], ...] = ()

    def _extra(self, kw: dict) -> dict:
        if self.contact:
            kw["contact"] = self.contact
        if self.what_falls is not None:
            kw["what_falls"] = self.what_falls
        if self.queries:
            kw.update(queries=self.queries, query_parameters=dict(self.query_parameters))
        return kw

    def _own_dict(self) -> dict:
        data = {"contact": [f"{a}:{b}" for a, b in self.contact]} if self.contact else {}
        if self.queries:
            data.update(queries=list(self.queries), query_parameters=dict(self.query_parameters))
        return data if self.what_falls is None else {**data, "what_falls": self.what_falls}


@dataclass(frozen=True, kw_only=True)
class RemoveQuestion(_ContactAndWhatFalls):
    """P(anything else falls) without each named object (None: every one); ``safe_below``: decide
    each removal safe or unsafe at this level."""

    kind: ClassVar[str] = "remove"
    fields: ClassVar[frozenset[str]] = frozenset({"objects", "safe_below", "contact", "what_falls", "queries",
                                                  "query_parameters"})

    objects: tuple[str, ...] | None = None
    safe_below: float | None = None

    def __post_init__(self) -> None:
        if self.objects is not None and not self.objects:
            raise ConfigError("objects", NO_OBJECTS)
        if self.safe_below is not None:
            check_level("safe_below", self.safe_below)

    @classmethod
    def from_dict(cls, data: dict, common: dict) -> RemoveQuestion:
        objects = data.get("objects")
        if objects is not None and (not isinstance(objects, list) or not all(isinstance(o, str) for o in objects)):
            raise ConfigError("objects", "must be a list of object names")
        return cls(objects=None if objects is None else tuple(objects),
                   safe_below=_field(data, "safe_below", float, None), **common)

    def _answer(self, scene, model, settings, kw) -> Reply:
        answers = remove(scene, None if self.objects is None else list(self.objects), model, settings,
                         safe_below=self.safe_below, sequential=self.sequential, **self._extra(kw))
        return Reply(answers.to_dict(), answers, answers)

    def _own_dict(self) -> dict:
        data = {} if self.objects is None else {"objects": list(self.objects)}
        return {**data, **({} if self.safe_below is None else {"safe_below": self.safe_below}), **super()._own_dict()}


@dataclass(frozen=True, kw_only=True)
class SupportQuestion(Question):
    """What supports what (removing i makes j fall with P >= ``threshold``), and what is safe to
    take now (P(anything else falls) below ``safe_below``)."""

    kind: ClassVar[str] = "support"
    fields: ClassVar[frozenset[str]] = frozenset({"threshold", "safe_below"})

    threshold: float = DEFAULT_SUPPORT_THRESHOLD
    safe_below: float = DEFAULT_SAFE_BELOW

    def __post_init__(self) -> None:
        check_level("threshold", self.threshold)
        check_level("safe_below", self.safe_below)

    @classmethod
    def from_dict(cls, data: dict, common: dict) -> SupportQuestion:
        return cls(threshold=_field(data, "threshold", float, DEFAULT_SUPPORT_THRESHOLD),
                   safe_below=_field(data, "safe_below", float, DEFAULT_SAFE_BELOW), **common)

    def _answer(self, scene, model, settings, kw) -> Reply:
        graph = support_graph(scene, model, settings, threshold=self.threshold, safe_below=self.safe_below,
                              sequential=self.sequential, **kw)
        return Reply(graph.to_dict(), graph.answers, graph)

    def _own_dict(self) -> dict:
        return {"threshold": self.threshold, "safe_below": self.safe_below}


@dataclass(frozen=True, kw_only=True)
class ClearQuestion(Question):
    """An order to take the scene apart (down to ``target``, None: everything), each step's risk."""

    kind: ClassVar[str] = "clear"
    fields: ClassVar[frozenset[str]] = frozenset({"target"})

    target: str | None = None

    @classmethod
    def from_dict(cls, data: dict, common: dict) -> ClearQuestion:
        return cls(target=_field(data, "target", str), **common)

    def _answer(self, scene, model, settings, kw) -> Reply:
        kw = {k: v for k, v in kw.items() if k not in ("record_every", "record_samples")}  # asks once per step
        order = clear_order(scene, model, settings, target=self.target, sequential=self.sequential, **kw)
        return Reply(order.to_dict(), None, order)

    def _own_dict(self) -> dict:
        return {} if self.target is None else {"target": self.target}


@dataclass(frozen=True, kw_only=True)
class PlaceQuestion(_ContactAndWhatFalls):
    """Where to put ``body``: at each of ``spots`` ((x, y, yaw_rad), lowered onto what is below), or
    the best of ``candidates`` x ``yaws`` poses searched in ``region`` (one of the two)."""

    kind: ClassVar[str] = "place"
    fields: ClassVar[frozenset[str]] = frozenset({"object", "at", "region", "contact", "what_falls", "queries",
                                                  "query_parameters"})

    body: Body
    spots: tuple[tuple[float, float, float], ...] = ()
    region: Region | None = None
    candidates: int = 16
    yaws: int = 1

    def __post_init__(self) -> None:
        _check_spots_or_region(bool(self.spots), self.region is not None)
        _check_spot_count(len(self.spots))
        if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 400
                   for v in (self.candidates, self.yaws)):
            raise ConfigError("region.candidates", "candidates and yaws must be integers in [1, 400]")
        if self.region is not None and self.candidates * self.yaws > limits.MAX_QUESTION_VARIANTS:
            raise ConfigError("region.candidates",
                              f"{self.candidates} candidates x {self.yaws} yaws are {self.candidates * self.yaws} "
                              f"placements, more than the {limits.MAX_QUESTION_VARIANTS} one question may ask "
                              "about; search a smaller region or fewer yaws")

    @classmethod
    def from_dict(cls, data: dict, common: dict) -> PlaceQuestion:
        body = new_object_from_dict(data.get("object"), "object")
        at, region = data.get("at"), data.get("region")
        _check_spots_or_region(at is not None, region is not None)  # before reading either: one of them, not both
        if at is not None:
            if isinstance(at, list):
                _check_spot_count(len(at))  # before reading each spot
            if not isinstance(at, list) or not at or not all(
                    isinstance(s, list) and len(s) in (2, 3) and all(
                        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in s)
                    for s in at):
                raise ConfigError("at", "must be a list of [x, y] or [x, y, yaw_deg] spots")
            spots = tuple((float(s[0]), float(s[1]), math.radians(s[2]) if len(s) == 3 else 0.0) for s in at)
            return cls(body=body, spots=spots, **common)
        return cls(body=body, **_region_from_dict(region), **common)

    def _answer(self, scene, model, settings, kw) -> Reply:
        kw = dict(self._extra(kw), sequential=self.sequential)
        if self.region is not None:
            rows, answers = best_place(scene, self.body, self.region, model, settings, candidates=self.candidates,
                                       yaws=self.yaws, **kw)
        else:
            rows, answers = place_at(scene, self.body, self.spots, model, settings, **kw)
        return Reply(placements_to_dict(scene, rows, answers), answers, rows)

    def _own_dict(self) -> dict:
        data = {"object": object_to_dict(self.body)}
        if self.region is not None:
            data["region"] = {"x_m": list(self.region.x_m), "y_m": list(self.region.y_m),
                              "yaw_deg": [math.degrees(a) for a in self.region.yaw_rad],
                              "candidates": self.candidates, "yaws": self.yaws}
        else:
            data["at"] = [[x, y, math.degrees(yaw)] for x, y, yaw in self.spots]
        return {**data, **super()._own_dict()}


@dataclass(frozen=True, kw_only=True)
class PushQuestion(_ContactAndWhatFalls):
    """What one push makes fall, and in which direction (the full k: no decision to reach)."""

    kind: ClassVar[str] = "push"
    fields: ClassVar[frozenset[str]] = frozenset({"object", "velocity_m_s", "point_m", "direction_sigma_deg",
                                                  "speed_sigma", "contact", "queries", "query_parameters"})

    push: Push

    @classmethod
    def from_dict(cls, data: dict, common: dict) -> PushQuestion:
        velocity = data.get("velocity_m_s")
        if not isinstance(velocity, list) or len(velocity) != 2:
            raise ConfigError("velocity_m_s", "must be [vx, vy] in m/s")
        point = data.get("point_m")
        if point is not None and (not isinstance(point, list) or len(point) != 3):
            raise ConfigError("point_m", "must be [x, y, z] in metres or absent")
        try:
            action = Push(_field(data, "object", str, path=""), (float(velocity[0]), float(velocity[1]), 0.0),
                          None if point is None else tuple(float(v) for v in point),
                          math.radians(_field(data, "direction_sigma_deg", float, 0.0)),
                          _field(data, "speed_sigma", float, 0.0))
        except (TypeError, ValueError):
            raise ConfigError("velocity_m_s", "must hold numbers") from None
        if action.name is None:
            raise ConfigError("object", "name the object to push")
        return cls(push=action, **common)

    def _answer(self, scene, model, settings, kw) -> Reply:
        answers = push(scene, [self.push], model, settings, **self._extra(kw))
        return Reply(answers.to_dict(), answers, answers)

    def _own_dict(self) -> dict:
        p = self.push
        data = {"object": p.name, "velocity_m_s": list(p.velocity_m_s[:2]),
                "direction_sigma_deg": math.degrees(p.direction_sigma_rad), "speed_sigma": p.speed_sigma_fraction}
        return {**data, **({} if p.point_m is None else {"point_m": list(p.point_m)}), **super()._own_dict()}



#: every kind of question by its JSON name
QUESTION_KINDS: dict[str, type[Question]] = {cls.kind: cls for cls in (RemoveQuestion, SupportQuestion, ClearQuestion,
                                                                         PlaceQuestion, PushQuestion)}
QUESTIONS = tuple(QUESTION_KINDS)


def question_from_dict(data) -> Question:
    """A question from parsed JSON::

        {"id": "r1", "question": "remove", "objects": ["block3"], "safe_below": 0.05}
                                     (objects: default every one; safe_below: decide safe/unsafe)
        {"id": "r2", "question": "support", "threshold": 0.5, "safe_below": 0.05}
        {"id": "r3", "question": "clear", "target": "block7"}                (target optional)
        {"id": "r4", "question": "place", "object": {...scene-format object...},
         "at": [[x, y, yaw_deg], ...]}  or  "region": {"x_m": [x0, x1], "y_m": [y0, y1],
         "yaw_deg": [a0, a1], "candidates": 16, "yaws": 1}
        {"id": "r5", "question": "push", "object": "block2", "velocity_m_s": [vx, vy],
         "point_m": [x, y, z], "direction_sigma_deg": 0, "speed_sigma": 0}
        remove, place, push: "contact": ["A:B", ...] (also P(A touches B) per variant; B may be "support")
        remove, place: "what_falls": true/false (also which objects fall; default: a remove question
        without safe_below only - a decision reads "does anything fall?" and its rollouts end at the
        first fall)
        any of them: "samples": k, "fell_off": true (also which objects end off the table),
        "sequential": false (the full k for every variant), "self_check": true (each variant checked
        against the reference physics, engine.checking.fidelity), "cancel_older": true (the node drops the
        older questions about the same scene, waiting or running)
    """
    if not isinstance(data, dict):
        raise ConfigError("question", "must be a JSON object with a \"question\" field")
    kind = data.get("question")
    if not isinstance(kind, str) or kind not in QUESTION_KINDS:  # a list or a dict is no name (nor hashable)
        raise ConfigError("question", f"must be one of {', '.join(QUESTIONS)}, got {kind!r}"[:300])
    cls = QUESTION_KINDS[kind]
    unknown = sorted(set(data) - cls.fields - COMMON_FIELDS, key=str)
    if unknown:
        key = unknown[0]
        allowed = ", ".join(sorted(cls.fields | COMMON_FIELDS - {"question"}))
        raise ConfigError(key if key.isidentifier() and len(key) <= 64 else f"[{shown(key)}]",
                          f"unknown field of a {kind} question; allowed: {allowed}")
    return cls.from_dict(data, _common_from_dict(data, cls))


def _common_from_dict(data: dict, cls: type[Question]) -> dict:
    """The fields every question has (and contact / what_falls where the kind has them), checked."""
    request_id = data.get("id", "")
    if not isinstance(request_id, str) or len(request_id) > 128:
        raise ConfigError("id", "must be a string of at most 128 characters")
    samples = data.get("samples")
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= 1000):
        raise ConfigError("samples", "must be an integer in [1, 1000]")
    common: dict[str, Any] = dict(request_id=request_id, samples=samples)
    for name, default in (("fell_off", False), ("sequential", True), ("cancel_older", False), ("self_check", False)):
        common[name] = data.get(name, default)
        if not isinstance(common[name], bool):
            raise ConfigError(name, "must be true or false")
    if "what_falls" in data:
        if not isinstance(data["what_falls"], bool):
            raise ConfigError("what_falls", "must be true or false")
        common["what_falls"] = data["what_falls"]
    if "contact" in data:
        pairs = data["contact"]
        if not isinstance(pairs, list) or not pairs or len(pairs) > 32:
            raise ConfigError("contact", "must be a list of 1-32 \"A:B\" pairs (B may be \"support\")")
        common["contact"] = tuple(parse_pair(pair, "contact") for pair in pairs)
        if len(set(common["contact"])) != len(common["contact"]):
            raise ConfigError("contact", "a pair is asked twice; ask each once")
    if "queries" in data:
        names = data["queries"]
        if not isinstance(names, list) or not names or len(names) > 16 or not all(isinstance(n, str) for n in names):
            raise ConfigError("queries", "must be a list of 1-16 query names (each variant also answers them)")
        if len(set(names)) != len(names):
            raise ConfigError("queries", "a query is asked twice; ask each once")
        check_names(frozenset(names))
        common["queries"] = tuple(names)
    if "query_parameters" in data:
        given = data["query_parameters"]
        if not isinstance(given, dict) or len(given) > 64:
            raise ConfigError("query_parameters", "must be an object of at most 64 \"<query>.<field>\": value entries")
        if "queries" not in common:
            raise ConfigError("query_parameters", "were given but no queries; list the queries they are for in "
                                                  "\"queries\"")
        spec_parameters(frozenset(common["queries"]), given)  # refused now, naming the parameter
        for key in given:
            if key.split(".")[0] not in common["queries"]:
                raise ConfigError(f"query_parameters.{key}", "is for a query this question does not ask; add it to "
                                                             "\"queries\" or drop the parameter")
        common["query_parameters"] = tuple(given.items())
    return common


def _field(data: dict, key: str, kind, default=None, *, path: str = ""):
    value = data.get(key, default)
    if value is default:
        return value
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        raise ConfigError(f"{path}{key}", f"must be {kind.__name__ if kind is not float else 'a number'}")
    return value


def _check_spots_or_region(spots: bool, region: bool) -> None:
    if spots == region:
        raise ConfigError("at", "give candidate spots in \"at\" or a \"region\" to search (one of them)")


def _check_spot_count(spots: int) -> None:
    if spots > limits.MAX_QUESTION_VARIANTS:
        raise ConfigError("at", f"{spots} spots are more than the {limits.MAX_QUESTION_VARIANTS} one question may "
                                "ask about; split them into several questions")


def _region_from_dict(region) -> dict:
    if not isinstance(region, dict):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg, candidates, yaws)")
    try:
        xs, ys = tuple(map(float, region["x_m"])), tuple(map(float, region["y_m"]))
        yaw = tuple(math.radians(float(v)) for v in region.get("yaw_deg", [0.0, 0.0]))
    except (KeyError, TypeError, ValueError):
        xs = ys = yaw = ()
    if not (len(xs) == len(ys) == len(yaw) == 2 and all(map(math.isfinite, xs + ys + yaw))):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg: [a0, a1])")
    return dict(region=Region(xs, ys, yaw), candidates=region.get("candidates", 16), yaws=region.get("yaws", 1))


def new_object_from_dict(data, path: str) -> Body:
    """An object to place, in the scene format; its pose may be left out (the spot gives it)."""
    if not isinstance(data, dict):
        raise ConfigError(path, "must be the new object in the scene format (/2)")
    body = object_from_dict({"position_m": [0.0, 0.0, 0.0], "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], **data}, path)
    validate_body(body, path)  # its own fields now: the geometry that lowers it comes before the scene check
    return body
