"""The node's side of the evidence protocol (engine.evidence), ROS-free: every registered source's
topics' newest messages as received, and the posterior of the latest view, one per view.

The node converts each message (the topic's ``receive``) and hands it here; a prediction or a
question under a perception that needs evidence asks ``perceived``: the evidence assembled from the
views held (their frame and stamp checked against the scene's), the source's chain run within its
share of the budget, and kept, so that the view's predictions and questions share one chain.
Nothing here knows a source by name.
"""

from __future__ import annotations

import collections
import threading
from typing import Any, Mapping

from ..engine import ConfigError
from ..engine.evidence import EvidenceTopic, Held
from ..engine.perceptions import PerceptionSource, perception_names, perception_source


def counter_names() -> tuple[str, ...]:
    """The /diagnostics counters of every registered source with topics: messages held and refused
    per counted topic, scenes refused for a stale view, chains run."""
    names: list[str] = []
    for source in sources_with_topics():
        for topic in source.needs.topics:
            if topic.counted_as:
                names += [topic.counted_as, f"{topic.counted_as}_refused"] + ([f"{topic.counted_as}_stale"]
                                                                            if topic.view else [])
        names.append(f"{source.name}_posteriors")
    return tuple(names)


def sources_with_topics() -> list[PerceptionSource]:
    return [s for s in map(perception_source, perception_names())
            if s.needs is not None and s.needs.topics and s.on_node]


class EvidenceViews:
    """The newest message per topic of each source, the counters, and the latest view's posterior."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._held: dict[str, dict[str, Held]] = {}
        self._counts = collections.Counter(dict.fromkeys(counter_names(), 0))  # zeros shown from the start
        self._posterior: tuple[tuple, Any] | None = None  # (key, perceived scenes) of the latest view

    def held(self, source: str) -> dict[str, Held]:
        with self._lock:
            return dict(self._held.get(source, {}))

    def hold(self, source: str, topic: EvidenceTopic, value: Any, stamp_ns: int, frame_id: str) -> None:
        """``topic``'s newest message, converted, with its stamp and frame (replaces the one before)."""
        with self._lock:
            held = self._held.setdefault(source, {})
            number = held[topic.name].number + 1 if topic.name in held else 1
            held[topic.name] = Held(value, int(stamp_ns), frame_id, number)
            if topic.counted_as:
                self._counts[topic.counted_as] += 1

    def refuse(self, topic: EvidenceTopic) -> None:
        """Count a message that could not be used (the node logs why)."""
        if topic.counted_as:
            with self._lock:
                self._counts[f"{topic.counted_as}_refused"] += 1

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    def latest_view_stamp_ns(self, source: str) -> int | None:
        """The stamp of ``source``'s newest view, or None before any."""
        views = perception_source(source).needs.views()
        held = self.held(source)
        stamps = [held[t.name].stamp_ns for t in views if t.name in held]
        return max(stamps) if stamps else None

    def evidence(self, source: PerceptionSource, stamp_ns: int, frame_id: str,
                 node_values: Mapping[str, Any]) -> tuple[Any, tuple]:
        """The evidence for a scene stamped ``stamp_ns`` in ``frame_id``, and the numbers of the
        views it was made of; a ConfigError naming ``perception`` says what is missing or too old."""
        needs, held = source.needs, self.held(source.name)
        numbers = []
        for view in needs.views():
            if view.name not in held:
                raise ConfigError("perception", f"{source.name}: no {view.what} received yet; {needs.missing}")
            got = held[view.name]
            if got.frame_id != frame_id:
                raise ConfigError("perception", f"{source.name}: {needs.frame_named} is in {got.frame_id!r} but the "
                                                f"scene in {frame_id!r}; give both in one frame")
            age = abs(got.stamp_ns - stamp_ns) / 1e9
            if needs.max_age_parameter:
                max_age_s = float(node_values[needs.max_age_parameter])
                if age > max_age_s:
                    if view.counted_as:
                        with self._lock:
                            self._counts[f"{view.counted_as}_stale"] += 1
                    raise ConfigError("perception", f"{source.name}: the newest {view.what} is {age:.3g} s from the "
                                                    f"scene's stamp, more than {needs.max_age_parameter} = "
                                                    f"{max_age_s:g} s")
            numbers.append(got.number)
        return needs.assemble({name: h.value for name, h in held.items()}), tuple(numbers)

    def perceived(self, source: PerceptionSource, scene, stamp_ns: int, frame_id: str, model, seed: int,
                  budget_s: float | None, node_values: Mapping[str, Any], map_fn=None):
        """The posterior's scenes for this scene from the newest views (one chain per view: the same
        views and scene predicted again, or asked about, reuse it while the chain would be the same:
        its samples, seed and source)."""
        evidence, numbers = self.evidence(source, stamp_ns, frame_id, node_values)
        key = (source.name, numbers, scene, model.samples, seed)
        with self._lock:
            if self._posterior is not None and self._posterior[0] == key:
                return self._posterior[1]
        perceived = source.perceive(scene, model, seed, map_fn, evidence, budget_s)
        with self._lock:
            self._posterior = (key, perceived)
            self._counts[f"{source.name}_posteriors"] += 1
        return perceived
