"""A seeded catalogue of random scenes well beyond the paper's towers, for tests and benchmarks.

Stacks and piles of mixed shapes (boxes, spheres, cylinders, capsules, cones, wedges, L-brackets),
sizes from 5 mm to 1 m, mass ratios up to 1000:1 either way, restitution 0-0.9, friction 0-2, bodies
thrown at up to 10 m/s, bodies resting tilted on others. Every body starts touching what is below it
(never inside it). ``capped_tower`` is the worked example of the scene-format guide: a tower of boxes
with a cone on top and a ball rolled into its base.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from .bodies import Body, Floor, Scene

from .validation import validate_scene
from .shapes import (BoxShape, Capsule, Compound, CompoundPart, ConvexHull, Cylinder, Sphere,
                     rotation_matrix, surface_points)

_IDENTITY = (0.0, 0.0, 0.0, 1.0)
#: Each scene has its own length scale (log-uniform in this range, metres; its bodies' smallest
#: extents reach down to a third of it, 5 mm) ...
SIZE_RANGE_M = (0.015, 1.0)
#: ... and mass ratios up to this, either way up.
MAX_MASS_RATIO = 1000.0
MAX_SPEED_M_S = 10.0


def _as_quat(rotation: Rotation) -> tuple[float, float, float, float]:
    return tuple(float(v) for v in rotation.as_quat())  # type: ignore[return-value]


def cone(radius_m: float, height_m: float, sides: int = 12) -> ConvexHull:
    """A cone (as a pyramid of ``sides`` sides) standing on its base, its apex up, origin at the base centre."""
    ring = tuple((radius_m * math.cos(a), radius_m * math.sin(a), 0.0)
                 for a in np.linspace(0, 2 * math.pi, sides, endpoint=False))
    return ConvexHull(ring + ((0.0, 0.0, height_m),))


def wedge(length_m: float, width_m: float, height_m: float) -> ConvexHull:
    """A right-angled wedge (a ramp) lying on its long face, origin at the middle of its base."""
    x, y, z = length_m / 2, width_m / 2, height_m
    return ConvexHull(((-x, -y, 0.0), (x, -y, 0.0), (-x, y, 0.0), (x, y, 0.0), (-x, -y, z), (-x, y, z)))


def ring(radius_m: float, tube_radius_m: float, segments: int = 10) -> Compound:
    """A torus lying flat (axis z) as ``segments`` capsules along its centre circle, origin at its centre."""
    chord = 2 * radius_m * math.sin(math.pi / segments)
    parts = []
    for i in range(segments):
        angle = 2 * math.pi * (i + 0.5) / segments
        # a capsule's axis is its z: turn it onto x, then onto the circle's tangent at ``angle``
        turn = Rotation.from_euler("z", angle + math.pi / 2) * Rotation.from_euler("y", math.pi / 2)
        centre = radius_m * math.cos(math.pi / segments)
        parts.append(CompoundPart(Capsule(tube_radius_m, chord), (centre * math.cos(angle), centre * math.sin(angle),
                                                                  0.0), _as_quat(turn)))
    return Compound(tuple(parts))


def bowl(radius_m: float, height_m: float, wall_m: float, segments: int = 10, flare_rad: float = 0.35) -> Compound:
    """An open bowl: a disc and ``segments`` wall plates flaring out by ``flare_rad``, origin at the
    centre of its base's underside."""
    parts = [CompoundPart(Cylinder(radius_m, wall_m), (0.0, 0.0, wall_m / 2))]
    width = 2 * (radius_m + height_m * math.sin(flare_rad)) * math.tan(math.pi / segments) + wall_m
    for i in range(segments):
        angle = 2 * math.pi * i / segments
        middle = radius_m + 0.5 * height_m * math.sin(flare_rad)
        tilt = Rotation.from_euler("z", angle) * Rotation.from_euler("y", flare_rad)
        parts.append(CompoundPart(BoxShape((wall_m, width, height_m)),
                                  (middle * math.cos(angle), middle * math.sin(angle),
                                   wall_m + 0.5 * height_m * math.cos(flare_rad)), _as_quat(tilt)))
    return Compound(tuple(parts))


def open_box(size_m: float, height_m: float, wall_m: float) -> Compound:
    """A square box without a lid, origin at the centre of its base's underside."""
    half = size_m / 2
    z = wall_m + height_m / 2
    return Compound((
        CompoundPart(BoxShape((size_m, size_m, wall_m)), (0.0, 0.0, wall_m / 2)),
        CompoundPart(BoxShape((wall_m, size_m, height_m)), (half - wall_m / 2, 0.0, z)),
        CompoundPart(BoxShape((wall_m, size_m, height_m)), (-half + wall_m / 2, 0.0, z)),
        CompoundPart(BoxShape((size_m - 2 * wall_m, wall_m, height_m)), (0.0, half - wall_m / 2, z)),
        CompoundPart(BoxShape((size_m - 2 * wall_m, wall_m, height_m)), (0.0, -half + wall_m / 2, z)),
    ))


def l_bracket(size_m: float, thickness_m: float) -> Compound:
    """An L of two plates (non-convex: a compound), its corner at the origin."""
    t, s = thickness_m, size_m
    return Compound((CompoundPart(BoxShape((s, t, t)), (s / 2, 0.0, t / 2)),
                     CompoundPart(BoxShape((t, t, s)), (t / 2, 0.0, s / 2))))


def _random_shape(rng: np.random.Generator, size_m: float):
    kind = rng.choice(["box", "box", "sphere", "cylinder", "capsule", "cone", "wedge", "bracket"])
    a, b, c = size_m * rng.uniform(0.5, 1.5, 3)
    if kind == "box":
        return BoxShape((float(a), float(b), float(c)))
    if kind == "sphere":
        return Sphere(float(a / 2))
    if kind == "cylinder":
        return Cylinder(float(a / 2), float(c))
    if kind == "capsule":
        return Capsule(float(a / 3), float(c / 2))
    if kind == "cone":
        return cone(float(a / 2), float(c))
    if kind == "wedge":
        return wedge(float(a), float(b), float(c / 2))
    return l_bracket(float(a), float(a / 3))


def _yaw_tilt(rng: np.random.Generator, tilt_rad: float) -> tuple[float, float, float, float]:
    yaw = rng.uniform(-math.pi, math.pi)
    axis = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    q = (Rotation.from_rotvec(axis * tilt_rad) * Rotation.from_rotvec([0.0, 0.0, yaw])).as_quat()
    return tuple(float(v) for v in q)


def _extent_z(shape, orientation) -> tuple[float, float]:
    """(lowest, highest) z of the shape's points about its own origin, at this orientation."""
    z = (surface_points(shape) @ rotation_matrix(orientation).T)[:, 2]
    return float(z.min()), float(z.max())


def _body(name: str, shape, position, orientation, mass_kg: float, rng: np.random.Generator, **fields) -> Body:
    return Body(name=name, shape=shape, position_m=tuple(float(v) for v in position), orientation_xyzw=orientation,
                friction=float(rng.uniform(0.0, 2.0)), restitution=float(rng.uniform(0.0, 0.9)),
                mass_kg=float(mass_kg), **fields)


def random_scene(rng: np.random.Generator, name: str) -> Scene:
    """One catalogue scene: a stack (possibly tilted, possibly with a thrown body) or a pile."""
    size = float(math.exp(rng.uniform(math.log(SIZE_RANGE_M[0]), math.log(SIZE_RANGE_M[1]))))
    layout = rng.choice(["stack", "stack", "pile"])
    n = int(rng.integers(2, 6))
    # masses: log-uniform within the ratio, sometimes the heaviest on top of the lightest
    ratio = float(math.exp(rng.uniform(0.0, math.log(MAX_MASS_RATIO))))
    base_mass = 4.0 * size ** 3 / 0.008 + 1e-3
    masses = base_mass * np.exp(rng.uniform(0.0, math.log(ratio), n))
    masses[0], masses[-1] = base_mass, base_mass * ratio
    if rng.random() < 0.5:
        masses = masses[::-1]
    bodies: list[Body] = []
    top_z, x0 = 0.0, 0.0
    for i in range(n):
        shape = _random_shape(rng, size)
        tilted = layout == "stack" and rng.random() < 0.3
        orientation = _yaw_tilt(rng, rng.uniform(0.1, 0.6)) if tilted else _IDENTITY
        low, high = _extent_z(shape, orientation)
        if layout == "stack":
            offset = rng.normal(0.0, 0.15 * size, 2)
            position = (offset[0], offset[1], top_z - low)
            top_z = top_z - low + high
        else:
            position = (x0, rng.normal(0.0, 0.2 * size), -low)
            x0 += 1.6 * size
        bodies.append(_body(f"{name}_o{i}", shape, position, orientation, masses[i], rng))
    if rng.random() < 0.5:  # a body thrown at the scene, known exactly (the robot threw it)
        shape = Sphere(float(size * rng.uniform(0.2, 0.5)))
        speed = float(rng.uniform(0.5, MAX_SPEED_M_S))
        start = -3.0 * size - shape.radius_m
        # kept within the mass ratio of the others (a light stack and a heavy throw would be refused)
        mass = float(np.clip(base_mass * rng.uniform(0.5, 2.0), masses.max() / MAX_MASS_RATIO,
                             masses.min() * MAX_MASS_RATIO))
        bodies.append(_body(f"{name}_thrown", shape, (start, 0.0, shape.radius_m), _IDENTITY, mass, rng,
                            linear_velocity_m_s=(speed, 0.0, 0.0), position_sigma_m=0.0))
    scene = Scene(name=name, objects=tuple(bodies), support=Floor(friction=float(rng.uniform(0.2, 1.5)),
                                                                  restitution=float(rng.uniform(0.0, 0.5))))
    return validate_scene(scene)


def scene_catalogue(seed: int, count: int) -> list[Scene]:
    """``count`` random scenes; scene i depends on (seed, i) only."""
    return [random_scene(np.random.default_rng([seed, i]), f"catalogue_{seed}_{i:03d}") for i in range(count)]


def capped_tower(ball_speed_m_s: float = 5.0) -> Scene:
    """Three 0.3 m boxes, a cone on top, and a 0.1 m ball rolling at the base: the guide's worked example."""
    side = 0.3
    bodies = [Body(f"box{i}", BoxShape((side, side, side)), (0.0, 0.0, side / 2 + i * side), _IDENTITY,
                   friction=0.6, restitution=0.1, mass_kg=2.0) for i in range(3)]
    bodies.append(Body("cone", cone(0.12, 0.25), (0.0, 0.0, 3 * side), _IDENTITY, friction=0.6, restitution=0.1,
                       density_kg_m3=600.0))
    bodies.append(Body("ball", Sphere(0.1), (-1.0, 0.0, 0.1), _IDENTITY, friction=0.4, restitution=0.5,
                       mass_kg=4.0, linear_velocity_m_s=(ball_speed_m_s, 0.0, 0.0), position_sigma_m=0.0))
    return validate_scene(Scene(name="capped_tower", objects=tuple(bodies), support=Floor(friction=0.8,
                                                                                         restitution=0.1)))
