"""Scenes as plain typed values: rigid bodies of any shape on a floor or a table.

Conventions: SI units (metres, kilograms, seconds), z up, right-handed. Orientations are unit
quaternions in (x, y, z, w) order, as pybullet and ROS use them. A body's pose is its own frame's
(the frame its shape is given in, see shapes.py); extents are FULL sizes (not half extents).

Everything here is a frozen dataclass: scenes pass between layers and processes by value.
``validate_scene`` checks a scene once, where it enters the engine; it raises
:class:`~ipe_ros.engine.errors.SceneError` naming the object and field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Union

import numpy as np

from . import limits, shapes
from ..errors import SceneError, shown
from .shapes import BoxShape, Shape

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
#: The longest horizon a scene may ask for: a prediction's cost grows with it.
MAX_HORIZON_S = 60.0

#: A quaternion whose norm differs from 1 by more than this is rejected (not renormalised silently).
QUATERNION_NORM_TOLERANCE = 1e-3
#: Default cap on the number of boxes in one scene (a configurable guard against runaway input).
DEFAULT_MAX_OBJECTS = 200
#: The group label that marks a box as heavy for the mass ratio mu (case-insensitive).
HEAVY_GROUP = "heavy"


@dataclass(frozen=True)
class Body:
    """One rigid body.

    Attributes:
        name: unique within the scene; used in per-object outputs.
        shape: its shape in its own frame (shapes.BoxShape, Sphere, Cylinder, Capsule, ConvexHull, Compound).
        position_m: origin of the body's frame in the scene frame, metres (a box's, sphere's,
            cylinder's and capsule's centre; a hull's or compound's centre of mass may lie elsewhere).
        orientation_xyzw: unit quaternion (x, y, z, w) of the body frame in the scene frame.
        mass_kg: mass in kg, or None when ``density_kg_m3`` is given instead (mass = density x the
            shape's true volume).
        density_kg_m3: uniform density in kg/m^3, or None when ``mass_kg`` is given.
        friction: Coulomb friction coefficient (pybullet multiplies the two bodies' values).
        restitution: coefficient of restitution in [0, 1].
        group: free-text label ("red", "heavy", ...); ``heavy`` marks the bodies mu scales.
        static: True for fixed geometry (walls, obstacles); static bodies never move or fall.
        linear_velocity_m_s, angular_velocity_rad_s: the state at t = 0 (scene frame).
        position_sigma_m: this body's own position noise (SD, metres), overriding the model's sigma:
            a number (horizontal, as the paper's) or (sx, sy, sz); 0 = known exactly. None: the model's.
        yaw_sigma_rad: SD of a rotation about the vertical, radians; None or 0: none.
    """

    name: str
    shape: Shape
    position_m: Vec3
    orientation_xyzw: Quat
    friction: float
    restitution: float
    mass_kg: float | None = None
    density_kg_m3: float | None = None
    group: str = ""
    static: bool = False
    linear_velocity_m_s: Vec3 = (0.0, 0.0, 0.0)
    angular_velocity_rad_s: Vec3 = (0.0, 0.0, 0.0)
    position_sigma_m: float | Vec3 | None = None
    yaw_sigma_rad: float | None = None

    @property
    def extents_m(self) -> Vec3:
        """Full sizes of the shape's bounding box along the body's own axes."""
        return shapes.extents_m(self.shape)

    @property
    def smallest_extent_m(self) -> float:
        return min(self.extents_m)

    @property
    def volume_m3(self) -> float:
        return shapes.volume_m3(self.shape)

    @property
    def centre_of_mass_m(self) -> np.ndarray:
        """The centre of mass in the scene frame."""
        local = shapes.centre_of_mass_m(self.shape)
        if not local.any():
            return np.asarray(self.position_m, float)
        return np.asarray(self.position_m, float) + quaternion_to_matrix(self.orientation_xyzw) @ local

    @property
    def moving(self) -> bool:
        """Given an initial velocity."""
        return any(self.linear_velocity_m_s) or any(self.angular_velocity_rad_s)

    @property
    def resolved_mass_kg(self) -> float:
        """Mass in kg whichever of mass or density was given (0 for a static body without either)."""
        if self.mass_kg is not None:
            return float(self.mass_kg)
        if self.density_kg_m3 is not None:
            return float(self.density_kg_m3) * self.volume_m3
        return 0.0

    @property
    def is_heavy(self) -> bool:
        return self.group.strip().lower() == HEAVY_GROUP


def Box(name: str, extents_m: Vec3, position_m: Vec3, orientation_xyzw: Quat, friction: float, restitution: float,
        **fields) -> Body:  # noqa: N802 - reads as the type it makes
    """A body whose shape is a box of full ``extents_m``: the paper's blocks."""
    return Body(name=name, shape=BoxShape(tuple(extents_m)), position_m=position_m,
                orientation_xyzw=orientation_xyzw, friction=friction, restitution=restitution, **fields)


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
        obstacles: static bodies attached to the table (short walls); each must be ``static``.
    """

    top_height_m: float
    size_m: tuple[float, float]
    center_xy_m: tuple[float, float]
    thickness_m: float
    friction: float
    restitution: float
    floor_z_m: float | None
    obstacles: tuple[Body, ...] = ()

    @property
    def top_m(self) -> float:
        return self.top_height_m

    def covers_xy(self, x, y):
        """True where (x, y) lies over the table top (edges included); numbers or arrays alike."""
        return (np.abs(np.subtract(x, self.center_xy_m[0])) <= self.size_m[0] / 2) \
            & (np.abs(np.subtract(y, self.center_xy_m[1])) <= self.size_m[1] / 2)


Support = Union[Floor, Table]


@dataclass(frozen=True)
class Scene:
    """Rigid bodies on a support under gravity.

    Attributes:
        name: identifies the scene in outputs (a tower name, a file stem, a ROS scene id).
        objects: the rigid bodies, dynamic and static.
        support: a :class:`Floor` or a :class:`Table`.
        gravity_m_s2: gravity vector in m/s^2; z must be negative (z is up).
        horizon_s: how long to simulate this scene, or None for the settings' horizon.
    """

    name: str
    objects: tuple[Body, ...]
    support: Support
    gravity_m_s2: Vec3 = (0.0, 0.0, -9.81)
    horizon_s: float | None = None

    @property
    def dynamic_objects(self) -> tuple[Body, ...]:
        return tuple(b for b in self.objects if not b.static)

    @property
    def static_objects(self) -> tuple[Body, ...]:
        obstacles = self.support.obstacles if isinstance(self.support, Table) else ()
        return tuple(b for b in self.objects if b.static) + tuple(obstacles)


# --------------------------------------------------------------------------------------------
# geometry helpers (pure numpy)

quaternion_to_matrix = shapes.rotation_matrix


def box_corners(extents_m, position_m, orientation_xyzw) -> np.ndarray:
    """The 8 corners (8 x 3, metres) of a box in the scene frame."""
    half = np.asarray(extents_m, dtype=float) / 2
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    rot = quaternion_to_matrix(orientation_xyzw)
    return np.asarray(position_m, float) + (signs * half) @ rot.T


def half_heights_m(bodies, orientations_xyzw: np.ndarray) -> np.ndarray:
    """How far each body reaches below its centre of mass (n,), at the given orientations."""
    return np.array([shapes.half_height_m(b.shape, q) for b, q in zip(bodies, orientations_xyzw)])


# --------------------------------------------------------------------------------------------
# validation

def _finite(values, path: str, what: str) -> None:
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise SceneError(path, f"{what} must be finite numbers, got {shown([float(v) for v in np.ravel(arr)])}")


def _check_vector(values, n: int, path: str, what: str, *, max_abs: float | None = None,
                  max_norm: float | None = None, why: str = "") -> None:
    if not isinstance(values, (tuple, list)) or len(values) != n:
        raise SceneError(path, f"{what} must be a list of {n} numbers, got {shown(values)}")
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(path, f"{what} must be a list of {n} numbers, got {shown(values)}")
    _finite(values, path, what)
    if max_abs is not None and max(abs(v) for v in values) > max_abs:
        raise SceneError(path, f"{what} must be within +-{max_abs:g}{why}, got {shown(list(values))}")
    if max_norm is not None and math.sqrt(sum(v * v for v in values)) > max_norm:
        raise SceneError(path, f"{what} must have a magnitude of at most {max_norm:g}{why}, got {shown(list(values))}")


def _check_name(value, path: str) -> None:
    """Names are printed in logs, messages and recordings: real text, of bounded length."""
    if not isinstance(value, str) or not value.strip():
        raise SceneError(path, "must be a non-empty string")
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        raise SceneError(path, f"must be valid Unicode text (it holds a lone surrogate), got {shown(value)}") from None
    if len(value) > limits.MAX_NAME_CHARS:
        raise SceneError(path, f"must be at most {limits.MAX_NAME_CHARS} characters, got {len(value)}")
    if any(not c.isprintable() for c in value):
        raise SceneError(path, f"must be printable (no control characters), got {shown(value)}")


_COORDINATE = dict(max_abs=limits.MAX_COORDINATE_M, why=" m of the scene frame's origin (use a frame near the scene)")
_SPEED = dict(max_norm=limits.MAX_SPEED_M_S, why=" m/s (faster objects are projectiles, not scenes)")
_SPIN = dict(max_norm=limits.MAX_SPIN_RAD_S, why=" rad/s")


def _check_number(value, path: str, what: str, *, lo: float | None = None, lo_open: bool = False,
                  hi: float | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(path, f"{what} must be a number, got {shown(value)}")
    if not math.isfinite(value):
        raise SceneError(path, f"{what} must be finite, got {shown(value)}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        bound = f"> {lo:g}" if lo_open else f">= {lo:g}"
        raise SceneError(path, f"{what} must be {bound}, got {shown(value)}")
    if hi is not None and value > hi:
        raise SceneError(path, f"{what} must be <= {hi:g}, got {shown(value)}")


def validate_body(body: Body, path: str) -> None:
    """Check one body's own fields; raises SceneError naming ``path`` + the field."""
    _check_name(body.name, f"{path}.name")
    path = f"{path} ({shown(body.name)})"
    shapes.validate_shape(body.shape, f"{path}.shape")
    extents = body.extents_m
    if min(extents) < limits.MIN_SIZE_M or max(extents) > limits.MAX_SIZE_M:
        raise SceneError(f"{path}.shape", f"every extent must be within [{limits.MIN_SIZE_M:g}, {limits.MAX_SIZE_M:g}] m "
                                          f"(smaller bodies need ever finer steps; check the units), got "
                                          f"{shown(list(extents))}")
    _check_vector(body.position_m, 3, f"{path}.position_m", "position in metres", **_COORDINATE)
    _check_vector(body.orientation_xyzw, 4, f"{path}.orientation_xyzw", "quaternion (x, y, z, w)")
    norm = math.sqrt(sum(c * c for c in body.orientation_xyzw))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise SceneError(f"{path}.orientation_xyzw",
                         f"must be a unit quaternion (norm within {QUATERNION_NORM_TOLERANCE:g} of 1),"
                         f" got norm {norm:.6g}; normalise it")
    _check_number(body.friction, f"{path}.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
    _check_number(body.restitution, f"{path}.restitution", "restitution", lo=0.0, hi=1.0)
    if not isinstance(body.group, str):
        raise SceneError(f"{path}.group", f"must be a string, got {shown(body.group)}")
    if body.group:
        _check_name(body.group, f"{path}.group")
    if not isinstance(body.static, bool):
        raise SceneError(f"{path}.static", f"must be true or false, got {shown(body.static)}")
    if body.mass_kg is not None and body.density_kg_m3 is not None:
        raise SceneError(f"{path}.mass_kg", "give mass_kg or density_kg_m3, not both")
    if body.mass_kg is None and body.density_kg_m3 is None and not body.static:
        raise SceneError(f"{path}.mass_kg", "a dynamic body needs mass_kg or density_kg_m3 (> 0)")
    if body.mass_kg is not None:
        _check_number(body.mass_kg, f"{path}.mass_kg", "mass in kg", lo=0.0, lo_open=True)
    if body.density_kg_m3 is not None:
        _check_number(body.density_kg_m3, f"{path}.density_kg_m3", "density in kg/m^3", lo=0.0,
                      lo_open=True)
    mass = body.resolved_mass_kg
    if not body.static and not limits.MIN_MASS_KG <= mass <= limits.MAX_MASS_KG:
        field = "mass_kg" if body.mass_kg is not None else "density_kg_m3"
        raise SceneError(f"{path}.{field}", f"the mass must be within [{limits.MIN_MASS_KG:g}, {limits.MAX_MASS_KG:g}] kg "
                                            f"(check the units), got {mass:.6g} kg")
    _check_vector(body.linear_velocity_m_s, 3, f"{path}.linear_velocity_m_s", "velocity in m/s", **_SPEED)
    _check_vector(body.angular_velocity_rad_s, 3, f"{path}.angular_velocity_rad_s", "angular velocity in rad/s",
                  **_SPIN)
    if body.static and body.moving:
        raise SceneError(f"{path}.linear_velocity_m_s", "a static body cannot move; drop its velocity or make it "
                                                        "dynamic")
    sigma = body.position_sigma_m
    if sigma is not None:
        if isinstance(sigma, (tuple, list)):
            _check_vector(sigma, 3, f"{path}.position_sigma_m", "position noise SDs (x, y, z) in metres",
                          max_abs=limits.MAX_SIGMA_M, why=" m (check the units)")
            if min(sigma) < 0:
                raise SceneError(f"{path}.position_sigma_m", f"noise SDs must be >= 0, got {shown(list(sigma))}")
        else:
            _check_number(sigma, f"{path}.position_sigma_m", "position noise SD in metres", lo=0.0,
                          hi=limits.MAX_SIGMA_M)
    if body.yaw_sigma_rad is not None:
        _check_number(body.yaw_sigma_rad, f"{path}.yaw_sigma_rad", "yaw noise SD in radians", lo=0.0, hi=math.pi)


def lowest_z_m(body: Body) -> float:
    """The lowest point of the body in the scene frame."""
    points = shapes.surface_points(body.shape) @ quaternion_to_matrix(body.orientation_xyzw).T
    return float(points[:, 2].min() + body.position_m[2])


#: the attribute a scene found valid carries (set on the value, not in a shared table: every thread
#: and process that holds the scene knows it, and nothing grows)
_CHECKED = "_ipe_checked"


def validate_scene(scene: Scene, max_objects: int = DEFAULT_MAX_OBJECTS) -> Scene:
    """Check a whole scene; return it unchanged or raise :class:`SceneError`.

    Checks: well-formed shapes, finite numbers, positive sizes and masses, unit quaternions, unique
    names, at least one dynamic body, no more than ``max_objects`` bodies, gravity pointing down, a
    horizon within MAX_HORIZON_S, and no body starting below its support (a tolerance of 1% of the
    body's smallest extent absorbs rounding in the input). A scene is checked in full once: found
    valid and immutable all the way down (hashable), it is marked so, and a later check (where a
    request is costed, where it is predicted) compares only its object count with ``max_objects``.
    """
    if getattr(scene, _CHECKED, False):
        _check_count(scene, max_objects)
        return scene
    _validate(scene, max_objects)
    try:
        hash(scene)  # a list where a tuple belongs could change after the check: checked every time
    except TypeError:
        return scene
    object.__setattr__(scene, _CHECKED, True)  # frozen: the mark is not a field (equality, replace ignore it)
    return scene


def _check_count(scene: Scene, max_objects: int) -> None:
    support = scene.support
    n_objects = len(scene.objects) + (len(support.obstacles) if isinstance(support, Table) else 0)
    if n_objects > max_objects:
        raise SceneError("objects", f"{n_objects} objects exceed the maximum of {max_objects}; "
                                    "split the scene or raise max_objects")


def _validate(scene: Scene, max_objects: int) -> Scene:
    _check_name(scene.name, "name")
    _check_vector(scene.gravity_m_s2, 3, "gravity_m_s2", "gravity in m/s^2")
    if scene.gravity_m_s2[2] >= 0:
        raise SceneError("gravity_m_s2", f"z must be negative (z is up), got {shown(scene.gravity_m_s2[2])}")
    g = math.sqrt(sum(v * v for v in scene.gravity_m_s2))
    if not limits.MIN_GRAVITY_M_S2 <= g <= limits.MAX_GRAVITY_M_S2:
        raise SceneError("gravity_m_s2", f"the magnitude must be within [{limits.MIN_GRAVITY_M_S2:g}, "
                                         f"{limits.MAX_GRAVITY_M_S2:g}] m/s^2 (Earth: 9.81), got {shown(list(scene.gravity_m_s2))}")
    height = dict(lo=-limits.MAX_COORDINATE_M, hi=limits.MAX_COORDINATE_M)
    support = scene.support
    if isinstance(support, Floor):
        _check_number(support.friction, "support.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        _check_number(support.height_m, "support.height_m", "floor height in metres", **height)
    elif isinstance(support, Table):
        _check_number(support.top_height_m, "support.top_height_m", "table top height in metres", **height)
        _check_vector(support.size_m, 2, "support.size_m", "table top (x, y) size in metres", **_COORDINATE)
        if min(support.size_m) <= 0:
            raise SceneError("support.size_m", f"both sizes must be > 0 metres, got {shown(list(support.size_m))}")
        _check_vector(support.center_xy_m, 2, "support.center_xy_m", "table centre (x, y) in metres", **_COORDINATE)
        _check_number(support.thickness_m, "support.thickness_m", "thickness in metres", lo=0.0,
                      lo_open=True, hi=limits.MAX_SIZE_M)
        _check_number(support.friction, "support.friction", "friction", lo=0.0, hi=limits.MAX_FRICTION)
        _check_number(support.restitution, "support.restitution", "restitution", lo=0.0, hi=1.0)
        if support.floor_z_m is not None:
            _check_number(support.floor_z_m, "support.floor_z_m", "floor height in metres", **height)
            if support.floor_z_m > support.top_height_m - support.thickness_m:
                raise SceneError("support.floor_z_m",
                                 f"must be at or below the table's underside "
                                 f"({support.top_height_m - support.thickness_m:g} m), got {shown(support.floor_z_m)}")
        for i, obstacle in enumerate(support.obstacles):
            if obstacle.static is not True:
                raise SceneError(f"support.obstacles[{i}] ({shown(obstacle.name)}).static",
                                 "obstacles are attached to the table and must be static: true")
            validate_body(obstacle, f"support.obstacles[{i}]")
    else:
        raise SceneError("support", f"must be a Floor or a Table, got {type(support).__name__}")

    if scene.horizon_s is not None:
        _check_number(scene.horizon_s, "horizon_s", "the simulated time in seconds", lo=0.0, lo_open=True,
                      hi=MAX_HORIZON_S)
    _check_count(scene, max_objects)
    if not scene.dynamic_objects:
        raise SceneError("objects", "the scene has no dynamic object: nothing can fall")

    seen: set[str] = set()
    everything = [(f"objects[{i}]", b) for i, b in enumerate(scene.objects)]
    if isinstance(support, Table):
        everything += [(f"support.obstacles[{i}]", b) for i, b in enumerate(support.obstacles)]
    for path, body in everything:
        if path.startswith("objects"):
            validate_body(body, path)
        if body.name in seen:
            raise SceneError(f"{path}.name", f"duplicate name {shown(body.name)}; names must be unique")
        seen.add(body.name)
        lowest, ground = deepest_into_support(support, body)
        tolerance = 0.01 * body.smallest_extent_m
        if ground is not None and lowest < ground - tolerance:
            raise SceneError(f"{path} ({shown(body.name)}).position_m",
                             f"the body's lowest point z = {lowest:.6g} m is below the support surface "
                             f"at z = {ground:.6g} m; raise it by at least {ground - lowest:.6g} m")
    masses = [(b.resolved_mass_kg, b.name) for b in scene.dynamic_objects]
    (heaviest, heavy_name), (lightest, light_name) = max(masses), min(masses)
    if lightest > 0 and heaviest / lightest > limits.MAX_MASS_RATIO:
        raise SceneError("objects", f"{shown(heavy_name)} is {heaviest / lightest:.4g} times as heavy as "
                                    f"{shown(light_name)}; mass ratios above {limits.MAX_MASS_RATIO:g}:1 are beyond what "
                                    "the solver converges on (check the units)")
    return scene


def deepest_into_support(support: Support, body: Body) -> tuple[float, float | None]:
    """(z, surface z) of the body's point deepest inside the support's solid (the floor's half-space,
    the table top's slab, the floor under a table): each point is judged against the support under
    *it*, so a body resting on a table and tilted over its edge hangs below the top where no table
    is. (lowest z, None) when no point lies over any support."""
    points = shapes.surface_points(body.shape) @ quaternion_to_matrix(body.orientation_xyzw).T
    points = points + np.asarray(body.position_m, float)
    x, y, z = points.T
    if isinstance(support, Floor):
        surface = np.full(len(z), support.height_m)
    else:
        over = support.covers_xy(x, y) & (z >= support.top_height_m - support.thickness_m)  # under it: not inside
        below = np.nan if support.floor_z_m is None else support.floor_z_m
        surface = np.where(over, support.top_height_m, below)
    if np.all(np.isnan(surface)):
        return float(z.min()), None
    i = int(np.nanargmin(z - surface))
    return float(z[i]), float(surface[i])


def support_top_below(support: Support, x: float, y: float) -> float | None:
    """z of the support surface under (x, y): the floor, the table top, or None (nothing below)."""
    if isinstance(support, Floor):
        return support.height_m
    if support.covers_xy(x, y):
        return support.top_height_m
    return support.floor_z_m
