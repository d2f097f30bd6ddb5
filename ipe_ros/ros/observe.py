"""``~/observe``: observed motion in, inferred properties out on latched ``~/properties`` (and an
``infer`` question on ``~/ask``, answered on ``~/answer``); mixed into the node's interface (ros/node.py). What was learned replaces an object's own properties, by name, in the
scenes that follow for ``learned_properties_s`` (each prediction says which it used)."""

from __future__ import annotations

from std_msgs.msg import String

from msg_bridge.ask_json import request_id_of
from msg_bridge.json_text import answer_to_string
from msg_bridge.observe_json import string_to_infer_question, string_to_observation

from ..engine.errors import clip
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
        request_id = request_id_of(msg)
        try:
            request_id, observation = string_to_observation(msg)
            refused = self.observations.submit(request_id, observation)
        except ValueError as exc:
            refused = str(exc)
        except Exception as exc:  # noqa: BLE001 - no input may end the node
            refused = f"data: unreadable observation ({type(exc).__name__})"
        if refused is not None:
            self._log_refusal(f"observation {request_id!r} refused: {refused}")
            self._publish_properties({"id": request_id, "error": clip(refused, 1000)})

    def _asked_to_infer(self, msg: String) -> bool:
        """Whether ``msg`` on ``~/ask`` is an ``infer`` question: then queued with the observations
        (what it teaches is learned alike) and answered on ``~/answer`` as every question is."""
        try:
            asked = string_to_infer_question(msg)
            if asked is None:
                return False
            refused = self.observations.submit(*asked, publish=self._publish_inferred)
        except ValueError as exc:
            refused = str(exc)
        if refused is not None:
            request_id = request_id_of(msg)
            self._log_refusal(f"question {request_id!r} refused: {refused}")
            self._publish_inferred({"id": request_id, "error": clip(refused, 1000)})
        return True

    def _publish_inferred(self, message: dict) -> None:
        self._pub_answer.publish(answer_to_string({"question": "infer", "final": True, **message}))

    def _publish_properties(self, message: dict) -> None:
        self._pub_properties.publish(answer_to_string(message))
