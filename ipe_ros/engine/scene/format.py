"""Scenes to and from the engine's JSON format (files, and the paper's tower CSV: ``scene_files.py``).

JSON scene format ``ipe_ros.scene/2`` (written by this version; ``/1`` files are read unchanged), SI
units, z up; docs/scene-format.md gives it in full::

    {
      "format": "ipe_ros.scene/2",
      "name": "capped_tower",
      "gravity_m_s2": [0.0, 0.0, -9.81],
      "horizon_s": 3.0,
      "support": {"type": "floor", "height_m": 0.0, "friction": 0.9, "restitution": 0.0},
      "objects": [
        {"name": "base", "shape": {"type": "box", "extents_m": [0.4, 0.4, 0.4]},
         "position_m": [0.0, 0.0, 0.2], "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], "mass_kg": 2.0,
         "friction": 0.6, "restitution": 0.2},
        {"name": "ball", "shape": {"type": "sphere", "radius_m": 0.1}, "position_m": [-1.0, 0.0, 0.1],
         "orientation_xyzw": [0.0, 0.0, 0.0, 1.0], "density_kg_m3": 500.0, "friction": 0.5,
         "restitution": 0.5, "linear_velocity_m_s": [3.0, 0.0, 0.0], "position_sigma_m": 0.0}
      ]
    }

Shapes: ``{"type": "box", "extents_m": [x, y, z]}``, ``{"type": "sphere", "radius_m": r}``,
``{"type": "cylinder", "radius_m": r, "length_m": l}`` (axis = object z), ``{"type": "capsule",
"radius_m": r, "length_m": l}`` (l: the straight section between the caps), ``{"type": "convex",
"vertices_m": [[x, y, z], ...]}`` (the hull of the points, object frame), ``{"type": "compound",
"parts": [{"shape": {...}, "position_m": [...], "orientation_xyzw": [...]}, ...]}``.

An object gives exactly one of ``mass_kg`` / ``density_kg_m3`` (density x the shape's true volume);
optional: ``group`` (""), ``static`` (false), ``linear_velocity_m_s`` and ``angular_velocity_rad_s``
(zero), ``position_sigma_m`` (a number: horizontal SD, or [sx, sy, sz]) and ``yaw_sigma_rad``, the
object's own noise (absent: the model's sigma). A table support is ``{"type": "table",
"top_height_m", "size_m": [x, y], "center_xy_m": [x, y], "thickness_m", "friction", "restitution",
"floor_z_m" (number or null), "obstacles": [object, ...]}``. Unknown fields are rejected: nothing is
guessed. A file may hold one scene object or a list of them. In ``/1`` files objects are
``"boxes"`` with ``"extents_m"`` instead of a shape.

Round trip: ``scene_from_dict(scene_to_dict(s)) == s`` exactly (floats are written with ``repr``
precision by the json module).
"""

from __future__ import annotations

import functools
import math
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from ..errors import SceneError, json_type as _json_type, shown
from .limits import MAX_JSON_CHARS
from .bodies import DEFAULT_MAX_OBJECTS, Body, Box, Floor, Scene, Table
from .meshes import MeshAccess, mesh_shape, readable_source
from .properties import PRIOR_FIELDS, PROPERTIES, SUPPORT_PROPERTIES, priors_from_dict, priors_to_dict
from .validation import validate_scene
from .shapes import (SHAPE_TYPES, BoxShape, Capsule, Compound, CompoundPart, ConvexHull, Cylinder, MeshSource, Sphere,
                     volume_m3)

SCENE_FORMAT = "ipe_ros.scene/2"
SCENE_FORMAT_V1 = "ipe_ros.scene/1"

_BOX_REQUIRED = ("name", "extents_m", "position_m", "orientation_xyzw", "friction", "restitution")
_BOX_OPTIONAL = ("mass_kg", "density_kg_m3", "group", "static")
OBJECT_REQUIRED = ("name", "shape", "position_m", "orientation_xyzw", "friction", "restitution")
_OBJECT_OPTIONAL = ("mass_kg", "density_kg_m3", "group", "static", "linear_velocity_m_s", "angular_velocity_rad_s",
                    "position_sigma_m", "yaw_sigma_rad", *PRIOR_FIELDS.values())
#: the support's optional fields: its surfaces' priors
SUPPORT_OPTIONAL = tuple(PRIOR_FIELDS[p] for p in SUPPORT_PROPERTIES)
_SHAPE_FIELDS = {"box": ("extents_m",), "sphere": ("radius_m",), "cylinder": ("radius_m", "length_m"),
                 "capsule": ("radius_m", "length_m"), "convex": ("vertices_m",), "compound": ("parts",),
                 "mesh": ("uri",)}
#: fields a shape may leave out
_SHAPE_OPTIONAL = {"mesh": ("scale", "open"), "compound": ("volume_m3", "centre_of_mass_m", "inertia_diagonal_per_kg_m2",
                                                    "source")}
FLOOR_FIELDS = ("type", "height_m", "friction", "restitution")
TABLE_FIELDS = ("type", "top_height_m", "size_m", "center_xy_m", "thickness_m", "friction",
                 "restitution", "floor_z_m", "obstacles")
SCENE_REQUIRED = ("name", "gravity_m_s2", "support", "objects")
_SCENE_REQUIRED_V1 = ("name", "gravity_m_s2", "support", "boxes")


# --------------------------------------------------------------------------------------------
# to JSON

def shape_to_dict(shape) -> dict[str, Any]:
    if isinstance(shape, BoxShape):
        return {"type": "box", "extents_m": list(shape.extents_m)}
    if isinstance(shape, Sphere):
        return {"type": "sphere", "radius_m": shape.radius_m}
    if isinstance(shape, (Cylinder, Capsule)):
        return {"type": shape.type, "radius_m": shape.radius_m, "length_m": shape.length_m}
    if isinstance(shape, ConvexHull):
        return {"type": "convex", "vertices_m": [list(v) for v in shape.vertices_m]}
    out = {"type": "compound", "parts": [{"shape": shape_to_dict(p.shape), "position_m": list(p.position_m),
                                          "orientation_xyzw": list(p.orientation_xyzw)} for p in shape.parts]}
    if shape.volume_m3 is not None:  # the solid's own (a mesh's), not the parts'
        out.update(volume_m3=shape.volume_m3, centre_of_mass_m=list(shape.centre_of_mass_m))
    if shape.inertia_diagonal_per_kg_m2 is not None:
        out.update(inertia_diagonal_per_kg_m2=list(shape.inertia_diagonal_per_kg_m2))
    if shape.source is not None:
        out.update(source={"uri": shape.source.uri, "scale": list(shape.source.scale),
                           **({"repaired": shape.source.repaired} if shape.source.repaired else {})})
    return out


def object_to_dict(body: Body) -> dict[str, Any]:
    out: dict[str, Any] = {
        "name": body.name,
        "shape": shape_to_dict(body.shape),
        "position_m": list(body.position_m),
        "orientation_xyzw": list(body.orientation_xyzw),
    }
    if body.mass_kg is not None:
        out["mass_kg"] = body.mass_kg
    if body.density_kg_m3 is not None:
        out["density_kg_m3"] = body.density_kg_m3
    out.update(friction=body.friction, restitution=body.restitution, group=body.group, static=body.static)
    if any(body.linear_velocity_m_s):
        out["linear_velocity_m_s"] = list(body.linear_velocity_m_s)
    if any(body.angular_velocity_rad_s):
        out["angular_velocity_rad_s"] = list(body.angular_velocity_rad_s)
    if body.position_sigma_m is not None:
        sigma = body.position_sigma_m
        out["position_sigma_m"] = list(sigma) if isinstance(sigma, (tuple, list)) else sigma
    if body.yaw_sigma_rad is not None:
        out["yaw_sigma_rad"] = body.yaw_sigma_rad
    out.update(priors_to_dict(body.priors))
    return out


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    support = scene.support
    if isinstance(support, Floor):
        sup: dict[str, Any] = {"type": "floor", "height_m": support.height_m,
                               "friction": support.friction, "restitution": support.restitution}
    else:
        sup = {"type": "table", "top_height_m": support.top_height_m, "size_m": list(support.size_m),
               "center_xy_m": list(support.center_xy_m), "thickness_m": support.thickness_m,
               "friction": support.friction, "restitution": support.restitution,
               "floor_z_m": support.floor_z_m,
               "obstacles": [object_to_dict(b) for b in support.obstacles]}
    sup.update(priors_to_dict(support.priors))
    out = {"format": SCENE_FORMAT, "name": scene.name, "gravity_m_s2": list(scene.gravity_m_s2)}
    if scene.horizon_s is not None:
        out["horizon_s"] = scene.horizon_s
    if scene.set_down_m:
        out["set_down_m"] = scene.set_down_m
    out.update(support=sup, objects=[object_to_dict(b) for b in scene.objects])
    return out


def scene_to_json(scene: Scene, indent: int | None = None) -> str:
    return json.dumps(scene_to_dict(scene), indent=indent, allow_nan=False)


def write_scenes(scenes: list[Scene], path: str | Path) -> None:
    """Write one scene as an object, several as a list, in the JSON format."""
    payload: Any = scene_to_dict(scenes[0]) if len(scenes) == 1 else [scene_to_dict(s) for s in scenes]
    Path(path).write_text(json.dumps(payload, indent=1, allow_nan=False) + "\n")


# --------------------------------------------------------------------------------------------
# from JSON

def _require_mapping(data: Any, path: str) -> dict:
    if not isinstance(data, dict):
        raise SceneError(path or "scene", f"must be a JSON object, got {_json_type(data)}")
    return data


def _check_keys(data: dict, required: Iterable[str], optional: Iterable[str], path: str) -> None:
    required, optional = tuple(required), tuple(optional)
    unknown = sorted(set(data) - set(required) - set(optional))
    if unknown:
        key = unknown[0]
        # a key that is not a plain name ("", "a b", 5 MB of text) is shown quoted and cut
        name = key if key.isidentifier() and len(key) <= 64 else f"[{shown(key)}]"
        where = f"{path}.{name}" if path and not name.startswith("[") else f"{path}{name}"
        raise SceneError(where, f"unknown field; allowed fields are {', '.join(required + optional)}")
    for key in required:
        if key not in data:
            raise SceneError(f"{path}.{key}" if path else key, "required field is missing")


def _vec(value: Any, n: int, path: str) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        raise SceneError(path, f"must be a list of {n} numbers, got {shown(value)}")
    return tuple(float(v) for v in value)


def _num(value: Any, path: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(path, f"must be a number, got {shown(value)}")
    return float(value)


def shape_from_dict(data: Any, path: str, *, nested: bool = False, meshes: MeshAccess | None = None):
    """A shape; a mesh shape is read through ``meshes`` (None: refused) and becomes its convex parts."""
    data = _require_mapping(data, path)
    kind = data.get("type")
    if not isinstance(kind, str) or kind not in _SHAPE_FIELDS or (nested and kind in ("compound", "mesh")):
        allowed = [t for t in (*SHAPE_TYPES, "mesh") if not (nested and t in ("compound", "mesh"))]
        raise SceneError(f"{path}.type", f"must be one of {', '.join(allowed)}, got {shown(kind)}")
    _check_keys(data, ("type", *_SHAPE_FIELDS[kind]), _SHAPE_OPTIONAL.get(kind, ()), path)
    if kind == "mesh":
        return mesh_shape(data, path, meshes)
    if kind == "box":
        return BoxShape(_vec(data["extents_m"], 3, f"{path}.extents_m"))  # type: ignore[arg-type]
    if kind == "sphere":
        return Sphere(_num(data["radius_m"], f"{path}.radius_m"))
    if kind in ("cylinder", "capsule"):
        cls = Cylinder if kind == "cylinder" else Capsule
        return cls(_num(data["radius_m"], f"{path}.radius_m"), _num(data["length_m"], f"{path}.length_m"))
    if kind == "convex":
        vertices = data["vertices_m"]
        if not isinstance(vertices, list):
            raise SceneError(f"{path}.vertices_m", "must be a list of [x, y, z] points")
        return ConvexHull(tuple(_vec(v, 3, f"{path}.vertices_m[{i}]") for i, v in enumerate(vertices)))
    parts = data["parts"]
    if not isinstance(parts, list):
        raise SceneError(f"{path}.parts", "must be a list of {shape, position_m, orientation_xyzw} parts")
    out = []
    for i, part in enumerate(parts):
        where = f"{path}.parts[{i}]"
        part = _require_mapping(part, where)
        _check_keys(part, ("shape",), ("position_m", "orientation_xyzw"), where)
        out.append(CompoundPart(shape=shape_from_dict(part["shape"], f"{where}.shape", nested=True),
                                position_m=_vec(part.get("position_m", [0.0, 0.0, 0.0]), 3, f"{where}.position_m"),
                                orientation_xyzw=_vec(part.get("orientation_xyzw", [0.0, 0.0, 0.0, 1.0]), 4,
                                                      f"{where}.orientation_xyzw")))
    volume, centre = data.get("volume_m3"), data.get("centre_of_mass_m")
    inertia = data.get("inertia_diagonal_per_kg_m2")
    return Compound(tuple(out), None if volume is None else _num(volume, f"{path}.volume_m3"),
                    None if centre is None else _vec(centre, 3, f"{path}.centre_of_mass_m"),
                    None if inertia is None else _vec(inertia, 3, f"{path}.inertia_diagonal_per_kg_m2"),
                    None if "source" not in data else _mesh_source(data["source"], f"{path}.source", meshes))


def _mesh_source(data: Any, path: str, meshes: MeshAccess | None) -> MeshSource:
    """The mesh file a compound was read from: shown; read again (to draw it) only where ``meshes``
    would read it as a mesh shape (under its roots), never where the scene merely says so."""
    data = _require_mapping(data, path)
    _check_keys(data, ("uri", "scale"), ("repaired",), path)
    repaired = data.get("repaired")
    if repaired is not None and (not isinstance(repaired, str) or len(repaired) > 500):
        raise SceneError(f"{path}.repaired", f"must be text (how an open mesh was closed), got {shown(repaired)}")
    uri = data["uri"]
    if not isinstance(uri, str) or not uri.strip():
        raise SceneError(f"{path}.uri", f"must be the mesh's path or URI, got {shown(uri)}")
    scale = _vec(data["scale"], 3, f"{path}.scale")
    if not all(math.isfinite(v) and v > 0 for v in scale):
        raise SceneError(f"{path}.scale", f"must be 3 finite numbers > 0 (metres per file unit), got {list(scale)}")
    return MeshSource(uri, scale, read_from=readable_source(uri, meshes), repaired=repaired)


def _common_fields(data: dict, path: str) -> dict[str, Any]:
    name = data["name"]
    if not isinstance(name, str):
        raise SceneError(f"{path}.name", f"must be a string, got {shown(name)}")
    mass = data.get("mass_kg")
    density = data.get("density_kg_m3")
    group = data.get("group", "")
    static = data.get("static", False)
    if not isinstance(group, str):
        raise SceneError(f"{path}.group", f"must be a string, got {shown(group)}")
    if not isinstance(static, bool):
        raise SceneError(f"{path}.static", f"must be true or false, got {shown(static)}")
    return dict(name=name,
                position_m=_vec(data["position_m"], 3, f"{path}.position_m"),
                orientation_xyzw=_vec(data["orientation_xyzw"], 4, f"{path}.orientation_xyzw"),
                friction=_num(data["friction"], f"{path}.friction"),
                restitution=_num(data["restitution"], f"{path}.restitution"),
                mass_kg=None if mass is None else _num(mass, f"{path}.mass_kg"),
                density_kg_m3=None if density is None else _num(density, f"{path}.density_kg_m3"),
                group=group, static=static)


def box_from_dict(data: Any, path: str) -> Body:
    """A ``/1`` box."""
    data = _require_mapping(data, path)
    _check_keys(data, _BOX_REQUIRED, _BOX_OPTIONAL, path)
    return Box(extents_m=_vec(data["extents_m"], 3, f"{path}.extents_m"), **_common_fields(data, path))


def object_from_dict(data: Any, path: str, meshes: MeshAccess | None = None) -> Body:
    """A ``/2`` object (its mesh shape read through ``meshes``)."""
    data = _require_mapping(data, path)
    _check_keys(data, OBJECT_REQUIRED, _OBJECT_OPTIONAL, path)
    fields = _common_fields(data, path)
    sigma = data.get("position_sigma_m")
    if sigma is not None and not isinstance(sigma, list):
        sigma = _num(sigma, f"{path}.position_sigma_m")
    elif sigma is not None:
        sigma = _vec(sigma, 3, f"{path}.position_sigma_m")
    yaw = data.get("yaw_sigma_rad")
    shape = shape_from_dict(data["shape"], f"{path}.shape", meshes=meshes)
    given = dict(fields)
    if given["mass_kg"] is None and given["density_kg_m3"] is not None:  # the mass a log-normal centres on
        given["mass_kg"] = given["density_kg_m3"] * volume_m3(shape)
    return Body(shape=shape,
                linear_velocity_m_s=_vec(data.get("linear_velocity_m_s", [0.0, 0.0, 0.0]), 3,
                                         f"{path}.linear_velocity_m_s"),  # type: ignore[arg-type]
                angular_velocity_rad_s=_vec(data.get("angular_velocity_rad_s", [0.0, 0.0, 0.0]), 3,
                                            f"{path}.angular_velocity_rad_s"),  # type: ignore[arg-type]
                position_sigma_m=sigma, yaw_sigma_rad=None if yaw is None else _num(yaw, f"{path}.yaw_sigma_rad"),
                priors=priors_from_dict(data, path, PROPERTIES, given), **fields)


def _surfaces(data: dict) -> dict[str, float]:
    """The support's friction and restitution, as given (the centres of their priors)."""
    return {prop: _num(data[prop], f"support.{prop}") for prop in SUPPORT_PROPERTIES}


def _support_from_dict(data: Any, read_object) -> Floor | Table:
    data = _require_mapping(data, "support")
    kind = data.get("type")
    if kind == "floor":
        _check_keys(data, FLOOR_FIELDS, SUPPORT_OPTIONAL, "support")
        surfaces = _surfaces(data)
        return Floor(**surfaces, height_m=_num(data["height_m"], "support.height_m"),
                     priors=priors_from_dict(data, "support", SUPPORT_PROPERTIES, surfaces))
    if kind == "table":
        _check_keys(data, TABLE_FIELDS, SUPPORT_OPTIONAL, "support")
        obstacles = data["obstacles"]
        if not isinstance(obstacles, list):
            raise SceneError("support.obstacles", "must be a list of objects (may be empty)")
        floor = data["floor_z_m"]
        top = dict(top_height_m=_num(data["top_height_m"], "support.top_height_m"),
                   size_m=_vec(data["size_m"], 2, "support.size_m"),
                   center_xy_m=_vec(data["center_xy_m"], 2, "support.center_xy_m"),
                   thickness_m=_num(data["thickness_m"], "support.thickness_m"))
        surfaces = _surfaces(data)
        return Table(
            **top, **surfaces,  # type: ignore[arg-type]
            floor_z_m=None if floor is None else _num(floor, "support.floor_z_m"),
            obstacles=tuple(read_object(b, f"support.obstacles[{i}]") for i, b in enumerate(obstacles)),
            priors=priors_from_dict(data, "support", SUPPORT_PROPERTIES, surfaces),
        )
    raise SceneError("support.type", f"must be \"floor\" or \"table\", got {shown(kind)}")


def scene_from_dict(data: Any, max_objects: int = DEFAULT_MAX_OBJECTS, meshes: MeshAccess | None = None) -> Scene:
    """Build and validate a scene from parsed JSON (``/2``, or ``/1``); raises SceneError naming the bad field.
    ``meshes``: where mesh shapes may be read from (None: a mesh shape is refused)."""
    data = _require_mapping(data, "")
    # without a "format", a scene with "boxes" and no "objects" is a /1 scene
    fmt = data.get("format", SCENE_FORMAT_V1 if "boxes" in data and "objects" not in data else SCENE_FORMAT)
    if fmt == SCENE_FORMAT_V1:
        _check_keys(data, _SCENE_REQUIRED_V1, ("format",), "")
        key, read_object = "boxes", box_from_dict
    elif fmt == SCENE_FORMAT:
        _check_keys(data, SCENE_REQUIRED, ("format", "horizon_s", "set_down_m"), "")
        key, read_object = "objects", functools.partial(object_from_dict, meshes=meshes)
    else:
        raise SceneError("format", f"unsupported format {shown(fmt)}; this version reads {shown(SCENE_FORMAT)} and "
                                   f"{shown(SCENE_FORMAT_V1)}")
    items = data[key]
    if not isinstance(items, list):
        raise SceneError(key, f"must be a list of {key}")
    # Count before parsing so that a 10 000-object message fails fast.
    if len(items) > max_objects:
        raise SceneError(key, f"{len(items)} objects exceed the maximum of {max_objects}; "
                              "split the scene or raise max_objects")
    if not isinstance(data["name"], str):
        raise SceneError("name", f"must be a string, got {shown(data['name'])}")
    horizon = data.get("horizon_s")
    scene = Scene(
        name=data["name"],
        objects=tuple(read_object(b, f"{key}[{i}]") for i, b in enumerate(items)),
        support=_support_from_dict(data["support"], read_object),
        gravity_m_s2=_vec(data["gravity_m_s2"], 3, "gravity_m_s2"),  # type: ignore[arg-type]
        horizon_s=None if horizon is None else _num(horizon, "horizon_s"),
        set_down_m=_num(data.get("set_down_m", 0.0), "set_down_m"),
    )
    try:
        return validate_scene(scene, max_objects=max_objects)
    except SceneError as exc:
        if key == "boxes" and exc.field.startswith("objects"):  # name the field as the file does
            field = "boxes" + exc.field[len("objects"):].replace(".shape.extents_m", ".extents_m")
            raise SceneError(field[:-len(".shape")] + ".extents_m" if field.endswith(".shape") else field,
                             exc.problem) from None
        raise


@dataclass(frozen=True)
class RefusedScene:
    """A scene of a file that could not be read, while the others could: its position in the file
    (0-based), its name where readable ("" otherwise) and why."""

    index: int
    name: str
    error: SceneError


#: Called with each scene a file holds that cannot be read; without one the first such scene ends the read.
OnRefused = Callable[[RefusedScene], None]


def _reject_constant(token: str) -> None:
    raise SceneError("json", f"{token} is not a valid number; use finite numbers only")


def scenes_from_json(text: str, max_objects: int = DEFAULT_MAX_OBJECTS, on_refused: OnRefused | None = None,
                     meshes: MeshAccess | None = None) -> list[Scene]:
    """Parse JSON text holding one scene object or a list of them. With ``on_refused``, a scene of
    the list that cannot be read is handed to it and the others are returned (the text itself must
    still be JSON holding scenes)."""
    if len(text) > MAX_JSON_CHARS:
        raise SceneError("json", f"{len(text)} characters exceed the maximum of {MAX_JSON_CHARS}; split the scene")
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise SceneError("json", f"malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}") from None
    except RecursionError:
        raise SceneError("json", "nested too deeply to read; a scene nests a few levels (objects, shapes, "
                                 "parts), not hundreds") from None
    if isinstance(data, list):
        if not data:
            raise SceneError("json", "the list of scenes is empty")
        scenes = []
        for i, item in enumerate(data):
            try:
                scenes.append(scene_from_dict(item, max_objects, meshes))
            except SceneError as exc:
                error = SceneError(f"scenes[{i}].{exc.field}", exc.problem)
                if on_refused is None:
                    raise error from None
                name = item.get("name") if isinstance(item, dict) else None
                on_refused(RefusedScene(i, name[:128] if isinstance(name, str) else "", error))
        if not scenes and on_refused is not None:
            raise SceneError("json", f"none of the {len(data)} scenes can be read (each refusal is reported)")
        return scenes
    return [scene_from_dict(data, max_objects, meshes)]
