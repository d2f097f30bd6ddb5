"""``contact``: will A touch B? For each asked pair ``A:B`` (B may be ``support``: the floor or
the table, and the floor under it), the probability that they touch at some time within the
horizon, its 95% interval, the median time of first contact over the rollouts in which they touch,
and the share of samples in which they already touch at t = 0 (those count as touching at 0 s).
Each rollout also keeps where they first touched (a point on B's surface), which recordings show.

Touching: a contact point between the two, as the physics found it after a step, no farther apart
than ``CONTACT_TOLERANCE_FRACTION`` of the smaller body's smallest extent. Looked at after every
step, so an impact is seen whatever the step (the travel limit keeps a body from passing through
another within one). A rollout asked only contacts ends once every pair has touched.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ConfigError, shown
from .base import Query, Reading, Samples, StepWatch

SUPPORT = "support"
#: how far apart (a fraction of the smaller smallest extent) two bodies may be and still "touch":
#: resting contacts sit within ~0.1% of a size; the margin absorbs the solver's slop, not a gap
CONTACT_TOLERANCE_FRACTION = 0.02


def pair_key(a: str, b: str) -> str:
    return f"{a}:{b}"


def parse_pair(text: str, field: str = "contact") -> tuple[str, str]:
    """``"cup:glass"`` -> ("cup", "glass"); names that hold ":" or edge spaces as JSON,
    ``'["cup:1", " glass"]'``; ConfigError naming ``field`` otherwise."""
    if isinstance(text, str) and text.lstrip().startswith("["):
        return _json_pair(_json(text, field), text, field)
    if not isinstance(text, str) or text.count(":") != 1:
        raise ConfigError(field, f"a pair is written A:B (B may be {SUPPORT}; names holding \":\" as JSON: "
                                 f"[\"A\", \"B\"]), got {shown(text)}")
    a, b = (part.strip() for part in text.split(":"))
    if not a or not b:
        raise ConfigError(field, f"a pair is written A:B with both names given, got {shown(text)}")
    return a, b


def parse_pairs(text: str, field: str) -> tuple[tuple[str, str], ...]:
    """Comma-separated A:B pairs (``"cup:glass,ball:support"``), or a JSON list of pairs for names that
    hold ":", "," or edge spaces (``'[["cup:1", "glass"]]'``); empty: none."""
    text = text.strip()
    if not text:
        return ()
    if text.startswith("[["):
        value = _json(text, field)
        if not isinstance(value, list):
            raise ConfigError(field, f'a JSON list of pairs is [["A", "B"], ...], got {shown(text)}')
        return tuple(_json_pair(pair, text, field) for pair in value)
    return tuple(parse_pair(part, field) for part in text.split(","))


def _json(text: str, field: str) -> Any:
    import json

    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(field, f'a pair in JSON is ["A", "B"]: {exc.msg} at column {exc.colno}') from None


def _json_pair(value: Any, text: str, field: str) -> tuple[str, str]:
    if not (isinstance(value, list) and len(value) == 2 and all(isinstance(v, str) and v for v in value)):
        raise ConfigError(field, f'a pair in JSON is ["A", "B"] (two non-empty names), got {shown(text)}')
    return value[0], value[1]


def check_pairs(pairs, scene, added: tuple[str, ...] = ()) -> None:
    """Each pair names two objects of the scene (or ``added`` ones: objects a robot question places),
    or the support, and one of them can move; ConfigError naming ``contact`` otherwise."""
    dynamic = {b.name for b in scene.dynamic_objects} | set(added)
    known = {b.name for b in scene.objects} | set(added) | {SUPPORT}
    where = f"in scene {shown(scene.name)}" + (" or placed by the question" if added else "")
    for a, b in pairs:
        for name in (a, b):
            if name not in known:
                raise ConfigError("contact", f"{pair_key(a, b)}: no object {shown(name)} {where}; objects: "
                                             f"{', '.join(sorted(known))}")
        if a == b:
            raise ConfigError("contact", f"{pair_key(a, b)}: an object always touches itself; name two")
        if a not in dynamic and b not in dynamic:
            raise ConfigError("contact", f"{pair_key(a, b)}: neither moves, so the answer is fixed; "
                                         "name a dynamic object")


class ContactWatch(StepWatch):
    """First contact time of each pair in one rollout.

    After each step the world's contacts are read in one call and matched to the pairs through their
    bodies: the cost is per contact, not per pair (asking pybullet pair by pair cost 39,800 calls a
    step for every pair of a 200-body scene). Each pair's first contact point is the one
    ``getContactPoints(a, b)`` would list first (pybullet's order; a contact stored as (b, a) has B's
    side as its A side)."""

    def __init__(self, scene, pairs: tuple[tuple[str, str], ...], world):
        handles = _handles(scene, world)
        extents = {b.name: b.smallest_extent_m for b in scene.objects}
        # a pair with an object not in this world (a robot question's variant removed it, or left it
        # out as beyond the action's reach) cannot touch: it stays None
        self._pairs = [(pair_key(a, b), handles[a], handles[b],
                        CONTACT_TOLERANCE_FRACTION * min(extents[n] for n in (a, b) if n in extents))
                       for a, b in pairs if a in handles and b in handles]
        self.first_s: dict[str, float | None] = {pair_key(a, b): None for a, b in pairs}
        self.at_start: dict[str, bool] = {pair_key(a, b): False for a, b in pairs}
        self.where_m: dict[str, list[float] | None] = {pair_key(a, b): None for a, b in pairs}  # on B
        # per body pair (lower id first): the watched pairs it belongs to, as (key, A's body, rank of
        # the body pair in that pair's A x B order, tolerance)
        self._by_bodies: dict[tuple[int, int], list[tuple[str, int, int, float]]] = {}
        for key, first, second, tolerance in self._pairs:
            for rank, (a, b) in enumerate((a, b) for a in first for b in second):
                self._by_bodies.setdefault((min(a, b), max(a, b)), []).append((key, a, rank, tolerance))
        self._undecided = len({key for key, *_ in self._pairs})
        self._client = world.client

    def start(self, world) -> None:
        from ..simulation.bullet import pybullet

        p = pybullet()
        for key, first, second, tolerance in self._pairs:
            for a in first:
                for b in second:
                    points = p.getClosestPoints(a, b, tolerance, physicsClientId=self._client)
                    if points and self.first_s[key] is None:
                        self.first_s[key], self.at_start[key] = 0.0, True
                        self.where_m[key] = [float(v) for v in points[0][6]]
                        self._undecided -= 1

    def after_step(self, world, t_s: float) -> None:
        from ..simulation.bullet import pybullet

        if not self._undecided:
            return
        contacts: dict[tuple[int, int], list] = {}
        for c in pybullet().getContactPoints(physicsClientId=self._client):
            contacts.setdefault((min(c[1], c[2]), max(c[1], c[2])), []).append(c)
        found: dict[str, tuple[int, list[float]]] = {}
        for bodies, points in contacts.items():
            for key, a, rank, tolerance in self._by_bodies.get(bodies, ()):
                if self.first_s[key] is not None or (key in found and found[key][0] < rank):
                    continue
                touching = next((c for c in points if c[8] <= tolerance), None)
                if touching is not None:
                    found[key] = (rank, [float(v) for v in (touching[6] if touching[1] == a else touching[5])])
        for key, (_, where) in found.items():
            self.first_s[key], self.where_m[key] = t_s, where
            self._undecided -= 1

    @property
    def decided(self) -> bool:
        return not self._undecided

    def events(self) -> Any:
        return {"first_s": dict(self.first_s), "at_start": dict(self.at_start), "where_m": dict(self.where_m)}


def _handles(scene, world) -> dict[str, tuple[int, ...]]:
    """Every name a pair may use (the objects and the support) -> its pybullet bodies in this world."""
    handles = {b.name: (i,) for b, i in zip(scene.dynamic_objects, world.dynamic_ids)}
    handles.update({b.name: (i,) for b, i in zip(scene.static_objects, world.static_ids)})
    handles[SUPPORT] = tuple(world.support_ids)
    return handles


class Contact(Query):
    name = "contact"
    fields = ("contact_probability", "contact_probability_ci95", "contact_time_s", "contact_at_start")
    summary = "P(A touches B) within the horizon for pairs A:B (B may be support), first-contact time"

    def check(self, scene, spec) -> None:
        check_pairs(spec.contact_pairs, scene)  # QuerySpec has refused a contact query without pairs

    def watch(self, scene, spec, world) -> StepWatch | None:
        return ContactWatch(scene, spec.contact_pairs, world)

    def read(self, reading: Reading) -> dict[str, Any]:
        return {"contact": reading.events["contact"]}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        keys = [pair_key(a, b) for a, b in samples.spec.contact_pairs]
        probability, interval, time_s, at_start = {}, {}, {}, {}
        for key in keys:
            p = float(samples.per_sample(lambda r: r.value("contact")["first_s"][key] is not None).mean())
            probability[key] = p
            interval[key] = list(samples.fraction_interval(p))
            times = [r.value("contact")["first_s"][key] for r in samples.rollouts]
            touched = [t for t in times if t is not None]
            time_s[key] = float(np.median(touched)) if touched else None
            at_start[key] = float(samples.per_sample(lambda r: r.value("contact")["at_start"][key]).mean())
        return {"contact_probability": probability, "contact_probability_ci95": interval,
                "contact_time_s": time_s, "contact_at_start": at_start}

    def flags(self, rollout) -> dict[str, list[float]]:
        if rollout.get("contact") is None:
            return {}
        return {"contact": [float(t is not None) for t in rollout.value("contact")["first_s"].values()]}

    def describe(self, prediction) -> list[str]:
        lines = []
        for key, p in (prediction.contact_probability or {}).items():
            lo, hi = prediction.contact_probability_ci95[key]
            when = prediction.contact_time_s[key]
            line = f"P({key.replace(':', ' touches ')}): {p:.3f} [{lo:.2f}, {hi:.2f}]"
            line += "" if when is None else f", first at {when:.2f} s (median)"
            if prediction.contact_at_start[key]:
                line += f"; touching at the start in {prediction.contact_at_start[key]:.0%} of samples"
            lines.append(line)
        return lines

    def sample_columns(self, outcome) -> dict[str, float]:
        keys = outcome.rollouts[0].value("contact")["first_s"]
        return {f"contact {key}": float(np.mean([r.value("contact")["first_s"][key] is not None
                                                 for r in outcome.rollouts])) for key in keys}


QUERY = Contact()
