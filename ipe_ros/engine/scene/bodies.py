"""Scenes as plain typed values: rigid bodies of any shape on a floor or a table.

Conventions: SI units (metres, kilograms, seconds), z up, right-handed. Orientations are unit
quaternions in (x, y, z, w) order, as pybullet and ROS use them. A body's pose is its own frame's
(the frame its shape is given in, see shapes.py); extents are FULL sizes (not half extents).

Everything here is a frozen dataclass: scenes pass between layers and processes by value.
``validation.validate_scene`` checks a scene once, where it enters the engine.
"""

from __future__ import annotations

import functools

from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from . import shapes
from .shapes import BoxShape, Shape

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
#: The longest horizon a scene may ask for: a prediction's cost grows with it.
MAX_HORIZON_S = 60.0
#: the farthest an object is set down onto its support (Scene.set_down_m): estimates, not placements
MAX_SET_DOWN_M = 0.1

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
        priors: (property, prior) pairs (``scene.properties``): properties the robot does not know
            exactly, each sample drawing its own value; the value above is then only the prior's centre.
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
    priors: tuple[tuple[str, Any], ...] = field(default=(), metadata={"keyed": "when set"})

    @functools.cached_property  # a mesh's is every part's points turned: ~0.6 ms, asked at every look
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
    priors: tuple[tuple[str, Any], ...] = field(default=(), metadata={"keyed": "when set"})  # as Body's

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
        priors: the top's uncertain friction and restitution, as ``Body.priors``.
    """

    top_height_m: float
    size_m: tuple[float, float]
    center_xy_m: tuple[float, float]
    thickness_m: float
    friction: float
    restitution: float
    floor_z_m: float | None
    obstacles: tuple[Body, ...] = ()
    priors: tuple[tuple[str, Any], ...] = field(default=(), metadata={"keyed": "when set"})

    @property
    def top_m(self) -> float:
        return self.top_height_m

    def covers_xy(self, x, y):
        """True where (x, y) lies over the table top (edges included); numbers or arrays alike."""
        return (np.abs(np.subtract(x, self.center_xy_m[0])) <= self.size_m[0] / 2) \
            & (np.abs(np.subtract(y, self.center_xy_m[1])) <= self.size_m[1] / 2)


Support = Union[Floor, Table]


@dataclass(frozen=True)
class TimedPush:
    """A known push during the rollout (the robot's own, watched in an observation): at ``at_s`` the
    object ``name``'s velocity changes by ``velocity_change_m_s`` (an impulse over its mass)."""

    name: str
    at_s: float
    velocity_change_m_s: Vec3


@dataclass(frozen=True)
class Scene:
    """Rigid bodies on a support under gravity.

    Attributes:
        name: identifies the scene in outputs (a tower name, a file stem, a ROS scene id).
        objects: the rigid bodies, dynamic and static.
        support: a :class:`Floor` or a :class:`Table`.
        gravity_m_s2: gravity vector in m/s^2; z must be negative (z is up).
        horizon_s: how long to simulate this scene, or None for the settings' horizon.
        set_down_m: each dynamic object whose lowest point is at most this far above what is under it
            is set down onto it before the rollout (after overlaps are removed): for heights that are
            estimates (a detector's, a depth posterior's), which leave objects hovering millimetres
            above their supports. 0: heights as given (the paper's stacks).
        pushes: known pushes after t = 0, in time order (``TimedPush``; engine-only: an observation's
            actions), each applied at the first step boundary at or after its time.
    """

    name: str
    objects: tuple[Body, ...]
    support: Support
    gravity_m_s2: Vec3 = (0.0, 0.0, -9.81)
    horizon_s: float | None = None
    set_down_m: float = 0.0
    pushes: tuple[TimedPush, ...] = field(default=(), metadata={"keyed": "when set"})

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

def lowest_z_m(body: Body) -> float:
    """The lowest point of the body in the scene frame."""
    points = shapes.surface_points(body.shape) @ quaternion_to_matrix(body.orientation_xyzw).T
    return float(points[:, 2].min() + body.position_m[2])


#: the attribute a scene found valid carries (set on the value, not in a shared table: every thread
#: and process that holds the scene knows it, and nothing grows)
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
