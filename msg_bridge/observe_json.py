"""``std_msgs/String`` JSON -> observed motion (``~/observe``): an ``ipe_ros.observation/1`` object,
plus optionally ``"id"``, echoed in its answer on ``~/properties`` (written by ``answer_to_string``);
or an ``infer`` question on ``~/ask``: ``{"question": "infer", "id": ..., "observation": {...}}``."""

from __future__ import annotations

from std_msgs.msg import String

from ipe_ros.engine.errors import ConfigError
from ipe_ros.engine.inference.observation import Observation, observation_from_dict, parsed_json

from .ask_json import id_of

#: the fields of an ``infer`` question
INFER_FIELDS = ("question", "id", "observation")


def string_to_observation(msg: String) -> tuple[str, Observation]:
    """(the request's id or "", the observation); ConfigError/SceneError naming the field."""
    data = parsed_json(msg.data)
    request_id = id_of(data)
    if isinstance(data, dict):
        data.pop("id", None)
    return request_id, observation_from_dict(data)


def string_to_infer_question(msg: String) -> tuple[str, Observation] | None:
    """(the question's id or "", its observation) when ``msg`` is an ``infer`` question, else None
    (another kind of question, or no JSON object: ``~/ask``'s own reader answers those);
    ConfigError/SceneError naming the field."""
    try:
        data = parsed_json(msg.data)
    except ConfigError:
        return None
    if not isinstance(data, dict) or data.get("question") != "infer":
        return None
    unknown = sorted(set(data) - set(INFER_FIELDS), key=str)
    if unknown:
        raise ConfigError(str(unknown[0])[:64], "unknown field of an infer question; allowed: id, observation")
    if "observation" not in data:
        raise ConfigError("observation", "required field is missing: an ipe_ros.observation/1 object")
    return id_of(data), observation_from_dict(data["observation"])
