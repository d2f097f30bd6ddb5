"""Robot questions as data: the JSON a robot sends on ``~/ask`` (or a script passes), read into
a :class:`Question` with every field checked and named when wrong; beside ``scene_io`` (scenes as
data)."""

from __future__ import annotations

import math
from dataclasses import dataclass


from . import limits
from .errors import ConfigError, shown
from .query.contact import parse_pair
from .scene import Body, validate_body
from .actions.kinds import DEFAULT_SAFE_BELOW, DEFAULT_SUPPORT_THRESHOLD, NO_OBJECTS, Push, Region, check_level


# -- questions as data (the node's ~/ask, scripts) ------------------------------------------------------
QUESTIONS = ("remove", "support", "clear", "place", "push")


@dataclass(frozen=True)
class Question:
    """One question as a robot sends it (see ``question_from_dict`` for the JSON)."""

    kind: str
    request_id: str = ""
    objects: tuple[str, ...] | None = None  # remove: which (None: every object)
    threshold: float = DEFAULT_SUPPORT_THRESHOLD  # support
    safe_below: float | None = DEFAULT_SAFE_BELOW  # support; remove: None (no decision) unless asked
    target: str | None = None  # clear
    body: Body | None = None  # place
    spots: tuple[tuple[float, float, float], ...] = ()  # place: (x, y, yaw_rad), lowered onto what is below
    region: Region | None = None  # place: search here instead
    candidates: int = 16
    yaws: int = 1
    push: Push | None = None
    samples: int | None = None  # None: the asker's default
    fell_off: bool = False  # also: which objects end off the table (a scene on a table)
    sequential: bool = True  # decision questions sample until decided; False: the full k
    cancel_older: bool = False  # the node drops older questions about the same scene for this one
    contact: tuple[tuple[str, str], ...] = ()  # remove, place, push: also P(A touches B) per variant
    self_check: bool = False  # check each variant's fast physics against the reference (engine.fidelity)
    #: remove, place: also which objects fall (None: remove without safe_below only; a decision reads
    #: "does anything fall?", and its rollouts end at the first fall)
    what_falls: bool | None = None


def _field(data: dict, key: str, kind, default=None, *, path: str = ""):
    value = data.get(key, default)
    if value is default:
        return value
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        raise ConfigError(f"{path}{key}", f"must be {kind.__name__ if kind is not float else 'a number'}")
    return value


#: The fields each kind of question reads, besides id, question, samples and scene.
_QUESTION_FIELDS = {"remove": {"objects", "safe_below", "contact", "what_falls"},
                    "support": {"threshold", "safe_below"}, "clear": {"target"},
                    "place": {"object", "at", "region", "contact", "what_falls"},
                    "push": {"object", "velocity_m_s", "point_m", "direction_sigma_deg", "speed_sigma", "contact"}}


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
        against the reference physics, engine.fidelity), "cancel_older": true (the node drops the
        older questions about the same scene, waiting or running)
    """
    if not isinstance(data, dict):
        raise ConfigError("question", "must be a JSON object with a \"question\" field")
    kind = data.get("question")
    if kind not in QUESTIONS:
        raise ConfigError("question", f"must be one of {', '.join(QUESTIONS)}, got {kind!r}"[:300])
    common_fields = {"id", "question", "samples", "scene", "fell_off", "sequential", "cancel_older", "self_check"}
    unknown = sorted(set(data) - _QUESTION_FIELDS[kind] - common_fields, key=str)
    if unknown:
        key = unknown[0]
        allowed = ", ".join(sorted(_QUESTION_FIELDS[kind] | common_fields - {"question"}))
        raise ConfigError(key if key.isidentifier() and len(key) <= 64 else f"[{shown(key)}]",
                          f"unknown field of a {kind} question; allowed: {allowed}")
    request_id = data.get("id", "")
    if not isinstance(request_id, str) or len(request_id) > 128:
        raise ConfigError("id", "must be a string of at most 128 characters")
    samples = data.get("samples")
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int) or not 1 <= samples <= 1000):
        raise ConfigError("samples", "must be an integer in [1, 1000]")
    flags = {}
    for name, default in (("fell_off", False), ("sequential", True), ("cancel_older", False), ("self_check", False)):
        flags[name] = data.get(name, default)
        if not isinstance(flags[name], bool):
            raise ConfigError(name, "must be true or false")
    common = dict(kind=kind, request_id=request_id, samples=samples, **flags)
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
    if kind == "remove":
        objects = data.get("objects")
        if objects is not None and (not isinstance(objects, list) or not all(isinstance(o, str) for o in objects)):
            raise ConfigError("objects", "must be a list of object names")
        if objects == []:  # refused when read, before the question waits its turn (remove() refuses it too)
            raise ConfigError("objects", NO_OBJECTS)
        safe_below = _field(data, "safe_below", float, None)
        if safe_below is not None:
            check_level("safe_below", safe_below)
        return Question(objects=None if objects is None else tuple(objects), safe_below=safe_below, **common)
    if kind == "support":
        question = Question(threshold=_field(data, "threshold", float, DEFAULT_SUPPORT_THRESHOLD),
                            safe_below=_field(data, "safe_below", float, DEFAULT_SAFE_BELOW), **common)
        check_level("threshold", question.threshold)
        check_level("safe_below", question.safe_below)
        return question
    if kind == "clear":
        return Question(target=_field(data, "target", str), **common)
    if kind == "push":
        velocity = data.get("velocity_m_s")
        if not isinstance(velocity, list) or len(velocity) != 2:
            raise ConfigError("velocity_m_s", "must be [vx, vy] in m/s")
        point = data.get("point_m")
        if point is not None and (not isinstance(point, list) or len(point) != 3):
            raise ConfigError("point_m", "must be [x, y, z] in metres or absent")
        try:
            push = Push(_field(data, "object", str, path=""), (float(velocity[0]), float(velocity[1]), 0.0),
                        None if point is None else tuple(float(v) for v in point),
                        math.radians(_field(data, "direction_sigma_deg", float, 0.0)),
                        _field(data, "speed_sigma", float, 0.0))
        except (TypeError, ValueError):
            raise ConfigError("velocity_m_s", "must hold numbers") from None
        if push.name is None:
            raise ConfigError("object", "name the object to push")
        return Question(push=push, **common)
    body = new_object_from_dict(data.get("object"), "object")
    at, region = data.get("at"), data.get("region")
    if (at is None) == (region is None):
        raise ConfigError("at", "give candidate spots in \"at\" or a \"region\" to search (one of them)")
    if at is not None:
        if isinstance(at, list) and len(at) > limits.MAX_QUESTION_VARIANTS:
            raise ConfigError("at", f"{len(at)} spots are more than the {limits.MAX_QUESTION_VARIANTS} one question may "
                                    "ask about; split them into several questions")
        if not isinstance(at, list) or not at or not all(
                isinstance(s, list) and len(s) in (2, 3) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                                 and math.isfinite(v) for v in s) for s in at):
            raise ConfigError("at", "must be a list of [x, y] or [x, y, yaw_deg] spots")
        spots = tuple((float(s[0]), float(s[1]), math.radians(s[2]) if len(s) == 3 else 0.0) for s in at)
        return Question(body=body, spots=spots, **common)
    if not isinstance(region, dict):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg, candidates, yaws)")
    try:
        xs, ys = tuple(map(float, region["x_m"])), tuple(map(float, region["y_m"]))
        yaw = tuple(math.radians(float(v)) for v in region.get("yaw_deg", [0.0, 0.0]))
    except (KeyError, TypeError, ValueError):
        xs = ys = yaw = ()
    if not (len(xs) == len(ys) == len(yaw) == 2 and all(map(math.isfinite, xs + ys + yaw))):
        raise ConfigError("region", "must be {\"x_m\": [x0, x1], \"y_m\": [y0, y1]} (+ yaw_deg: [a0, a1])")
    candidates, yaws = region.get("candidates", 16), region.get("yaws", 1)
    if not all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 400 for v in (candidates, yaws)):
        raise ConfigError("region.candidates", "candidates and yaws must be integers in [1, 400]")
    if candidates * yaws > limits.MAX_QUESTION_VARIANTS:
        raise ConfigError("region.candidates", f"{candidates} candidates x {yaws} yaws are {candidates * yaws} "
                                               f"placements, more than the {limits.MAX_QUESTION_VARIANTS} one question "
                                               "may ask about; search a smaller region or fewer yaws")
    return Question(body=body, region=Region(xs, ys, yaw), candidates=candidates, yaws=yaws, **common)


def new_object_from_dict(data, path: str) -> Body:
    """An object to place, in the scene format; its pose may be left out (the spot gives it)."""
    from .scene_io import object_from_dict

    if not isinstance(data, dict):
        raise ConfigError(path, "must be the new object in the scene format (/2)")
    body = object_from_dict({"position_m": [0.0, 0.0, 0.0], "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], **data}, path)
    validate_body(body, path)  # its own fields now: the geometry that lowers it comes before the scene check
    return body
