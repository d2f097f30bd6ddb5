"""``~/observe``: observed motion in, inferred properties out on latched ``~/properties`` (and an
``infer`` question on ``~/ask``, answered on ``~/answer``); mixed into the node's interface (ros/node.py). What was learned replaces an object's own properties, by name, in the
scenes that follow for ``learned_properties_s`` (each prediction says which it used)."""

from __future__ import annotations

from std_msgs.msg import String

from msg_bridge.ask_json import id_of
from msg_bridge.json_text import answer_to_string
from msg_bridge.observe_json import infer_question_from_data, observation_with_id

from ..engine.errors import clip
from ..engine.inference.observation import parsed_json
from ..service.observations import ObservationService


class ObserveInterface:
    """Mixed into ``IpeInterface``: the ``~/properties`` publisher, the observation service, ``~/observe``."""

    observations: ObservationService | None = None

    def _open_observations(self, latched_qos) -> None:
        self._pub_properties = self.create_publisher(String, "~/properties", latched_qos)
        self.observations = ObservationService(self.service, publish=self._publish_properties,
                                               keep_s=float(self._values["learned_properties_s"]),
                                               log_error=self._log_error)
        self.observations.start()

    def _on_observe(self, msg: String) -> None:
        request_id = ""
        try:
            data = parsed_json(msg.data)  # read once: its id, then the observation
            request_id = id_of(data)
            refused = self.observations.submit(*observation_with_id(data))
        except ValueError as exc:
            refused = str(exc)
        except Exception as exc:  # noqa: BLE001 - no input may end the node
            refused = f"data: unreadable observation ({type(exc).__name__})"
        if refused is not None:
            self._log_refusal(f"observation {request_id!r} refused: {refused}")
            self._publish_properties({"id": request_id, "error": clip(refused, 1000)})

    def _ask_infer(self, data: dict, request_id: str) -> None:
        """An ``infer`` question on ``~/ask`` (its JSON read by ``_on_ask``): queued with the
        observations (what it teaches is learned alike), answered on ``~/answer`` as every question is."""
        try:
            refused = self.observations.submit(*infer_question_from_data(data), publish=self._publish_inferred)
        except ValueError as exc:
            refused = str(exc)
        if refused is not None:
            self._log_refusal(f"question {request_id!r} refused: {refused}")
            self._publish_inferred({"id": request_id, "error": clip(refused, 1000)})

    def _publish_inferred(self, message: dict) -> None:
        self._pub_answer.publish(answer_to_string({"question": "infer", "final": True, **message}))

    def _publish_properties(self, message: dict) -> None:
        self._pub_properties.publish(answer_to_string(message))
