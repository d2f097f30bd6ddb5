"""Rigid shapes in their own frame, and their geometry: volume, centre of mass, extents, rest heights.

Every shape is a frozen dataclass (metres). A cylinder's and a capsule's axis is the object's z; a
capsule's ``length_m`` is the straight section between its two half-sphere caps. A convex hull is the
hull of its vertices; a compound is a rigid union of parts, each a shape at a pose in the object
frame (non-convex objects as convex parts). Pure numpy + scipy (convex hulls); no pybullet here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Union

import numpy as np
from scipy.spatial.transform import Rotation

from . import limits
from ..errors import SceneError, shown

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

#: Points on a sphere used where a shape's surface is sampled (rest heights, pictures): the 42
#: vertices of a twice-subdivided icosahedron, good to 2% of the radius.
_SPHERE_SAMPLES = 42
_CIRCLE_SAMPLES = 24


@dataclass(frozen=True)
class BoxShape:
    extents_m: Vec3  # full edge lengths along x, y, z

    type = "box"


@dataclass(frozen=True)
class Sphere:
    radius_m: float

    type = "sphere"


@dataclass(frozen=True)
class Cylinder:
    radius_m: float
    length_m: float  # along the object's z

    type = "cylinder"


@dataclass(frozen=True)
class Capsule:
    radius_m: float
    length_m: float  # the straight section between the caps, along z

    type = "capsule"


@dataclass(frozen=True)
class ConvexHull:
    vertices_m: tuple[Vec3, ...]  # the hull of these points, in the object frame

    type = "convex"


@dataclass(frozen=True)
class CompoundPart:
    shape: "Primitive"
    position_m: Vec3 = (0.0, 0.0, 0.0)
    orientation_xyzw: Quat = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class MeshSource:
    """The mesh file a compound was read from, as the scene named it: what RViz and the JSON show
    (the physics uses the parts). ``uri`` as given (a path, file:// or package://), ``scale`` metres
    per file unit along x, y, z."""

    uri: str
    scale: Vec3 = (1.0, 1.0, 1.0)
    #: the file the mesh reader itself read (under its roots), which a recording may read again to
    #: draw it; None for a source a scene only names (never read: it could point anywhere)
    read_from: Path | None = field(default=None, compare=False)
    #: how the mesh, open, was closed before it was decomposed (mesh_repair.closed_solid); None: it was closed
    repaired: str | None = None


@dataclass(frozen=True)
class Compound:
    """Convex parts in the object frame. ``volume_m3`` and ``centre_of_mass_m``: those of the solid
    the parts approximate, where it is known (a mesh's own, exact; the parts' hulls overlap and
    overfill a mesh's concave corners, 5-25% more volume): mass and centre of mass come from them.
    Without them, from the parts (taken as not overlapping). ``inertia_diagonal_per_kg_m2``: the
    diagonal of the solid's inertia tensor about its centre of mass in the object frame, per kg
    (m^2; a mesh's own); without it, pybullet's estimate from the parts' bounding box. ``source``:
    the mesh file it was read from (None: given as parts)."""

    parts: tuple[CompoundPart, ...]
    volume_m3: float | None = None
    centre_of_mass_m: Vec3 | None = None
    inertia_diagonal_per_kg_m2: Vec3 | None = None
    #: part of a stored result's key only when set (compounds stored before it keep their keys)
    source: MeshSource | None = field(default=None, metadata={"keyed": "when set"})

    type = "compound"


Primitive = Union[BoxShape, Sphere, Cylinder, Capsule, ConvexHull]
Shape = Union[BoxShape, Sphere, Cylinder, Capsule, ConvexHull, Compound]
SHAPE_TYPES = ("box", "sphere", "cylinder", "capsule", "convex", "compound")


def rotation_matrix(q_xyzw) -> np.ndarray:
    """Rotation matrix of one (normalised here) quaternion in (x, y, z, w) order."""
    return Rotation.from_quat(np.asarray(q_xyzw, dtype=float)).as_matrix()


def quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a * b for (n, 4) xyzw quaternions (b applied first)."""
    return (Rotation.from_quat(np.asarray(a, float)) * Rotation.from_quat(np.asarray(b, float))).as_quat()


# --------------------------------------------------------------------------------------------
# validation

def _positive(value, path: str, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise SceneError(path, f"{what} must be a finite number > 0, got {shown(value)}")


@lru_cache(maxsize=256)
def _hull_properties(vertices: tuple) -> tuple[float, tuple, float]:
    """(volume, centre of mass, smallest distance from it to a face) of the hull of ``vertices``."""
    points = np.asarray(vertices, float).reshape(-1, 3)
    hull = _hull_or_error(points, "vertices_m")
    inner = points[hull.vertices].mean(axis=0)  # inside the hull: each face makes a tetrahedron with it
    tets = points[hull.simplices]  # (faces, 3, 3)
    vols = np.abs(np.einsum("ij,ij->i", tets[:, 0] - inner, np.cross(tets[:, 1] - inner, tets[:, 2] - inner))) / 6
    centre = (((tets.sum(axis=1) + inner) / 4) * vols[:, None]).sum(axis=0) / vols.sum()
    # qhull's equations: n . x + d <= 0 inside, |n| = 1; a point's distance to a face is -(n . x + d)
    rest = float(np.min(-(hull.equations[:, :3] @ centre + hull.equations[:, 3])))
    return float(hull.volume), tuple(float(v) for v in centre), max(0.0, rest)


def _hull_or_error(points: np.ndarray, path: str):
    from scipy.spatial import ConvexHull as QHull, QhullError

    if len(points) < 4:
        raise SceneError(path, f"a convex hull needs at least 4 points not all in one plane, got {len(points)}")
    if not np.all(np.isfinite(points)):
        raise SceneError(path, "vertices must be finite numbers")
    try:
        hull = QHull(points)
    except (QhullError, ValueError):
        raise SceneError(path, "the points are degenerate (all in one plane or on one line); a convex hull needs "
                               "at least 4 points not all in one plane") from None
    span = float(np.max(points.max(axis=0) - points.min(axis=0)))
    if hull.volume <= 1e-9 * span ** 3:
        raise SceneError(path, "the points are (nearly) all in one plane: the hull has no volume")
    return hull


def validate_shape(shape, path: str) -> None:
    """Raise SceneError naming ``path`` + the field when a shape is malformed."""
    if isinstance(shape, BoxShape):
        ext = shape.extents_m
        if not isinstance(ext, tuple) or len(ext) != 3:
            raise SceneError(f"{path}.extents_m", f"must be 3 full extents in metres, got {shown(ext)}")
        if any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0 for v in ext):
            raise SceneError(f"{path}.extents_m", f"every extent must be a finite number > 0 metres, got {list(ext)}")
    elif isinstance(shape, Sphere):
        _positive(shape.radius_m, f"{path}.radius_m", "the radius")
    elif isinstance(shape, (Cylinder, Capsule)):
        _positive(shape.radius_m, f"{path}.radius_m", "the radius")
        if isinstance(shape, Capsule):
            if isinstance(shape.length_m, bool) or not isinstance(shape.length_m, (int, float)) \
                    or not math.isfinite(shape.length_m) or shape.length_m < 0:
                raise SceneError(f"{path}.length_m", f"the straight section must be a finite number >= 0 "
                                                     f"(0: a sphere), got {shown(shape.length_m)}")
        else:
            _positive(shape.length_m, f"{path}.length_m", "the length")
    elif isinstance(shape, ConvexHull):
        if len(shape.vertices_m) > limits.MAX_HULL_VERTICES:  # counted before any hull is computed
            raise SceneError(f"{path}.vertices_m", f"{len(shape.vertices_m)} points exceed the maximum of "
                                                   f"{limits.MAX_HULL_VERTICES} for one hull; decimate the mesh")
        _hull_or_error(np.asarray(shape.vertices_m, float).reshape(-1, 3), f"{path}.vertices_m")
    elif isinstance(shape, Compound):
        if not shape.parts:
            raise SceneError(f"{path}.parts", "a compound needs at least one part")
        if len(shape.parts) > limits.MAX_COMPOUND_PARTS:
            raise SceneError(f"{path}.parts", f"{len(shape.parts)} parts exceed the maximum of "
                                              f"{limits.MAX_COMPOUND_PARTS} for one compound; merge parts into hulls")
        points = sum(len(getattr(part.shape, "vertices_m", ())) for part in shape.parts)
        if points > limits.MAX_COMPOUND_VERTICES:
            raise SceneError(f"{path}.parts", f"its hulls hold {points} points, more than the maximum of "
                                              f"{limits.MAX_COMPOUND_VERTICES} for one compound; decimate them")
        _check_mass_properties(shape, path)
        for i, part in enumerate(shape.parts):
            if isinstance(part.shape, Compound):
                raise SceneError(f"{path}.parts[{i}].shape", "parts must be simple shapes, not compounds; "
                                                             "list the inner parts directly")
            validate_shape(part.shape, f"{path}.parts[{i}].shape")
            if len(part.position_m) != 3 or not all(math.isfinite(v) for v in part.position_m):
                raise SceneError(f"{path}.parts[{i}].position_m", "must be 3 finite numbers (metres)")
            norm = math.sqrt(sum(c * c for c in part.orientation_xyzw))
            if len(part.orientation_xyzw) != 4 or abs(norm - 1.0) > 1e-3:
                raise SceneError(f"{path}.parts[{i}].orientation_xyzw",
                                 f"must be a unit quaternion, got norm {norm:.6g}")
    else:
        raise SceneError(f"{path}.type", f"unknown shape; choose one of {', '.join(SHAPE_TYPES)}")


def _check_mass_properties(shape: Compound, path: str) -> None:
    """A compound's own volume and centre of mass: both or neither, positive and finite, the centre
    within the parts' bounds; its inertia (with them) a rigid body's, within the parts' reach."""
    if (shape.volume_m3 is None) != (shape.centre_of_mass_m is None):
        raise SceneError(f"{path}.volume_m3", "give volume_m3 and centre_of_mass_m together (or neither: both "
                                              "from the parts)")
    if shape.volume_m3 is None:
        if shape.inertia_diagonal_per_kg_m2 is not None:
            raise SceneError(f"{path}.inertia_diagonal_per_kg_m2", "give it with volume_m3 and centre_of_mass_m (the "
                                                                   "solid's own, about that centre)")
        return
    _positive(shape.volume_m3, f"{path}.volume_m3", "the volume")
    centre = shape.centre_of_mass_m
    if len(centre) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in centre):
        raise SceneError(f"{path}.centre_of_mass_m", "must be 3 finite numbers (metres, object frame)")
    vertices, _ = hull_faces(shape)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    if np.any(np.asarray(centre) < low) or np.any(np.asarray(centre) > high):
        raise SceneError(f"{path}.centre_of_mass_m", f"{list(centre)} lies outside the parts' bounds "
                                                     f"{low.round(4).tolist()} .. {high.round(4).tolist()}")
    parts_volume = float(sum(volume_m3(p.shape) for p in shape.parts))
    if not 0.2 * parts_volume <= shape.volume_m3 <= 1.2 * parts_volume:
        raise SceneError(f"{path}.volume_m3", f"{shape.volume_m3:g} m^3 against the parts' {parts_volume:g}: the parts "
                                              "do not describe that solid")
    inertia = shape.inertia_diagonal_per_kg_m2
    if inertia is None:
        return
    where = f"{path}.inertia_diagonal_per_kg_m2"
    if len(inertia) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in inertia):
        raise SceneError(where, "must be 3 finite numbers > 0 (m^2: the inertia about the centre of mass per kg)")
    a, b, c = sorted(inertia)
    reach = float(np.max(np.linalg.norm(vertices - np.asarray(centre), axis=1)))
    if c > (a + b) * (1 + 1e-6) or c > reach ** 2:  # a rigid body's moments, and its mass within its parts
        raise SceneError(where, f"{list(inertia)} m^2 is not a solid's within these parts (each moment at most the "
                                f"sum of the other two, and at most {reach ** 2:.3g}, the parts' reach squared)")


# --------------------------------------------------------------------------------------------
# geometry

@lru_cache(maxsize=1)
def _unit_sphere_points() -> np.ndarray:
    """42 points on the unit sphere (icosahedron subdivided once, normalised)."""
    t = (1 + math.sqrt(5)) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    verts = np.array(v, float)
    verts /= np.linalg.norm(verts, axis=1, keepdims=True)
    # edge midpoints of the icosahedron (edges have the shortest length)
    d = np.linalg.norm(verts[:, None] - verts[None], axis=2)
    edge = d[d > 0].min()
    mids = [(verts[i] + verts[j]) / 2 for i in range(12) for j in range(i + 1, 12) if abs(d[i, j] - edge) < 1e-9]
    points = np.vstack([verts, np.array(mids)])
    return points / np.linalg.norm(points, axis=1, keepdims=True)


def surface_points(shape) -> np.ndarray:
    """(n, 3) points whose convex hull is the shape (exact for boxes and hulls; spheres and round
    sides sampled, inscribed within 2% of the radius)."""
    if isinstance(shape, BoxShape):
        half = np.asarray(shape.extents_m, float) / 2
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        return signs * half
    if isinstance(shape, Sphere):
        return _unit_sphere_points() * shape.radius_m
    if isinstance(shape, Cylinder):
        a = np.linspace(0, 2 * math.pi, _CIRCLE_SAMPLES, endpoint=False)
        ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1) * shape.radius_m
        return np.vstack([ring + [0, 0, shape.length_m / 2], ring - [0, 0, shape.length_m / 2]])
    if isinstance(shape, Capsule):
        ball = _unit_sphere_points() * shape.radius_m
        return np.vstack([ball + [0, 0, shape.length_m / 2], ball - [0, 0, shape.length_m / 2]])
    if isinstance(shape, ConvexHull):
        return np.asarray(shape.vertices_m, float).reshape(-1, 3)
    if isinstance(shape, Compound):
        return np.vstack([surface_points(p.shape) @ rotation_matrix(p.orientation_xyzw).T + np.asarray(p.position_m)
                          for p in shape.parts])
    raise TypeError(f"not a shape: {shown(shape)}")


def hull_faces(shape) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3), triangles (m, 3) indexing them) of the shape's convex hull in its own frame,
    or of each part's hull for a compound (a non-convex object drawn as its convex parts)."""
    from scipy.spatial import ConvexHull as QHull

    parts = shape.parts if isinstance(shape, Compound) else (CompoundPart(shape),)
    vertices, triangles, count = [], [], 0
    for part in parts:
        points = surface_points(part.shape) @ rotation_matrix(part.orientation_xyzw).T + np.asarray(part.position_m)
        triangles.append(QHull(points).simplices + count)
        vertices.append(points)
        count += len(points)
    return np.vstack(vertices), np.vstack(triangles)


def volume_m3(shape) -> float:
    """The shape's true volume (a compound's parts are taken as not overlapping)."""
    if isinstance(shape, BoxShape):
        return float(np.prod(shape.extents_m))
    if isinstance(shape, Sphere):
        return 4 / 3 * math.pi * shape.radius_m ** 3
    if isinstance(shape, Cylinder):
        return math.pi * shape.radius_m ** 2 * shape.length_m
    if isinstance(shape, Capsule):
        return math.pi * shape.radius_m ** 2 * shape.length_m + 4 / 3 * math.pi * shape.radius_m ** 3
    if isinstance(shape, ConvexHull):
        return _hull_properties(tuple(map(tuple, surface_points(shape))))[0]
    if isinstance(shape, Compound):
        if shape.volume_m3 is not None:
            return float(shape.volume_m3)
        return float(sum(volume_m3(p.shape) for p in shape.parts))
    raise TypeError(f"not a shape: {shown(shape)}")


def centre_of_mass_m(shape) -> np.ndarray:
    """Centre of mass of the uniformly dense shape, in its own frame."""
    if isinstance(shape, (BoxShape, Sphere, Cylinder, Capsule)):
        return np.zeros(3)
    if isinstance(shape, ConvexHull):
        return np.array(_hull_properties(tuple(map(tuple, surface_points(shape))))[1])
    if isinstance(shape, Compound):
        if shape.centre_of_mass_m is not None:
            return np.array(shape.centre_of_mass_m, float)
        vols = np.array([volume_m3(p.shape) for p in shape.parts])
        centres = np.array([rotation_matrix(p.orientation_xyzw) @ centre_of_mass_m(p.shape) + np.asarray(p.position_m)
                            for p in shape.parts])
        return (centres * vols[:, None]).sum(axis=0) / vols.sum()
    raise TypeError(f"not a shape: {shown(shape)}")


def extents_m(shape) -> Vec3:
    """Full sizes of the shape's bounding box along its own axes."""
    if isinstance(shape, BoxShape):
        return tuple(float(v) for v in shape.extents_m)
    if isinstance(shape, Sphere):
        return (2 * shape.radius_m,) * 3
    if isinstance(shape, Cylinder):
        return (2 * shape.radius_m, 2 * shape.radius_m, shape.length_m)
    if isinstance(shape, Capsule):
        return (2 * shape.radius_m, 2 * shape.radius_m, shape.length_m + 2 * shape.radius_m)
    points = surface_points(shape)
    return tuple(float(v) for v in points.max(axis=0) - points.min(axis=0))


def min_rest_height_m(shape) -> float:
    """The lowest its centre of mass can be above a plane the shape rests on, over every orientation.

    A rigid body rests on a plane with one face of its convex hull: the smallest distance from the
    centre of mass to a hull face. Exact for spheres, boxes, cylinders and capsules; for sampled
    round parts a little low (inscribed samples), which errs on the safe side where it is used.
    """
    if isinstance(shape, BoxShape):
        return min(shape.extents_m) / 2
    if isinstance(shape, (Sphere, Capsule)):
        return shape.radius_m
    if isinstance(shape, Cylinder):
        return min(shape.radius_m, shape.length_m / 2)
    if isinstance(shape, ConvexHull):
        return _hull_properties(tuple(map(tuple, surface_points(shape))))[2]
    # a compound rests on a face of the hull of all its parts, around its own centre of mass
    points = surface_points(shape) - centre_of_mass_m(shape)
    hull = _hull_or_error(points, "vertices_m")
    return float(max(0.0, np.min(-hull.equations[:, 3])))


def half_height_m(shape, orientation_xyzw) -> float:
    """How far the shape reaches below its centre of mass, at this orientation."""
    if isinstance(shape, BoxShape):
        return float(0.5 * np.abs(rotation_matrix(orientation_xyzw)[2, :]) @ np.asarray(shape.extents_m, float))
    if isinstance(shape, Sphere):
        return shape.radius_m
    points = (surface_points(shape) - centre_of_mass_m(shape)) @ rotation_matrix(orientation_xyzw).T
    return float(-points[:, 2].min())
