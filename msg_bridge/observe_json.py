"""``std_msgs/String`` JSON -> observed motion (``~/observe``): an ``ipe_ros.observation/1`` object,
plus optionally ``"id"``, echoed in its answer on ``~/properties`` (written by ``answer_to_string``)."""

from __future__ import annotations

from std_msgs.msg import String

from ipe_ros.engine.inference.observation import Observation, observation_from_dict, parsed_json


def string_to_observation(msg: String) -> tuple[str, Observation]:
    """(the request's id or "", the observation); ConfigError/SceneError naming the field."""
    data = parsed_json(msg.data)
    request_id = ""
    if isinstance(data, dict):
        value = data.pop("id", "")
        request_id = value[:128] if isinstance(value, str) else ""
    return request_id, observation_from_dict(data)
