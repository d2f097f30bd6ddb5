"""``visualization_msgs/MarkerArray`` <-> :class:`~ipe_ros.engine.Scene` (predictions as markers:
``prediction_markers``).

The mapping (MarkerArray has no notion of mass, friction or support, so some of it rides in
``Marker.text``):

* Every marker with action ``ADD`` is a body, ``pose`` its frame in ``header.frame_id`` (an all-zero
  quaternion, the message default, means identity, as RViz reads it; any other must have unit norm):
  ``CUBE``: a box, ``scale`` its FULL extents in metres; ``SPHERE``: a sphere of diameter ``scale``
  (all three equal: an ellipsoid is refused); ``CYLINDER``: a cylinder along its z, diameter
  ``scale.x`` (= ``scale.y``), length ``scale.z``; ``TRIANGLE_LIST``: the convex hull of its
  ``points`` (each multiplied by ``scale``, as RViz draws them): cones, pyramids, wedges; with
  ``decompose=true`` in ``text``, the closed surface its triangles make, as convex parts (a mug);
  ``MESH_RESOURCE``: the closed mesh at ``mesh_resource`` (``package://`` or ``file://``, under the
  node's ``mesh_roots``), scaled by ``scale`` per axis, read as its convex parts
  (``engine.scene.meshes``; ``mesh_use_embedded_materials`` is a colour and is ignored); a scene's
  objects read from a mesh file go out as this marker again (``scene_to_markers``, and the
  prediction's markers: RViz draws the mesh, not its parts). Capsules and compounds given as parts
  have no marker: publish them on ``~/scene_json``.
* Markers in namespace ``support`` are static. ``text`` ``role=floor`` makes an infinite floor whose
  top is the cube's top face; ``role=table`` makes a table top (axis-aligned; the cube is the slab);
  ``role=obstacle`` (the default) a static box (a wall on the table, a fixture on the floor). At most
  one floor or table; with neither, the floor is the plane z = 0 of the scene frame.
* Every other marker is a dynamic box named ``text``'s ``name`` or else ``<ns>/<id>``.
* ``text`` holds optional ``key=value`` pairs separated by spaces, commas or semicolons:
    dynamic bodies: ``name``, ``mass`` (kg) or ``density`` (kg/m^3, of the true volume),
    ``friction``, ``restitution``, ``group``; ``vx vy vz`` (m/s) and ``wx wy wz`` (rad/s), the
    velocity at t = 0; ``sigma`` (m) and ``yaw_sigma`` (rad), the body's own position noise (0: known
    exactly); without ``group`` a body with a non-zero colour gets the nearest named colour
    ("red", "yellow", ...), as in the paper's Exp. 5.
    floor/table: ``friction``, ``restitution``, ``gravity`` (vertical, m/s^2, default -9.81),
    ``scene`` (the scene's name); tables also ``floor_z`` (metres or ``none``; default: a floor at
    z = 0 when the slab's underside is at or above 0).
    obstacles: ``name``, ``friction``, ``restitution``, ``group``.
* ``DELETEALL`` and ``DELETE`` markers are ignored: every array is a complete scene, so clearing the
  previous one is implicit (RViz publishers often start with a DELETEALL). Any other marker type is
  rejected: silently dropping a mesh would hide an object from the physics.
* All markers must share one non-empty ``header.frame_id``. The scene's stamp is the first
  marker's ``header.stamp``.

Errors are :class:`~ipe_ros.engine.SceneError` (a ValueError) naming ``markers[i]`` and the field.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from dataclasses import dataclass

import numpy as np
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ipe_ros.engine import (Body, Box, BoxShape, ConvexHull, Cylinder, Floor, Scene, SceneError, Sphere, Table,
                            validate_scene)
from ipe_ros.engine.scene import shapes
from ipe_ros.engine.config import MODEL_LIGHT_DENSITY_KG_M3
from ipe_ros.viz.palette import SUPPORT_RGB, group_rgb, nearest_group_name
from ipe_ros.engine.errors import shown
from ipe_ros.engine.scene.bodies import DEFAULT_MAX_OBJECTS
from ipe_ros.engine.scene.meshes import MeshAccess, mesh_shape, triangles_shape

from .stamps import header_to_stamp_ns, stamp_ns_to_header

SUPPORT_NAMESPACE = "support"
DEFAULT_FRICTION = 0.9
DEFAULT_RESTITUTION = 0.0
#: The paper's light blocks (4.08 kg for 0.2 x 0.6 x 0.2 m): used when a box gives no mass or density.
DEFAULT_DENSITY_KG_M3 = MODEL_LIGHT_DENSITY_KG_M3
DEFAULT_GRAVITY_M_S2 = -9.81
DEFAULT_SCENE_NAME = "markers"
#: Thickness of the cube that stands for an infinite floor when a scene is turned into markers.
FLOOR_MARKER_THICKNESS_M = 0.01
FLOOR_MARKER_SIZE_M = 20.0

_DYNAMIC_KEYS = ("name", "mass", "density", "friction", "restitution", "group", "vx", "vy", "vz", "wx", "wy", "wz",
                 "sigma", "yaw_sigma", "decompose")
_FLOOR_KEYS = ("role", "name", "friction", "restitution", "gravity", "scene")
_TABLE_KEYS = _FLOOR_KEYS + ("floor_z",)
_OBSTACLE_KEYS = ("role", "name", "friction", "restitution", "group")
_ROLES = ("floor", "table", "obstacle")
_TYPE_NAMES = {getattr(Marker, n): n for n in ("ARROW", "CUBE", "SPHERE", "CYLINDER", "LINE_STRIP", "LINE_LIST",
                                               "CUBE_LIST", "SPHERE_LIST", "POINTS", "TEXT_VIEW_FACING",
                                               "MESH_RESOURCE", "TRIANGLE_LIST", "ARROW_STRIP")
               if hasattr(Marker, n)}


@dataclass(frozen=True)
class MarkerScene:
    """A scene read from a MarkerArray with the header it came with (stamp in ns since the epoch)."""

    scene: Scene
    frame_id: str
    stamp_ns: int


def parse_properties(text: str, allowed: tuple[str, ...], field: str) -> dict[str, str]:
    """``"mass=2 group=red"`` -> {"mass": "2", "group": "red"}; unknown keys or bad pairs raise."""
    props: dict[str, str] = {}
    for token in (t for t in re.split(r"[\s,;]+", text.strip()) if t):
        key, sep, value = token.partition("=")
        if not sep or not key or not value:
            raise SceneError(field, f"expected key=value pairs, got {shown(token)}")
        if key not in allowed:
            raise SceneError(field, f"unknown key {shown(key)}; allowed here: {', '.join(allowed)}")
        if key in props:
            raise SceneError(field, f"key {shown(key)} is given twice")
        props[key] = value
    return props


def _number(props: dict[str, str], key: str, field: str, default: float | None) -> float | None:
    if key not in props:
        return default
    try:
        value = float(props[key])
    except ValueError:
        raise SceneError(f"{field}.{key}", f"expected a number, got {shown(props[key])}") from None
    if not math.isfinite(value):
        raise SceneError(f"{field}.{key}", f"must be finite, got {shown(props[key])}")
    return value


def _orientation(marker: Marker) -> tuple[float, float, float, float]:
    q = marker.pose.orientation
    xyzw = (float(q.x), float(q.y), float(q.z), float(q.w))
    return (0.0, 0.0, 0.0, 1.0) if xyzw == (0.0, 0.0, 0.0, 0.0) else xyzw


def _vectors(marker: Marker, field: str) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    p, s = marker.pose.position, marker.scale
    position = (float(p.x), float(p.y), float(p.z))
    extents = (float(s.x), float(s.y), float(s.z))
    if not all(math.isfinite(v) for v in position):
        raise SceneError(f"{field}.pose.position", f"must be finite, got {list(position)}")
    if not all(math.isfinite(v) and v > 0 for v in extents):
        raise SceneError(f"{field}.scale", f"full sizes must be finite and > 0 m, got {list(extents)}")
    return position, extents


_BODY_TYPES = ("CUBE", "SPHERE", "CYLINDER", "TRIANGLE_LIST", "MESH_RESOURCE")


def _shape(marker: Marker, extents: tuple[float, float, float], field: str, meshes: MeshAccess | None,
           decompose: bool = False):
    """The body's shape from the marker's type and scale (``decompose``: a TRIANGLE_LIST's closed
    surface as convex parts, not its hull)."""
    if marker.type == Marker.MESH_RESOURCE:  # scale: per-axis factors of the file's units, as RViz draws it
        return mesh_shape({"uri": marker.mesh_resource, "scale": list(extents)}, field, meshes,
                          uri_field=f"{field}.mesh_resource")
    if marker.type == Marker.CUBE:
        return BoxShape(extents)
    if marker.type == Marker.SPHERE:
        if max(extents) - min(extents) > 1e-9 * max(extents):
            raise SceneError(f"{field}.scale", f"a SPHERE needs three equal scales (its diameter), got {list(extents)}; "
                                               "an ellipsoid cannot be simulated: approximate it by a TRIANGLE_LIST")
        return Sphere(extents[0] / 2)
    if marker.type == Marker.CYLINDER:
        if abs(extents[0] - extents[1]) > 1e-9 * max(extents):
            raise SceneError(f"{field}.scale", f"a CYLINDER needs scale.x = scale.y (its diameter), got {list(extents)}")
        return Cylinder(extents[0] / 2, extents[2])
    points = tuple((float(p.x) * extents[0], float(p.y) * extents[1], float(p.z) * extents[2]) for p in marker.points)
    if not all(math.isfinite(v) for point in points for v in point):
        raise SceneError(f"{field}.points", "must be finite")
    if decompose:  # no file is read: allowed without mesh_roots, decomposed and cached as a mesh is
        return triangles_shape(np.array(points), f"{field}.points", meshes or MeshAccess(roots=()))
    return ConvexHull(points)


def _triangles(shape) -> list[tuple[float, float, float]]:
    """The faces of a hull (or of each hull of a compound) as TRIANGLE_LIST points in the body frame."""
    vertices, triangles = shapes.hull_faces(shape)
    return [tuple(float(v) for v in vertices[k]) for face in triangles for k in face]


def _is_identity(q: tuple[float, float, float, float]) -> bool:
    return abs(q[0]) < 1e-9 and abs(q[1]) < 1e-9 and abs(q[2]) < 1e-9 and abs(abs(q[3]) - 1) < 1e-9


def markers_to_scene(msg: MarkerArray, *, max_objects: int = DEFAULT_MAX_OBJECTS,
                     meshes: MeshAccess | None = None) -> MarkerScene:
    """Read a scene from a MarkerArray (see the module docstring for the mapping) and validate it;
    MESH_RESOURCE markers read through ``meshes`` (None: refused). In three parts: the array's markers
    checked (``_body_markers``), each read as the support, an obstacle or a body (``_support_part``,
    ``_dynamic_body``), and the scene assembled from them."""
    adds, frame_id = _body_markers(msg, max_objects)
    dynamic: list[Body] = []
    obstacles: list[Body] = []
    support: Floor | Table | None = None
    gravity_z, scene_name = DEFAULT_GRAVITY_M_S2, DEFAULT_SCENE_NAME
    for i, m in adds:
        field = f"markers[{i}]"
        position, extents = _vectors(m, field)
        orientation = _orientation(m)
        if m.ns != SUPPORT_NAMESPACE:
            dynamic.append(_dynamic_body(m, field, position, extents, orientation, meshes))
            continue
        part = _support_part(m, field, position, extents, orientation)
        if isinstance(part, Body):
            obstacles.append(part)
            continue
        if support is not None:
            raise SceneError(f"{field}.text.role", f"a second {part[3]}: a scene has one floor or one table")
        support, gravity_z = part[0], part[1]
        scene_name = part[2] if part[2] is not None else scene_name
    if not dynamic:
        raise SceneError("markers", "no dynamic bodies: every marker is in the 'support' namespace; "
                                    "put the objects that may fall in another namespace")
    if support is None:
        support = Floor(friction=DEFAULT_FRICTION, restitution=DEFAULT_RESTITUTION, height_m=0.0)
    if isinstance(support, Table):
        support = dataclasses.replace(support, obstacles=tuple(obstacles))
        boxes = tuple(dynamic)
    else:
        boxes = tuple(dynamic) + tuple(obstacles)
    scene = Scene(name=scene_name, objects=boxes, support=support, gravity_m_s2=(0.0, 0.0, gravity_z))
    validate_scene(scene, max_objects=max_objects)
    return MarkerScene(scene=scene, frame_id=frame_id, stamp_ns=header_to_stamp_ns(adds[0][1].header))


def _body_markers(msg: MarkerArray, max_objects: int) -> tuple[list[tuple[int, Marker]], str]:
    """The ADD markers with their indices, and their one frame: each an ADD of a type that describes
    a body, in the first one's frame, its (ns, id) unique."""
    adds = [(i, m) for i, m in enumerate(msg.markers) if m.action not in (Marker.DELETE, Marker.DELETEALL)]
    if not adds:
        raise SceneError("markers", "the array holds no ADD markers; publish one CUBE, SPHERE, CYLINDER or "
                                    "TRIANGLE_LIST marker per body")
    # Count before converting anything, so a runaway array costs O(n) and nothing more.
    if len(adds) > max_objects:
        raise SceneError("markers", f"{len(adds)} markers exceed max_objects = {max_objects}; "
                                    "raise the max_objects parameter or publish a smaller scene")
    frame_id = adds[0][1].header.frame_id
    if not frame_id:
        raise SceneError(f"markers[{adds[0][0]}].header.frame_id", "is empty; set the frame the poses are in")
    seen: dict[tuple[str, int], int] = {}
    for i, m in adds:
        field = f"markers[{i}]"
        if m.action != Marker.ADD:
            raise SceneError(f"{field}.action", f"must be ADD (0), DELETE (2) or DELETEALL (3), got {m.action}")
        if _TYPE_NAMES.get(m.type) not in _BODY_TYPES or (m.ns == SUPPORT_NAMESPACE and m.type != Marker.CUBE):
            allowed = "CUBE" if m.ns == SUPPORT_NAMESPACE else ", ".join(_BODY_TYPES)
            raise SceneError(f"{field}.type", f"only {allowed} markers describe bodies here, got "
                                              f"{_TYPE_NAMES.get(m.type, m.type)} (ns {shown(m.ns)}, id {m.id}); "
                                              "drop it from the scene array")
        if m.header.frame_id != frame_id:
            raise SceneError(f"{field}.header.frame_id", f"is {shown(m.header.frame_id)} but markers[{adds[0][0]}] is in "
                                                         f"{shown(frame_id)}; publish every marker of a scene in one frame")
        key = (m.ns, m.id)
        if key in seen:
            raise SceneError(field, f"ns {shown(m.ns)} id {m.id} repeats markers[{seen[key]}]; "
                                    "give each marker a unique (ns, id)")
        seen[key] = i
    return adds, frame_id


def _support_part(m: Marker, field: str, position, extents, orientation):
    """A 'support' marker: an obstacle (a static Box), or (the floor or table, gravity, the scene's
    name or None, its role)."""
    every_key = tuple(dict.fromkeys(_TABLE_KEYS + _OBSTACLE_KEYS))
    role = parse_properties(m.text, every_key, f"{field}.text").get("role", "obstacle")
    if role not in _ROLES:
        raise SceneError(f"{field}.text.role", f"must be one of {', '.join(_ROLES)}, got {shown(role)}")
    allowed = {"floor": _FLOOR_KEYS, "table": _TABLE_KEYS, "obstacle": _OBSTACLE_KEYS}[role]
    props = parse_properties(m.text, allowed, f"{field}.text")
    friction = _number(props, "friction", f"{field}.text", DEFAULT_FRICTION)
    restitution = _number(props, "restitution", f"{field}.text", DEFAULT_RESTITUTION)
    if role == "obstacle":
        return Box(name=props.get("name", f"{m.ns}/{m.id}"), extents_m=extents, position_m=position,
                   orientation_xyzw=orientation, friction=friction, restitution=restitution,
                   group=props.get("group", ""), static=True)
    if not _is_identity(orientation) and role == "table":
        raise SceneError(f"{field}.pose.orientation", "a table must be axis-aligned in the scene frame "
                                                      "(identity orientation); rotate the frame instead")
    if role == "floor" and not _is_identity(orientation):
        raise SceneError(f"{field}.pose.orientation", "a floor must be horizontal (identity orientation)")
    gravity_z = _number(props, "gravity", f"{field}.text", DEFAULT_GRAVITY_M_S2)
    top = position[2] + extents[2] / 2
    if role == "floor":
        return Floor(friction=friction, restitution=restitution, height_m=top), gravity_z, props.get("scene"), role
    underside = position[2] - extents[2] / 2
    if props.get("floor_z", "").lower() == "none":
        floor_z = None
    else:
        floor_z = _number(props, "floor_z", f"{field}.text", 0.0 if underside >= 0 else None)
    table = Table(top_height_m=top, size_m=extents[:2], center_xy_m=position[:2], thickness_m=extents[2],
                  friction=friction, restitution=restitution, floor_z_m=floor_z)
    return table, gravity_z, props.get("scene"), role


def _dynamic_body(m: Marker, field: str, position, extents, orientation, meshes: MeshAccess | None) -> Body:
    """A body that may move: its shape, and its mass, surface, group, velocity and noise from the text."""
    props = parse_properties(m.text, _DYNAMIC_KEYS, f"{field}.text")
    decompose = props.get("decompose", "false").lower()
    if decompose not in ("true", "false") or (decompose == "true" and m.type != Marker.TRIANGLE_LIST):
        raise SceneError(f"{field}.text", f"decompose=true is for TRIANGLE_LIST markers (their closed surface as "
                                          f"convex parts, not their hull), got decompose={props['decompose']} on a "
                                          f"{_TYPE_NAMES.get(m.type, m.type)}")
    shape = _shape(m, extents, field, meshes, decompose == "true")
    if "mass" in props and "density" in props:
        raise SceneError(f"{field}.text", "give mass or density, not both")
    mass = _number(props, "mass", f"{field}.text", None)
    density = _number(props, "density", f"{field}.text", None)
    if mass is None and density is None:
        density = DEFAULT_DENSITY_KG_M3
    group = props.get("group")
    if group is None:
        c = m.color
        group = "" if (c.r, c.g, c.b) == (0.0, 0.0, 0.0) and c.a == 0.0 else nearest_group_name(c.r, c.g, c.b)
    velocity = tuple(_number(props, k, f"{field}.text", 0.0) for k in ("vx", "vy", "vz"))
    spin = tuple(_number(props, k, f"{field}.text", 0.0) for k in ("wx", "wy", "wz"))
    return Body(name=props.get("name", f"{m.ns}/{m.id}"), shape=shape, position_m=position,
                orientation_xyzw=orientation,
                friction=_number(props, "friction", f"{field}.text", DEFAULT_FRICTION),
                restitution=_number(props, "restitution", f"{field}.text", DEFAULT_RESTITUTION),
                mass_kg=mass, density_kg_m3=None if mass is not None else density, group=group,
                linear_velocity_m_s=velocity, angular_velocity_rad_s=spin,
                position_sigma_m=_number(props, "sigma", f"{field}.text", None),
                yaw_sigma_rad=_number(props, "yaw_sigma", f"{field}.text", None))


def _fmt(value: float) -> str:
    return repr(float(value))  # shortest text that reads back to the same float


def _cube(header, ns: str, marker_id: int, position, extents, orientation, rgb, alpha: float, text: str) -> Marker:
    # each marker its own Header: a shared one would make an edit of one marker change them all
    m = Marker(header=copy.deepcopy(header), ns=ns, id=marker_id, type=Marker.CUBE, action=Marker.ADD, text=text)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in position)
    q = m.pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in orientation)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in extents)
    m.color = ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(alpha))
    return m


def body_marker(header, ns: str, marker_id: int, body: Body, rgb, alpha: float, text: str, *,
                 exact: bool = True) -> Marker:
    """A marker in the body's own shape. ``exact``: refuse shapes no marker carries (capsules,
    compounds), else draw them as triangles."""
    shape = body.shape
    m = _cube(header, ns, marker_id, body.position_m, (1.0, 1.0, 1.0), body.orientation_xyzw, rgb, alpha, text)
    if isinstance(shape, BoxShape):
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in shape.extents_m)
    elif isinstance(shape, Sphere):
        m.type = Marker.SPHERE
        m.scale.x = m.scale.y = m.scale.z = 2 * float(shape.radius_m)
    elif isinstance(shape, Cylinder):
        m.type = Marker.CYLINDER
        m.scale.x = m.scale.y = 2 * float(shape.radius_m)
        m.scale.z = float(shape.length_m)
    elif isinstance(shape, ConvexHull) and exact:
        m.type = Marker.TRIANGLE_LIST
        m.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in shape.vertices_m]
    elif isinstance(shape, shapes.Compound) and shape.source is not None:  # the mesh itself, as RViz loads it
        m.type = Marker.MESH_RESOURCE
        m.mesh_resource = shape.source.uri
        m.scale.x, m.scale.y, m.scale.z = (float(v) for v in shape.source.scale)
    elif exact:
        raise ValueError(f"objects ({shown(body.name)}).shape: a {shape.type} has no marker; publish the scene on "
                         "~/scene_json (the JSON format carries every shape)")
    else:
        m.type = Marker.TRIANGLE_LIST
        m.points = [Point(x=x, y=y, z=z) for x, y, z in _triangles(shape)]
    return m


def scene_to_markers(scene: Scene, frame_id: str, stamp_ns: int = 0) -> MarkerArray:
    """The inverse of :func:`markers_to_scene`: ``markers_to_scene(scene_to_markers(s, f)).scene == s``
    (a floor's height up to rounding of ``z + thickness / 2``)."""
    if not frame_id:
        raise ValueError("frame_id: must be a non-empty frame name")
    gx, gy, gz = scene.gravity_m_s2
    if gx != 0 or gy != 0:
        raise ValueError(f"scene.gravity_m_s2: a MarkerArray scene carries vertical gravity only, got {scene.gravity_m_s2}")
    header = stamp_ns_to_header(stamp_ns, frame_id)
    markers: list[Marker] = []
    support = scene.support
    common = f"friction={_fmt(support.friction)} restitution={_fmt(support.restitution)} " \
             f"gravity={_fmt(gz)} scene={scene.name}"
    if isinstance(support, Floor):
        t = FLOOR_MARKER_THICKNESS_M
        markers.append(_cube(header, SUPPORT_NAMESPACE, 0, (0.0, 0.0, support.height_m - t / 2),
                             (FLOOR_MARKER_SIZE_M, FLOOR_MARKER_SIZE_M, t), (0, 0, 0, 1), SUPPORT_RGB, 1.0,
                             f"role=floor {common}"))
    else:
        floor = "none" if support.floor_z_m is None else _fmt(support.floor_z_m)
        markers.append(_cube(header, SUPPORT_NAMESPACE, 0,
                             (*support.center_xy_m, support.top_height_m - support.thickness_m / 2),
                             (*support.size_m, support.thickness_m), (0, 0, 0, 1), SUPPORT_RGB, 1.0,
                             f"role=table {common} floor_z={floor}"))
    for j, box in enumerate(scene.static_objects, start=1):
        if not isinstance(box.shape, BoxShape):
            raise ValueError(f"objects ({shown(box.name)}).shape: a static {box.shape.type} has no marker (the support "
                             "namespace holds CUBEs); publish the scene on ~/scene_json")
        markers.append(_cube(header, SUPPORT_NAMESPACE, j, box.position_m, box.extents_m, box.orientation_xyzw,
                             SUPPORT_RGB, 1.0, f"role=obstacle name={box.name} friction={_fmt(box.friction)} "
                                               f"restitution={_fmt(box.restitution)}"
                                               + (f" group={box.group}" if box.group else "")))
    for j, body in enumerate(scene.dynamic_objects):
        mass = f"mass={_fmt(body.mass_kg)}" if body.mass_kg is not None else f"density={_fmt(body.density_kg_m3)}"
        text = f"name={body.name} {mass} friction={_fmt(body.friction)} restitution={_fmt(body.restitution)}"
        if body.group:
            text += f" group={body.group}"
        for keys, values in ((("vx", "vy", "vz"), body.linear_velocity_m_s), (("wx", "wy", "wz"), body.angular_velocity_rad_s)):
            text += "".join(f" {k}={_fmt(v)}" for k, v in zip(keys, values) if v)
        if isinstance(body.position_sigma_m, (tuple, list)):
            raise ValueError(f"objects ({shown(body.name)}).position_sigma_m: a marker carries one horizontal sigma; "
                             "publish the scene on ~/scene_json")
        if body.position_sigma_m is not None:
            text += f" sigma={_fmt(body.position_sigma_m)}"
        if body.yaw_sigma_rad is not None:
            text += f" yaw_sigma={_fmt(body.yaw_sigma_rad)}"
        markers.append(body_marker(header, "objects", j, body, group_rgb(body.group), 1.0, text))
    for m in markers:
        for value in re.split(r"[\s,;]+", m.text):
            if value.count("=") != 1:
                raise ValueError(f"name: {shown(m.text)} cannot ride in Marker.text; scene and box names "
                                 "must not contain spaces, '=', ',' or ';'")
    return MarkerArray(markers=markers)
