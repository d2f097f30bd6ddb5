"""``ipe_ros.observation/1`` as a JSON Schema (draft 2020-12), built from the reader's own limits; its
scene is the scene format's schema. The committed copy is ``ipe_ros/schema/observation-1.json``
(tests keep it current); regenerate it with ``python -m ipe_ros.engine.inference.schema``.
What spans several values (frames in time order, names that exist in the scene, one unknown per
body and property, a prior inside the property's bounds) stays with the reader, which names the field.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from ..scene.schema import SCHEMA_ID as SCENE_SCHEMA_ID, prior_schema
from .observation import MAX_FRAMES, MAX_UNKNOWNS, MAX_WINDOW_S, OBSERVATION_FORMAT
from ..scene.properties import PROPERTIES

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "schema" / "observation-1.json"
SCHEMA_ID = "urn:ipe-ros:schema:observation-1"


def _numbers(n: int, description: str) -> dict[str, Any]:
    return {"type": "array", "items": {"type": "number"}, "minItems": n, "maxItems": n, "description": description}


def observation_schema() -> dict[str, Any]:
    pose = {"type": "object", "properties": {"position_m": _numbers(3, "the object's frame origin, scene frame"),
                                             "orientation_xyzw": _numbers(4, "unit quaternion; leave out if unseen")},
            "required": ["position_m"], "additionalProperties": False}
    frame = {"type": "object", "properties": {
        "t_s": {"type": "number", "exclusiveMinimum": 0, "maximum": MAX_WINDOW_S,
                "description": "seconds after the scene's t = 0; frames in time order"},
        "objects": {"type": "object", "additionalProperties": pose,
                    "description": "dynamic objects seen in this frame, by name (an occluded one left out)"}},
        "required": ["t_s", "objects"], "additionalProperties": False}
    unknown = {"type": "object", "properties": {
        "object": {"type": "string", "description": "a dynamic object's name, or \"support\""},
        "group": {"type": "string", "description": "every dynamic object of this group shares one value"},
        "property": {"enum": list(PROPERTIES)}, "prior": prior_schema("the property's prior")},
        "required": ["property", "prior"], "oneOf": [{"required": ["object"]}, {"required": ["group"]}],
        "additionalProperties": False}
    push = {"type": "object", "properties": {
        "kind": {"const": "push"}, "object": {"type": "string"},
        "at_s": {"type": "number", "minimum": 0, "maximum": MAX_WINDOW_S,
                 "description": "seconds after t = 0, within the frames' window (default 0)"},
        "impulse_N_s": _numbers(2, "horizontal impulse, N s (the mass then shows)"),
        "velocity_m_s": _numbers(2, "horizontal velocity change, m/s")},
        "required": ["kind", "object"], "oneOf": [{"required": ["impulse_N_s"]}, {"required": ["velocity_m_s"]}],
        "additionalProperties": False}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "$id": SCHEMA_ID,
            "title": OBSERVATION_FORMAT,
            "description": "What a tracker saw of a scene in motion, and which properties are unknown (docs/inference.md)",
            "type": "object", "properties": {
                "format": {"const": OBSERVATION_FORMAT},
                "scene": {"$ref": SCENE_SCHEMA_ID, "description": "every object's shape and exact pose at t = 0; an "
                          "object without linear_velocity_m_s has an unknown initial velocity"},
                "position_sd_m": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
                "yaw_sd_rad": {"type": "number", "exclusiveMinimum": 0, "maximum": 3.141592653589793},
                "frames": {"type": "array", "items": frame, "minItems": 1, "maxItems": MAX_FRAMES},
                "unknowns": {"type": "array", "items": unknown, "minItems": 1, "maxItems": MAX_UNKNOWNS},
                "actions": {"type": "array", "items": push}},
            "required": ["format", "scene", "position_sd_m", "frames", "unknowns"], "additionalProperties": False}


def schema_text() -> str:
    return json.dumps(observation_schema(), indent=1) + "\n"


if __name__ == "__main__":
    if sys.argv[1:] == ["--check"]:
        sys.exit(0 if SCHEMA_PATH.read_text() == schema_text() else 1)
    SCHEMA_PATH.write_text(schema_text())
    print(f"wrote {SCHEMA_PATH}")
