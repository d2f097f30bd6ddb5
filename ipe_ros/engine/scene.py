"""Scenes as plain typed values: rigid boxes on a floor or a table.

Conventions: SI units (metres, kilograms, seconds), z up, right-handed. Orientations are unit
quaternions in (x, y, z, w) order, as pybullet and ROS use them. Extents are FULL box sizes along
the box's own axes (not half extents).

Everything here is a frozen dataclass: scenes pass between layers and processes by value.
``validate_scene`` checks a scene once, where it enters the engine; it raises
:class:`~ipe_ros.engine.errors.SceneError` naming the object and field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from .errors import SceneError

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

#: A quaternion whose norm differs from 1 by more than this is rejected (not renormalised silently).
QUATERNION_NORM_TOLERANCE = 1e-3
#: Default cap on the number of boxes in one scene (a configurable guard against runaway input).
DEFAULT_MAX_OBJECTS = 200
#: The group label that marks a box as heavy for the mass ratio mu (case-insensitive).
HEAVY_GROUP = "heavy"


@dataclass(frozen=True)
class Box:
    """One rigid cuboid.

    Attributes:
        name: unique within the scene; used in per-object outputs.
        extents_m: full edge lengths along the box's x, y, z axes, metres.
        position_m: centre of the box in the scene frame, metres.
        orientation_xyzw: unit quaternion (x, y, z, w) of the box frame in the scene frame.
        mass_kg: mass in kg, or None when ``density_kg_m3`` is given instead.
        density_kg_m3: uniform density in kg/m^3, or None when ``mass_kg`` is given.
        friction: Coulomb friction coefficient (pybullet multiplies the two bodies' values).
        restitution: coefficient of restitution in [0, 1].
        group: free-text label ("red", "heavy", ...); ``heavy`` marks the boxes mu scales.
        static: True for fixed geometry (walls, obstacles); static boxes never move or fall.
    """

    name: str
    extents_m: Vec3
    position_m: Vec3
    orientation_xyzw: Quat
    friction: float
    restitution: float
    mass_kg: float | None = None
    density_kg_m3: float | None = None
    group: str = ""
    static: bool = False

    @property
    def volume_m3(self) -> float:
        return float(self.extents_m[0] * self.extents_m[1] * self.extents_m[2])

    @property
    def resolved_mass_kg(self) -> float:
        """Mass in kg whichever of mass or density was given (0 for a static box without either)."""
        if self.mass_kg is not None:
            return float(self.mass_kg)
        if self.density_kg_m3 is not None:
            return float(self.density_kg_m3) * self.volume_m3
        return 0.0

    @property
    def is_heavy(self) -> bool:
        return self.group.strip().lower() == HEAVY_GROUP


@dataclass(frozen=True)
class Floor:
    """An infinite horizontal plane with its top at ``height_m``."""

    friction: float
    restitution: float
    height_m: float = 0.0

    @property
    def top_m(self) -> float:
        return self.height_m


@dataclass(frozen=True)
class Table:
    """A static table top: a box whose top face is at ``top_height_m``.

    Attributes:
        top_height_m: z of the table's top surface, metres.
        size_m: (x, y) full extents of the top, metres; the top's edge defines "fell off".
        center_xy_m: (x, y) of the top's centre, metres.
        thickness_m: thickness of the top slab, metres.
        friction, restitution: surface properties of the top.
        floor_z_m: z of an infinite floor under the table, or None for no floor.
        obstacles: static boxes attached to the table (short walls); each must be ``static``.
    """

    top_height_m: float
    size_m: tuple[float, float]
    center_xy_m: tuple[float, float]
    thickness_m: float
    friction: float
    restitution: float
    floor_z_m: float | None
    obstacles: tuple[Box, ...] = ()

    @property
    def top_m(self) -> float:
        return self.top_height_m

    def covers_xy(self, x: float, y: float) -> bool:
        """True when (x, y) lies over the table top (edges included)."""
        return (abs(x - self.center_xy_m[0]) <= self.size_m[0] / 2
                and abs(y - self.center_xy_m[1]) <= self.size_m[1] / 2)


Support = Union[Floor, Table]


@dataclass(frozen=True)
class Scene:
    """Boxes on a support under gravity.

    Attributes:
        name: identifies the scene in outputs (a tower name, a file stem, a ROS scene id).
        boxes: the rigid boxes, dynamic and static.
        support: a :class:`Floor` or a :class:`Table`.
        gravity_m_s2: gravity vector in m/s^2; z must be negative (z is up).
    """

    name: str
    boxes: tuple[Box, ...]
    support: Support
    gravity_m_s2: Vec3 = (0.0, 0.0, -9.81)

    @property
    def dynamic_boxes(self) -> tuple[Box, ...]:
        return tuple(b for b in self.boxes if not b.static)

    @property
    def static_boxes(self) -> tuple[Box, ...]:
        obstacles = self.support.obstacles if isinstance(self.support, Table) else ()
        return tuple(b for b in self.boxes if b.static) + tuple(obstacles)


# --------------------------------------------------------------------------------------------
# geometry helpers (pure numpy)

def quaternion_to_matrix(q_xyzw) -> np.ndarray:
    """Rotation matrix of a (normalised here) quaternion in (x, y, z, w) order."""
    x, y, z, w = np.asarray(q_xyzw, dtype=float) / np.linalg.norm(q_xyzw)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def box_corners(extents_m, position_m, orientation_xyzw) -> np.ndarray:
    """The 8 corners (8 x 3, metres) of a box in the scene frame."""
    half = np.asarray(extents_m, dtype=float) / 2
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    rot = quaternion_to_matrix(orientation_xyzw)
    return np.asarray(position_m, float) + (signs * half) @ rot.T


def box_half_heights(extents_m: np.ndarray, orientations_xyzw: np.ndarray) -> np.ndarray:
    """Vertical half-extent of each box (n,), i.e. centre-to-lowest-point distance."""
    out = np.empty(len(extents_m))
    for i, (ext, q) in enumerate(zip(extents_m, orientations_xyzw)):
        rot = quaternion_to_matrix(q)
        out[i] = 0.5 * np.abs(rot[2, :]) @ np.asarray(ext, float)
    return out


# --------------------------------------------------------------------------------------------
# validation

def _finite(values, path: str, what: str) -> None:
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise SceneError(path, f"{what} must be finite numbers, got {[float(v) for v in np.ravel(arr)]}")


def _check_vector(values, n: int, path: str, what: str) -> None:
    if not isinstance(values, (tuple, list)) or len(values) != n:
        raise SceneError(path, f"{what} must be a list of {n} numbers, got {values!r}")
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(path, f"{what} must be a list of {n} numbers, got {values!r}")
    _finite(values, path, what)


def _check_number(value, path: str, what: str, *, lo: float | None = None, lo_open: bool = False,
                  hi: float | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(path, f"{what} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise SceneError(path, f"{what} must be finite, got {value!r}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        bound = f"> {lo:g}" if lo_open else f">= {lo:g}"
        raise SceneError(path, f"{what} must be {bound}, got {value!r}")
    if hi is not None and value > hi:
        raise SceneError(path, f"{what} must be <= {hi:g}, got {value!r}")


def validate_box(box: Box, path: str) -> None:
    """Check one box's own fields; raises SceneError naming ``path`` + the field."""
    if not isinstance(box.name, str) or not box.name.strip():
        raise SceneError(f"{path}.name", "must be a non-empty string")
    path = f"{path} ({box.name!r})"
    _check_vector(box.extents_m, 3, f"{path}.extents_m", "full extents in metres")
    if min(box.extents_m) <= 0:
        raise SceneError(f"{path}.extents_m",
                         f"every extent must be > 0 metres, got {list(box.extents_m)}")
    _check_vector(box.position_m, 3, f"{path}.position_m", "position in metres")
    _check_vector(box.orientation_xyzw, 4, f"{path}.orientation_xyzw", "quaternion (x, y, z, w)")
    norm = math.sqrt(sum(c * c for c in box.orientation_xyzw))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise SceneError(f"{path}.orientation_xyzw",
                         f"must be a unit quaternion (norm within {QUATERNION_NORM_TOLERANCE:g} of 1),"
                         f" got norm {norm:.6g}; normalise it")
    _check_number(box.friction, f"{path}.friction", "friction", lo=0.0)
    _check_number(box.restitution, f"{path}.restitution", "restitution", lo=0.0, hi=1.0)
    if not isinstance(box.group, str):
        raise SceneError(f"{path}.group", f"must be a string, got {box.group!r}")
    if not isinstance(box.static, bool):
        raise SceneError(f"{path}.static", f"must be true or false, got {box.static!r}")
    if box.mass_kg is not None and box.density_kg_m3 is not None:
        raise SceneError(f"{path}.mass_kg", "give mass_kg or density_kg_m3, not both")
    if box.mass_kg is None and box.density_kg_m3 is None and not box.static:
        raise SceneError(f"{path}.mass_kg", "a dynamic box needs mass_kg or density_kg_m3 (> 0)")
    if box.mass_kg is not None:
        _check_number(box.mass_kg, f"{path}.mass_kg", "mass in kg", lo=0.0, lo_open=True)
    if box.density_kg_m3 is not None:
        _check_number(box.density_kg_m3, f"{path}.density_kg_m3", "density in kg/m^3", lo=0.0,
                      lo_open=True)


def _lowest_z(box: Box) -> float:
    return float(box_corners(box.extents_m, box.position_m, box.orientation_xyzw)[:, 2].min())


def validate_scene(scene: Scene, max_objects: int = DEFAULT_MAX_OBJECTS) -> Scene:
    """Check a whole scene; return it unchanged or raise :class:`SceneError`.

    Checks: finite numbers, positive sizes and masses, unit quaternions, unique names, at least one
    dynamic box, no more than ``max_objects`` boxes, gravity pointing down, and no box starting below
    its support (a tolerance of 1% of the box's smallest extent absorbs rounding in the input).
    """
    if not isinstance(scene.name, str) or not scene.name.strip():
        raise SceneError("name", "must be a non-empty string")
    _check_vector(scene.gravity_m_s2, 3, "gravity_m_s2", "gravity in m/s^2")
    if scene.gravity_m_s2[2] >= 0:
        raise SceneError("gravity_m_s2", f"z must be negative (z is up), got {scene.gravity_m_s2[2]!r}")
    support = scene.support
    if isinstance(support, Floor):
        _check_number(support.friction, "support.friction", "friction", lo=0.0)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        _check_number(support.height_m, "support.height_m", "floor height in metres")
    elif isinstance(support, Table):
        _check_number(support.top_height_m, "support.top_height_m", "table top height in metres")
        _check_vector(support.size_m, 2, "support.size_m", "table top (x, y) size in metres")
        if min(support.size_m) <= 0:
            raise SceneError("support.size_m", f"both sizes must be > 0 metres, got {list(support.size_m)}")
        _check_vector(support.center_xy_m, 2, "support.center_xy_m", "table centre (x, y) in metres")
        _check_number(support.thickness_m, "support.thickness_m", "thickness in metres", lo=0.0,
                      lo_open=True)
        _check_number(support.friction, "support.friction", "friction", lo=0.0)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        if support.floor_z_m is not None:
            _check_number(support.floor_z_m, "support.floor_z_m", "floor height in metres")
            if support.floor_z_m > support.top_height_m - support.thickness_m:
                raise SceneError("support.floor_z_m",
                                 f"must be at or below the table's underside "
                                 f"({support.top_height_m - support.thickness_m:g} m), got {support.floor_z_m!r}")
        for i, obstacle in enumerate(support.obstacles):
            if obstacle.static is not True:
                raise SceneError(f"support.obstacles[{i}] ({obstacle.name!r}).static",
                                 "obstacles are attached to the table and must be static: true")
            validate_box(obstacle, f"support.obstacles[{i}]")
    else:
        raise SceneError("support", f"must be a Floor or a Table, got {type(support).__name__}")

    n_objects = len(scene.boxes) + (len(support.obstacles) if isinstance(support, Table) else 0)
    if n_objects > max_objects:
        raise SceneError("boxes", f"{n_objects} objects exceed the maximum of {max_objects}; "
                                  "split the scene or raise max_objects")
    if not scene.dynamic_boxes:
        raise SceneError("boxes", "the scene has no dynamic box: nothing can fall")

    seen: set[str] = set()
    all_boxes = [(f"boxes[{i}]", b) for i, b in enumerate(scene.boxes)]
    if isinstance(support, Table):
        all_boxes += [(f"support.obstacles[{i}]", b) for i, b in enumerate(support.obstacles)]
    for path, box in all_boxes:
        if path.startswith("boxes"):
            validate_box(box, path)
        if box.name in seen:
            raise SceneError(f"{path}.name", f"duplicate name {box.name!r}; names must be unique")
        seen.add(box.name)
        lowest = _lowest_z(box)
        tolerance = 0.01 * min(box.extents_m)
        ground = support_top_below(support, box.position_m[0], box.position_m[1])
        if ground is not None and lowest < ground - tolerance:
            raise SceneError(f"{path} ({box.name!r}).position_m",
                             f"the box's lowest point z = {lowest:.6g} m is below the support surface "
                             f"at z = {ground:.6g} m; raise it by at least {ground - lowest:.6g} m")
    return scene


def support_top_below(support: Support, x: float, y: float) -> float | None:
    """z of the support surface under (x, y): the floor, the table top, or None (nothing below)."""
    if isinstance(support, Floor):
        return support.height_m
    if support.covers_xy(x, y):
        return support.top_height_m
    return support.floor_z_m
