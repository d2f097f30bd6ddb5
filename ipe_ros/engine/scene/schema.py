"""The scene format ``ipe_ros.scene/2`` as a JSON Schema (draft 2020-12), for other tools to validate scenes.

Built from what the reader itself uses: the field names of ``scene_io`` and the ranges of ``limits``,
so the schema cannot drift from the validation. The committed copy, ``ipe_ros/schema/scene-2.json``,
is checked against this by the tests; regenerate it with ``python -m ipe_ros.engine.scene.schema``.

The schema says what it can: fields, types, required keys, per-number ranges. What spans several
values stays with the engine, which also names the field and the fix: unit quaternions, |gravity|,
a body's overall extents (1 mm .. 10 m), the mass ratio, unique names, bodies not starting below
their support. So every scene the engine accepts is valid under the schema, not the reverse.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

from . import limits
from . import format as io
from .bodies import DEFAULT_MAX_OBJECTS, MAX_HORIZON_S, MAX_SET_DOWN_M, QUATERNION_NORM_TOLERANCE
from .properties import PRIOR_FIELDS, PROPERTIES, SUPPORT_PROPERTIES

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "schema" / "scene-2.json"
SCHEMA_ID = "urn:ipe-ros:schema:scene-2"


def _number(description: str = "", minimum: float | None = None, maximum: float | None = None, *,
            exclusive_minimum: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "number", **({"description": description} if description else {})}
    if minimum is not None:
        out["exclusiveMinimum" if exclusive_minimum else "minimum"] = minimum
    if maximum is not None:
        out["maximum"] = maximum
    return out


def _vector(n: int, description: str, bound: float | None = None, minimum: float | None = None) -> dict[str, Any]:
    item: dict[str, Any] = {"type": "number"}
    if bound is not None:
        item.update(minimum=-bound if minimum is None else minimum, maximum=bound)
    return {"type": "array", "items": item, "minItems": n, "maxItems": n, "description": description}


def _name(description: str) -> dict[str, Any]:
    return {"type": "string", "maxLength": limits.MAX_NAME_CHARS, "description": description}


def _closed(properties: dict[str, Any], required: tuple[str, ...], description: str) -> dict[str, Any]:
    return {"type": "object", "description": description, "properties": properties, "required": list(required),
            "additionalProperties": False}


def _by_type(kinds: list[str]) -> dict[str, Any]:
    """An object whose ``type`` picks one of the ``kinds`` definitions."""
    return {"type": "object", "required": ["type"], "properties": {"type": {"enum": kinds}},
            "allOf": [{"if": {"properties": {"type": {"const": k}}, "required": ["type"]},
                       "then": {"$ref": f"#/$defs/{k}"}} for k in kinds]}


def _shapes() -> dict[str, Any]:
    half = limits.MAX_SIZE_M / 2
    length = _number("straight length, m", 0.0, limits.MAX_SIZE_M, exclusive_minimum=True)
    fields = {
        "box": {"extents_m": _vector(3, "full edge lengths along x, y, z, m", limits.MAX_SIZE_M, 0.0)},
        "sphere": {"radius_m": _number("m", 0.0, half, exclusive_minimum=True)},
        "cylinder": {"radius_m": _number("m", 0.0, half, exclusive_minimum=True), "length_m": length},
        "capsule": {"radius_m": _number("m", 0.0, half, exclusive_minimum=True),
                    "length_m": _number("the straight section between the caps, m", 0.0, limits.MAX_SIZE_M,
                                        exclusive_minimum=True)},
        "convex": {"vertices_m": {"type": "array", "minItems": 4, "description": "points whose convex hull is "
                                  "the shape (at least 4, not all in one plane)",
                                  "items": _vector(3, "a point in the object frame, m")}},
        "compound": {"parts": {"type": "array", "minItems": 1, "items": {"$ref": "#/$defs/part"},
                               "description": "convex parts in the object frame (not overlapping)"},
                     "volume_m3": _number("the solid's own volume (a mesh's), where the parts only approximate it: "
                                          "mass from it; with centre_of_mass_m", 0.0, exclusive_minimum=True),
                     "centre_of_mass_m": _vector(3, "the solid's own centre of mass in the object frame, m; with "
                                                    "volume_m3"),
                     "inertia_diagonal_per_kg_m2": _vector(3, "the diagonal of the solid's own inertia about its "
                                                              "centre of mass in the object frame, per kg (m^2); "
                                                              "with volume_m3"),
                     "source": _closed({"uri": {"type": "string", "minLength": 1,
                                                "description": "the mesh file as the scene named it"},
                                        "scale": _vector(3, "metres per file unit along x, y, z", None, 0.0),
                                        "repaired": {"type": "string", "maxLength": 500,
                                                     "description": "how the mesh, open, was closed before it was "
                                                                    "decomposed (absent: it was closed)"}},
                                       ("uri", "scale"), "the mesh file these parts were read from: shown (RViz's "
                                                         "MESH_RESOURCE), never read; the parts are the shape")},
        "mesh": {"uri": {"type": "string", "minLength": 1,
                         "description": "a closed mesh (OBJ, STL, PLY, GLB) in the object frame, +z up (GLB: its "
                                        "+y): a path beside the scene file, file:// or package://; read as convex "
                                        "parts (docs/scene-format.md)"},
                 "scale": {"description": "metres per file unit (0.001 for millimetres): one number or [sx, sy, sz]",
                           "oneOf": [_number("m per unit", 0.0, exclusive_minimum=True),
                                     _vector(3, "m per unit along x, y, z", None, 0.0)]},
                 "open": {"enum": ["repair", "refuse"], "default": "repair",
                          "description": "a mesh that is not closed: repaired (its holes filled where small, else a "
                                         "watertight remesh, else its convex hull; the source says how), or refused"}},
    }
    optional = {"mesh": ("scale", "open"), "compound": ("volume_m3", "centre_of_mass_m", "inertia_diagonal_per_kg_m2",
                                                 "source")}
    return {kind: _closed({"type": {"const": kind}, **props},
                          ("type", *(p for p in props if p not in optional.get(kind, ()))), f"a {kind}")
            for kind, props in fields.items()}


def prior_schema(description: str) -> dict[str, Any]:
    """A property's prior (``properties.prior_from_dict``); its bounds per property are the reader's."""
    bounds = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2,
              "description": "[LOW, HIGH] inside the property's physical bounds"}
    return {"description": description, "oneOf": [
        {"type": "object", "properties": {"uniform": bounds}, "required": ["uniform"], "additionalProperties": False},
        {"type": "object", "properties": {"log_uniform": bounds}, "required": ["log_uniform"],
         "additionalProperties": False},
        {"type": "object", "properties": {"log_sd": {"type": "number", "exclusiveMinimum": 0, "maximum": 5},
                                          "median": {"type": "number", "exclusiveMinimum": 0}},
         "required": ["log_sd"], "additionalProperties": False,
         "description": "log-normal around the given value (or its median): not for a restitution"}]}


def _priors(properties) -> dict[str, Any]:
    return {PRIOR_FIELDS[p]: prior_schema(f"the {p} is uncertain: each sample draws its own from this prior "
                                          "(the given value is its centre)") for p in properties}


def _object_properties() -> dict[str, Any]:
    sigma = limits.MAX_SIGMA_M
    props = {
        "name": _name("unique in the scene; per-object answers use it"),
        "shape": {"$ref": "#/$defs/shape"},
        "position_m": _vector(3, "the object frame's origin in the scene frame, m", limits.MAX_COORDINATE_M),
        "orientation_xyzw": _vector(4, "unit quaternion (x, y, z, w) of the object frame",
                                    1.0 + QUATERNION_NORM_TOLERANCE),
        "friction": _number("Coulomb friction", 0.0, limits.MAX_FRICTION),
        "restitution": _number("restitution", 0.0, 1.0),
        "mass_kg": _number(f"kg; a dynamic body's mass must lie in [{limits.MIN_MASS_KG:g}, {limits.MAX_MASS_KG:g}]",
                           0.0, exclusive_minimum=True),
        "density_kg_m3": _number("kg/m^3, times the shape's true volume", 0.0, exclusive_minimum=True),
        "group": _name("a label: 'heavy' (scaled by the model's mu), 'red' (counted by the bump query)"),
        "static": {"type": "boolean", "description": "fixed geometry: never moves, never falls"},
        "linear_velocity_m_s": _vector(3, f"at t = 0, scene frame, m/s (speed <= {limits.MAX_SPEED_M_S:g})",
                                       limits.MAX_SPEED_M_S),
        "angular_velocity_rad_s": _vector(3, f"at t = 0, scene frame, rad/s (<= {limits.MAX_SPIN_RAD_S:g})",
                                          limits.MAX_SPIN_RAD_S),
        "position_sigma_m": {"description": "this object's own position noise SD, m: a number (horizontal) or "
                                            "[sx, sy, sz]; 0: known exactly",
                             "oneOf": [_number("m", 0.0, sigma), _vector(3, "m", sigma, 0.0)]},
        "yaw_sigma_rad": _number("SD of a turn about the vertical through the centre of mass, rad", 0.0, math.pi),
        **_priors(PROPERTIES),
    }
    return props


def scene_schema() -> dict[str, Any]:
    """The JSON Schema of one scene file: a scene object or a list of them."""
    coordinate = limits.MAX_COORDINATE_M
    obj = _closed(_object_properties(), io.OBJECT_REQUIRED, "a rigid body")
    floor = _closed({"type": {"const": "floor"}, "height_m": _number("m", -coordinate, coordinate),
                     "friction": _number("Coulomb friction", 0.0, limits.MAX_FRICTION), "restitution": _number("restitution", 0.0, 1.0),
                     **_priors(SUPPORT_PROPERTIES)},
                    io.FLOOR_FIELDS, "an infinite horizontal plane")
    table = _closed({
        "type": {"const": "table"},
        "top_height_m": _number("m", -coordinate, coordinate),
        "size_m": _vector(2, "top (x, y) size, m (> 0)", coordinate, 0.0),
        "center_xy_m": _vector(2, "top centre (x, y), m", coordinate),
        "thickness_m": _number("m", 0.0, limits.MAX_SIZE_M, exclusive_minimum=True),
        "friction": _number("Coulomb friction", 0.0, limits.MAX_FRICTION),
        "restitution": _number("restitution", 0.0, 1.0),
        "floor_z_m": {"description": "a floor below the table (at or below its underside), or null for none",
                      "oneOf": [_number("m", -coordinate, coordinate), {"type": "null"}]},
        "obstacles": {"type": "array", "items": {"allOf": [{"$ref": "#/$defs/object"},
                                                           {"properties": {"static": {"const": True}},
                                                            "required": ["static"]}]},
                      "description": "static objects attached to the table"},
        **_priors(SUPPORT_PROPERTIES),
    }, io.TABLE_FIELDS, "a table top of finite size: objects can fall off its edge")
    scene = _closed({
        "format": {"const": io.SCENE_FORMAT},
        "name": _name("the scene's id in answers"),
        "gravity_m_s2": {**_vector(3, f"m/s^2, z < 0, magnitude within [{limits.MIN_GRAVITY_M_S2:g}, "
                                      f"{limits.MAX_GRAVITY_M_S2:g}]", limits.MAX_GRAVITY_M_S2),
                         "prefixItems": [{}, {}, {"exclusiveMaximum": 0}]},
        "horizon_s": _number("how long to simulate this scene, s", 0.0, MAX_HORIZON_S, exclusive_minimum=True),
        "set_down_m": _number("objects at most this far above what is under them are set down onto it before "
                              "the rollout (heights that are estimates); 0: heights as given", 0.0, MAX_SET_DOWN_M),
        "support": {"type": "object", "required": ["type"], "properties": {"type": {"enum": ["floor", "table"]}},
                    "if": {"properties": {"type": {"const": "floor"}}},
                    "then": {"$ref": "#/$defs/floor"}, "else": {"$ref": "#/$defs/table"}},
        "objects": {"type": "array", "items": {"$ref": "#/$defs/object"}, "minItems": 1,
                    "maxItems": DEFAULT_MAX_OBJECTS,
                    "description": f"at most max_objects ({DEFAULT_MAX_OBJECTS} by default), one dynamic at least"},
    }, io.SCENE_REQUIRED, f"a scene in the {io.SCENE_FORMAT} format")
    shapes = _shapes()
    part = _closed({"shape": _by_type([k for k in shapes if k not in ("compound", "mesh")]),
                    "position_m": _vector(3, "the part's origin in the object frame, m"),
                    "orientation_xyzw": _vector(4, "the part's unit quaternion in the object frame")},
                   ("shape",), "one convex part of a compound")
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": SCHEMA_ID,
        "title": f"ipe_ros scene ({io.SCENE_FORMAT})",
        "description": "SI units, z up, full sizes, quaternions (x, y, z, w). A file holds one scene or a list. "
                       "Checks spanning several values (unit quaternions, |gravity|, a body's overall extents "
                       f"{limits.MIN_SIZE_M:g} .. {limits.MAX_SIZE_M:g} m, mass ratio <= {limits.MAX_MASS_RATIO:g}, "
                       "unique names, nothing below its support) are the engine's: see docs/scene-format.md.",
        # if/then rather than anyOf/oneOf: a validator then names the offending field, not the whole scene
        "if": {"type": "array"}, "then": {"items": {"$ref": "#/$defs/scene"}}, "else": {"$ref": "#/$defs/scene"},
        "$defs": {"scene": scene, "floor": floor, "table": table, "object": obj, "part": part,
                  "shape": _by_type(list(shapes)), **shapes},
    }


def schema_text() -> str:
    return json.dumps(scene_schema(), indent=1) + "\n"


if __name__ == "__main__":
    if sys.argv[1:] == ["--check"]:
        sys.exit(0 if SCHEMA_PATH.read_text() == schema_text() else 1)
    SCHEMA_PATH.parent.mkdir(exist_ok=True)
    SCHEMA_PATH.write_text(schema_text())
    print(f"wrote {SCHEMA_PATH}")
