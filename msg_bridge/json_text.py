"""``std_msgs/String`` carrying JSON <-> scenes and answers (the engine's JSON scene format, ``ipe_ros.scene/2``; ``/1`` is read too)."""

from __future__ import annotations

import json
from typing import Any

from std_msgs.msg import String

from ipe_ros.engine import Scene, SceneError
from ipe_ros.engine.errors import json_type
from ipe_ros.engine.scene.bodies import DEFAULT_MAX_OBJECTS
from ipe_ros.engine.scene.format import scene_to_json, scenes_from_json
from ipe_ros.engine.scene.meshes import MeshAccess


def string_to_scene(msg: String, *, max_objects: int = DEFAULT_MAX_OBJECTS, meshes: MeshAccess | None = None) -> Scene:
    """Exactly one validated scene from a JSON text (a scene object, or a list holding one); its mesh
    shapes read through ``meshes`` (None: refused)."""
    if not msg.data.strip():
        raise SceneError("data", "is empty; publish one scene in the ipe_ros.scene/2 JSON format")
    scenes = scenes_from_json(msg.data, max_objects=max_objects, meshes=meshes)
    if len(scenes) != 1:
        raise SceneError("data", f"holds {len(scenes)} scenes; publish one scene per message")
    return scenes[0]


def scene_name_of(msg: String) -> str:
    """The scene's "name" if the text can be read that far ("" otherwise): a refusal names the scene
    it refuses even when the rest of it is unreadable."""
    try:
        data = json.loads(msg.data)
    except (ValueError, RecursionError):
        return ""
    if isinstance(data, list) and len(data) == 1:
        data = data[0]
    value = data.get("name", "") if isinstance(data, dict) else ""
    return value[:128] if isinstance(value, str) else ""


def scene_to_string(scene: Scene) -> String:
    return String(data=scene_to_json(scene))


def answer_to_string(answer: dict[str, Any]) -> String:
    """An answer (a prediction's ``Answer.to_dict()``, a question's reply) as compact JSON; NaN/inf are refused
    (not JSON)."""
    return String(data=json.dumps(answer, allow_nan=False, sort_keys=True))


def string_to_answer(msg: String) -> dict[str, Any]:
    try:
        value = json.loads(msg.data)
    except RecursionError:
        raise ValueError("data: JSON nested too deeply to read") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"data: not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(value, dict):
        raise ValueError(f"data: expected a JSON object, got {json_type(value)}")
    return value
