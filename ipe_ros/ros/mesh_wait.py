"""Inputs whose meshes are not decomposed yet (``engine.scene.meshes.NotYetDecomposed``): the sender
hears "decomposing" at once, and the input is read again once the parts are ready, off the executor
(``service.decompositions``); mixed into the node's interface (ros/node.py)."""

from __future__ import annotations

from typing import Callable

from msg_bridge.json_text import answer_to_string

from ..engine.errors import clip
from ..engine.scene.meshes import NotYetDecomposed
from ..service import decomposing_answer
from ..service.decompositions import DecompositionService


class MeshWaitInterface:
    """Mixed into ``IpeInterface``: scenes and questions waiting on a mesh's decomposition."""

    decompositions: DecompositionService | None = None

    def _scene_waits_for_mesh(self, pending: NotYetDecomposed, again: Callable[[], None], topic: str, scene_id: str,
                              stamp_ns: int, frame_id: str) -> None:
        """A scene whose mesh is not decomposed yet: its sender hears "decomposing" on ~/prediction now,
        and the scene is read again once the parts are ready (the newest per topic), or refused."""
        where = (clip(scene_id, 128), stamp_ns, clip(frame_id, 256))
        status = self.decompositions.wait_for(
            pending.job, again, lambda reason: self._reject(topic, RuntimeError(reason), *where), stream=topic)
        if isinstance(status, str):
            self._reject(topic, RuntimeError(status), *where)
            return
        self._log_info(f"scene on {topic}: decomposing {status['object']} ({status['mesh']}, {status['triangles']} "
                       "triangles) into convex parts; it is answered once they are ready")
        self._pub_prediction.publish(answer_to_string(decomposing_answer(status, *where, topic)))

    def _question_waits_for_mesh(self, pending: NotYetDecomposed, data: dict, request_id: str) -> str | None:
        """A question whose scene holds a mesh not decomposed yet: a reply now (``"final": false``,
        ``decomposing``), asked again once the parts are ready; or why it is refused ("busy")."""
        status = self.decompositions.wait_for(pending.job, lambda: self._ask(data, request_id),
                                              lambda reason: self._refuse_question(request_id, reason))
        if isinstance(status, str):
            return status
        self._pub_answer.publish(answer_to_string({"id": request_id, "question": data.get("question"),
                                                   "final": False, "decomposing": status}))
        return None
