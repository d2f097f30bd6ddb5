"""``std_msgs/String`` JSON <-> questions about actions (``~/ask``) and their answers (``~/answer``).

A question is ``ipe_ros.engine.actions.question_from_dict``'s JSON, plus optionally ``"scene"``: a
scene in the ``ipe_ros.scene/2`` format to ask about (default: the newest scene the node accepted).
"""

from __future__ import annotations

import json
from typing import Any

from std_msgs.msg import ColorRGBA, String
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

from ipe_ros.engine import ConfigError, Scene, SceneError
from ipe_ros.engine.scene.meshes import MeshAccess
from ipe_ros.engine.actions.question import Question, question_from_dict
from ipe_ros.engine.errors import json_type
from ipe_ros.engine.scene.limits import MAX_JSON_CHARS
from ipe_ros.engine.scene.bodies import DEFAULT_MAX_OBJECTS
from ipe_ros.engine.scene.format import scene_from_dict
from ipe_ros.viz.palette import risk_rgb

from .stamps import stamp_ns_to_header


def request_id_of(msg: String) -> str:
    """The id of a request refused before it was read (too large, not an object), if its JSON can
    be read at all ("" otherwise), to echo it with the error; a request read is ``id_of``'s."""
    try:
        data = json.loads(msg.data)
    except (ValueError, RecursionError):
        return ""
    return id_of(data)


def id_of(data: Any) -> str:
    """A parsed request's "id" as it is echoed (a string, at most 128 characters; else "")."""
    value = data.get("id", "") if isinstance(data, dict) else ""
    return value[:128] if isinstance(value, str) else ""


def parse_request(msg: String) -> dict[str, Any]:
    """The JSON object of a request on ``~/ask``, read once (its size bounded first, NaN and
    Infinity refused as in scenes); ConfigError naming ``data``."""
    if len(msg.data) > MAX_JSON_CHARS:  # before reading it: the reply must not wait on 100 MB of JSON
        raise ConfigError("data", f"{len(msg.data)} characters exceed the maximum of {MAX_JSON_CHARS} for a question; "
                                  "send the scene on ~/scene_json and ask about it without \"scene\"")
    try:
        data = json.loads(msg.data, parse_constant=_not_a_number)
    except RecursionError:
        raise ConfigError("data", "JSON nested too deeply to read") from None
    except json.JSONDecodeError as exc:
        raise ConfigError("data", f"not JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    if not isinstance(data, dict):
        raise ConfigError("data", f"expected a JSON object, got {json_type(data)}")
    return data


def _not_a_number(token: str) -> None:
    raise ConfigError("data", f"{token} is not a valid number; use finite numbers only")


def question_from_data(data: dict[str, Any], *, max_objects: int = DEFAULT_MAX_OBJECTS,
                       meshes: MeshAccess | None = None) -> tuple[Question, Scene | None]:
    """A question and the scene it brings (None: ask about the node's newest scene; its mesh shapes
    read through ``meshes``, None: refused), from its parsed JSON (``parse_request``)."""
    data = dict(data)
    scene = None
    if "scene" in data:
        try:
            scene = scene_from_dict(data.pop("scene"), max_objects, meshes)
        except SceneError as exc:
            raise SceneError(f"scene.{exc.field}", exc.problem) from None
    return question_from_dict(data), scene


def string_to_question(msg: String, *, max_objects: int = DEFAULT_MAX_OBJECTS,
                       meshes: MeshAccess | None = None) -> tuple[Question, Scene | None]:
    """``question_from_data`` of ``parse_request``: a question read from its message."""
    return question_from_data(parse_request(msg), max_objects=max_objects, meshes=meshes)


def support_graph_markers(scene: Scene, answer: dict[str, Any], frame_id: str, stamp_ns: int) -> MarkerArray:
    """A support graph answer as RViz/Foxglove markers: a line from each supporter's centre of mass
    to each object it holds up, coloured by the probability (green 0 .. red 1), after a DELETEALL."""
    header = stamp_ns_to_header(stamp_ns, frame_id)
    markers = [Marker(header=header, ns="support_graph", id=0, action=Marker.DELETEALL)]
    centres = {b.name: b.centre_of_mass_m for b in scene.objects}
    line = Marker(header=header, ns="support_graph", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
    line.scale.x = 0.01
    line.pose.orientation.w = 1.0
    for supporter, supported, p in answer.get("edges", []):
        r, g, b = risk_rgb(p)
        for name in (supporter, supported):
            x, y, z = (float(v) for v in centres[name])
            line.points.append(Point(x=x, y=y, z=z))
            line.colors.append(ColorRGBA(r=r, g=g, b=b, a=1.0))
    if line.points:
        markers.append(line)
    return MarkerArray(markers=markers)
