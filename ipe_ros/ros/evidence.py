"""The perception sources' topics (engine.evidence): for every registered source the node can feed,
a subscription per declared topic, each message converted as it arrives and held as the newest
(service/evidence.py); mixed into the node's interface (ros/node.py). Depth's ``~/depth/image``,
``~/depth/camera_info`` and ``~/depth/camera_pose`` are made here like any other source's."""

from __future__ import annotations

import importlib
from typing import Any, Callable

from rclpy.qos import qos_profile_sensor_data

from msg_bridge.stamps import header_to_stamp_ns

from ..engine.evidence import EvidenceTopic, resolve
from ..service.evidence import sources_with_topics


def message_class(name: str) -> type:
    """``"sensor_msgs/msg/Image"`` -> the message class (a ValueError naming the type when absent)."""
    package, kind, cls = (name.split("/") + ["", ""])[:3]
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), cls)
    except (ImportError, AttributeError):
        raise ValueError(f"no message type {name!r}: give it as package/msg/Type of an installed package") from None


class EvidenceInterface:
    """Mixed into ``IpeInterface``: the sources' subscriptions (made in ``_listen``)."""

    def _subscribe_evidence(self, group) -> None:
        # camera streams: a best-effort subscription turns a reliable publisher's images best effort,
        # and Fast DDS loses most best-effort messages over ~500 KB (a 640 x 480 depth image) in their
        # fragments: with "both" a reliable publisher's images come whole through the reliable one
        for source in sources_with_topics():
            streams = [(message_class(t.message_type), t.name, self._evidence_handler(source.name, t))
                       for t in source.needs.topics]
            self._subscribe_per_reliability(source.needs.reliability_parameter or "scene_reliability",
                                            qos_profile_sensor_data.depth, group, streams)

    def _evidence_handler(self, source: str, topic: EvidenceTopic) -> Callable[[Any], None]:
        receive = resolve(topic.receive)

        def handle(msg: Any) -> None:
            """A message for ``source``: converted with what its other topics hold, and kept as the newest."""
            views = self.service.evidence
            try:
                value, frame_id = receive(msg, views.held(source), self._values)
            except Exception as exc:  # noqa: BLE001 - a plugin's converter may raise anything: the node goes on
                why = str(exc) if isinstance(exc, ValueError) else f"{type(exc).__name__}: {exc}"
                views.refuse(topic)
                self._log_refusal(f"refused {topic.what} on {self.resolve_topic_name(topic.name)}: {why}")
                return
            header = getattr(msg, "header", None)  # a message without one is stamped as it arrives
            stamp_ns = header_to_stamp_ns(header) if header is not None else self.get_clock().now().nanoseconds
            views.hold(source, topic, value, stamp_ns, frame_id)

        handle.__name__ = f"evidence {source} {topic.name}"  # the duplicate filter's key (node._once)
        return handle
