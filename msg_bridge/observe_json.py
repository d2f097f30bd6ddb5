"""``std_msgs/String`` JSON, once read, -> observed motion (``~/observe``): an ``ipe_ros.observation/1``
object (read with ``inference.observation.parsed_json``), plus optionally ``"id"``, echoed in its
answer on ``~/properties`` (written by ``answer_to_string``); or an ``infer`` question on ``~/ask``
(read with ``ask_json.parse_request``): ``{"question": "infer", "id": ..., "observation": {...}}``."""

from __future__ import annotations

from ipe_ros.engine.errors import ConfigError
from ipe_ros.engine.inference.observation import Observation, observation_from_dict

from .ask_json import id_of

#: the fields of an ``infer`` question
INFER_FIELDS = ("question", "id", "observation")


def observation_with_id(data) -> tuple[str, Observation]:
    """(the request's id or "", the observation) from ``~/observe``'s parsed JSON."""
    request_id = id_of(data)
    if isinstance(data, dict):
        data = {k: v for k, v in data.items() if k != "id"}
    return request_id, observation_from_dict(data)


def infer_question_from_data(data: dict) -> tuple[str, Observation]:
    """(the question's id or "", its observation) from an ``infer`` question's parsed JSON
    (``ask_json.parse_request``); ConfigError/SceneError naming the field."""
    unknown = sorted(set(data) - set(INFER_FIELDS), key=str)
    if unknown:
        raise ConfigError(str(unknown[0])[:64], "unknown field of an infer question; allowed: id, observation")
    if "observation" not in data:
        raise ConfigError("observation", "required field is missing: an ipe_ros.observation/1 object")
    return id_of(data), observation_from_dict(data["observation"])