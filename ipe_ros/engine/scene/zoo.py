"""The scene zoo: seeded families of scenes that stand for what robots and benchmarks bring.

The paper's towers and the catalogue are slow scenes: blocks at rest that may topple. The zoo adds
fast impacts and chains of events, the scenes on which a fast integrator drifts from converged
physics without noticing (docs/zoo.md). Each family is one function ``(rng, name) -> Scene``:

- ``launch``: a ball or block launched into a stack at 0.5-15 m/s, up to 10x a block's mass;
- ``dominoes``: 5-20 thin slabs, spaced around the critical spacing, the first one tipped;
- ``ramp``: a ball or block rolled or slid down a static ramp into a stack;
- ``drop``: an object dropped from 0.2-2 m onto a stack or into a container (bowl, open box);
- ``strike``: a heavy object (10-100x) sliding into a light one;
- ``rings``: rings (tori as compounds) dropped onto a static post;
- ``bouncy``: large (0.3-1 m) bouncy (restitution 0.5-0.9) blocks stacked or dropped;
- ``plates``: thin plates stacked with overhangs;
- ``caps``: towers capped by a cone, a ring or a bowl, sometimes with a ball launched at the base;
- ``stacks``: boxes at rest in 1-3 stacks side by side, drawn over the whole envelope in which the
  self-check trusts `default` without reference reruns (``checking/envelope.py``);
- ``household``: a mug with a ladle leaning in it, a bowl with balls dropped in, a can on a box: real
  non-convex objects from procedural meshes (``household.py``), read as convex parts.

Scene i of a family depends on (seed, family, i) only. Bodies the robot moves (thrown, launched,
dropped) are known exactly (``position_sigma_m = 0``); the rest takes the model's sigma.
"""

from __future__ import annotations

import functools
import math
import zlib
from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from .catalogue import bowl, cone, open_box, ring, wedge
from .bodies import Body, Floor, Scene
from .validation import validate_scene
from .shapes import BoxShape, Compound, Cylinder, Sphere, surface_points

_IDENTITY = (0.0, 0.0, 0.0, 1.0)

#: clear of Bullet's convex-hull collision margin (0.9 mm): a body set this far from a hull (the
#: ramp's wedge, a mesh's parts) starts touching nothing, and one at rest on it stays about this far
HULL_MARGIN_M = 1e-3


def _quat(rotation: Rotation) -> tuple[float, float, float, float]:
    return tuple(float(v) for v in rotation.as_quat())  # type: ignore[return-value]


def _yaw(rad: float) -> tuple[float, float, float, float]:
    return _quat(Rotation.from_euler("z", rad))


def _body(name: str, shape, position, *, mass_kg: float, friction: float = 0.6, restitution: float = 0.1,
          orientation=_IDENTITY, **fields) -> Body:
    return Body(name=name, shape=shape, position_m=tuple(float(v) for v in position),  # type: ignore[arg-type]
                orientation_xyzw=orientation, friction=float(friction), restitution=float(restitution),
                mass_kg=float(mass_kg), **fields)


def _stack(rng: np.random.Generator, prefix: str, n: int, size_m: float, *, x_m: float = 0.0, base_z_m: float = 0.0,
           offset_sd: float = 0.15, friction: float = 0.6, restitution: float = 0.1,
           density_kg_m3: float = 500.0) -> list[Body]:
    """``n`` boxes of about ``size_m`` stacked on each other, each shifted by ``offset_sd`` of its
    size: some such stacks stand, some topple by themselves."""
    bodies, top = [], base_z_m
    for i in range(n):
        ext = size_m * rng.uniform(0.8, 1.2, 3)
        offset = rng.normal(0.0, offset_sd * size_m, 2)
        bodies.append(_body(f"{prefix}{i}", BoxShape(tuple(float(v) for v in ext)),
                            (x_m + offset[0], offset[1], top + ext[2] / 2), mass_kg=density_kg_m3 * float(np.prod(ext)),
                            friction=friction, restitution=restitution, orientation=_yaw(rng.normal(0.0, 0.1))))
        top += float(ext[2])
    return bodies


def _floor(rng: np.random.Generator, restitution: float = 0.1) -> Floor:
    return Floor(friction=float(rng.uniform(0.5, 1.0)), restitution=restitution)


def launch(rng: np.random.Generator, name: str) -> Scene:
    """A ball or a block launched along +x into a stack of 2-5 blocks, at 0.5-15 m/s, up to 10x a block's mass."""
    size = float(rng.uniform(0.1, 0.4))
    stack = _stack(rng, "block", int(rng.integers(2, 6)), size, offset_sd=0.05)
    block_mass = float(np.mean([b.mass_kg for b in stack]))
    mass = block_mass * float(np.exp(rng.uniform(math.log(0.3), math.log(10.0))))
    speed = float(np.exp(rng.uniform(math.log(0.5), math.log(15.0))))
    level = int(rng.integers(0, len(stack)))
    z = stack[level].position_m[2]
    if rng.random() < 0.6:
        radius = size * float(rng.uniform(0.25, 0.5))
        shape, z = Sphere(radius), max(z, radius)
    else:
        side = size * float(rng.uniform(0.4, 0.8))
        shape, z = BoxShape((side, side, side)), max(z, side / 2)
    start = -size - 0.3 - float(rng.uniform(0.0, 0.3))
    projectile = _body("projectile", shape, (start, 0.0, z), mass_kg=mass, friction=0.5,
                       restitution=float(rng.uniform(0.0, 0.6)), linear_velocity_m_s=(speed, 0.0, 0.0),
                       position_sigma_m=0.0)
    return Scene(name=name, objects=tuple(stack) + (projectile,), support=_floor(rng))


def dominoes(rng: np.random.Generator, name: str) -> Scene:
    """5-20 thin slabs in a row, spaced at 0.4-1.1 of their height (a falling slab reaches the next
    one below ~1x), the first one tipped forward at 1-4 rad/s."""
    n = int(rng.integers(5, 21))
    height = float(rng.uniform(0.08, 0.2))
    thickness, width = height * float(rng.uniform(0.12, 0.2)), height * float(rng.uniform(0.4, 0.6))
    spacing = height * float(rng.uniform(0.4, 1.1))
    mass = 600.0 * height * thickness * width
    bodies = []
    for i in range(n):
        x = i * spacing + float(rng.normal(0.0, 0.02 * spacing))
        fields = {}
        if i == 0:
            # tipped about its front bottom edge: v = w x (centre - edge)
            spin = float(rng.uniform(1.0, 4.0))
            fields = {"angular_velocity_rad_s": (0.0, spin, 0.0),
                      "linear_velocity_m_s": (spin * height / 2, 0.0, spin * thickness / 2)}
        bodies.append(_body(f"domino{i}", BoxShape((thickness, width, height)), (x, 0.0, height / 2), mass_kg=mass,
                            friction=0.5, restitution=0.05, orientation=_yaw(rng.normal(0.0, 0.03)), **fields))
    return Scene(name=name, objects=tuple(bodies), support=_floor(rng))


def ramp(rng: np.random.Generator, name: str) -> Scene:
    """A static ramp (15-35 degrees); a ball rolls or a block slides down it into 1-3 stacked blocks."""
    slope = math.radians(float(rng.uniform(15.0, 35.0)))
    height = float(rng.uniform(0.2, 0.6))
    length = height / math.tan(slope)
    # the wedge's high end is at -x: it descends along +x
    ramp_body = Body("ramp", wedge(length, 0.5, height), (0.0, 0.0, 0.0), _IDENTITY, friction=0.5, restitution=0.1,
                     static=True)
    size = float(rng.uniform(0.08, 0.2))
    # the object starts near the top, resting on the slope (rotated to lie on it)
    along = float(rng.uniform(0.1, 0.3)) * length
    x_top, z_surface = -length / 2 + along, height * (1 - along / length)
    tilt = Rotation.from_euler("y", slope)
    normal = np.array([math.sin(slope), 0.0, math.cos(slope)])
    if rng.random() < 0.5:
        radius = size * float(rng.uniform(0.3, 0.5))
        shape, lift, friction = Sphere(radius), radius, 0.6
    else:
        side = size * float(rng.uniform(0.4, 0.7))
        shape, lift, friction = BoxShape((side, side, side)), side / 2, float(rng.uniform(0.05, 0.3))
    start = np.array([x_top, 0.0, z_surface]) + (lift + HULL_MARGIN_M) * normal
    mass = 500.0 * size ** 3 * float(np.exp(rng.uniform(0.0, math.log(5.0))))
    mover = _body("mover", shape, start, mass_kg=mass, friction=friction, restitution=0.1,
                  orientation=_quat(tilt), position_sigma_m=0.0)
    stack = _stack(rng, "block", int(rng.integers(1, 4)), size, x_m=length / 2 + size + float(rng.uniform(0.05, 0.3)),
                   offset_sd=0.05)
    return Scene(name=name, objects=(ramp_body, mover, *stack), support=_floor(rng))


def drop(rng: np.random.Generator, name: str) -> Scene:
    """An object dropped from 0.2-2 m onto a stack of 1-3 blocks or into a container (a bowl or an open box)."""
    size = float(rng.uniform(0.08, 0.25))
    fall = float(rng.uniform(0.2, 2.0))
    radius = size * float(rng.uniform(0.25, 0.45))
    kind = rng.choice(["ball", "box", "cylinder"])
    shape = {"ball": Sphere(radius), "box": BoxShape((2 * radius,) * 3), "cylinder": Cylinder(radius, 2 * radius)}[kind]
    if rng.random() < 0.5:
        below = _stack(rng, "block", int(rng.integers(1, 4)), size, offset_sd=0.1)
        top = max(b.position_m[2] + b.shape.extents_m[2] / 2 for b in below)
        aim = rng.normal(0.0, 0.3 * size, 2)
    else:
        wall = 0.08 * size
        if rng.random() < 0.5:
            container = bowl(1.2 * size, 0.8 * size, wall)
        else:
            container = open_box(2.4 * size, 0.8 * size, wall)
        below = [_body("container", container, (0.0, 0.0, 0.0), mass_kg=600.0 * size ** 3, friction=0.6,
                       restitution=0.2)]
        top, aim = 0.9 * size, rng.normal(0.0, 0.4 * size, 2)
    dropped = _body("dropped", shape, (aim[0], aim[1], top + fall + radius), mass_kg=500.0 * size ** 3 *
                    float(rng.uniform(0.5, 4.0)), friction=0.5, restitution=float(rng.uniform(0.0, 0.6)),
                    orientation=_quat(Rotation.random(random_state=int(rng.integers(2 ** 31)))), position_sigma_m=0.0)
    return Scene(name=name, objects=(*below, dropped), support=_floor(rng))


def strike(rng: np.random.Generator, name: str) -> Scene:
    """A heavy object (10-100x) sliding at 1-5 m/s into a light block standing on end, with a second behind it."""
    size = float(rng.uniform(0.08, 0.3))
    light = 200.0 * size ** 3 * 2
    ratio = float(np.exp(rng.uniform(math.log(10.0), math.log(100.0))))
    targets = [_body(f"light{i}", BoxShape((0.5 * size, size, 2 * size)), (i * 1.2 * size, 0.0, size), mass_kg=light,
                     friction=0.5, restitution=float(rng.uniform(0.0, 0.5))) for i in range(2)]
    side = 1.2 * size
    heavy = _body("heavy", BoxShape((side, side, side)), (-1.5 * size - side / 2, 0.0, side / 2), mass_kg=light * ratio,
                  friction=float(rng.uniform(0.05, 0.3)), restitution=float(rng.uniform(0.0, 0.5)),
                  linear_velocity_m_s=(float(rng.uniform(1.0, 5.0)), 0.0, 0.0), position_sigma_m=0.0)
    return Scene(name=name, objects=(*targets, heavy), support=_floor(rng))


def rings(rng: np.random.Generator, name: str) -> Scene:
    """1-3 rings (tori of capsules) dropped from 1-20 cm onto a static post, off its axis by up to
    the gap between them: each ring threads the post or catches on its top."""
    post_r, post_h = float(rng.uniform(0.01, 0.03)), float(rng.uniform(0.15, 0.4))
    post = Body("post", Cylinder(post_r, post_h), (0.0, 0.0, post_h / 2), _IDENTITY, friction=0.4, restitution=0.2,
                static=True)
    bodies = [post]
    z = post_h
    for i in range(int(rng.integers(1, 4))):
        tube = float(rng.uniform(0.006, 0.015))
        radius = post_r + tube + float(rng.uniform(0.5, 3.0)) * post_r
        z += float(rng.uniform(0.01, 0.2)) + tube
        offset = float(rng.uniform(0.0, 1.5)) * (radius - tube - post_r)
        angle = float(rng.uniform(-math.pi, math.pi))
        tilt = Rotation.from_euler("x", float(rng.normal(0.0, 0.15)))
        bodies.append(_body(f"ring{i}", ring(radius, tube), (offset * math.cos(angle), offset * math.sin(angle), z),
                            mass_kg=1500.0 * 2 * math.pi * radius * math.pi * tube ** 2, friction=0.4,
                            restitution=0.2, orientation=_quat(tilt), position_sigma_m=0.0))
        z += tube
    return Scene(name=name, objects=tuple(bodies), support=_floor(rng, restitution=0.2))


def bouncy(rng: np.random.Generator, name: str) -> Scene:
    """2-4 large (0.3-1 m) blocks of restitution 0.5-0.9 stacked, the top one dropped from up to a
    third of its size, on a bouncy floor."""
    size = float(rng.uniform(0.3, 1.0))
    restitution = float(rng.uniform(0.5, 0.9))
    stack = _stack(rng, "block", int(rng.integers(2, 5)), size, offset_sd=0.12, restitution=restitution,
                   density_kg_m3=300.0)
    top = stack[-1]
    lift = float(rng.uniform(0.0, 0.33)) * size
    stack[-1] = _body(top.name, top.shape, (top.position_m[0], top.position_m[1], top.position_m[2] + lift),
                      mass_kg=top.mass_kg, friction=top.friction, restitution=restitution,
                      orientation=top.orientation_xyzw)
    return Scene(name=name, objects=tuple(stack), support=_floor(rng, restitution=float(rng.uniform(0.5, 0.9))))


def plates(rng: np.random.Generator, name: str) -> Scene:
    """3-8 thin plates (thickness 1/30-1/10 of their width) stacked with overhangs."""
    width = float(rng.uniform(0.1, 0.4))
    bodies, top = [], 0.0
    for i in range(int(rng.integers(3, 9))):
        thick = width * float(rng.uniform(1 / 30, 1 / 10))
        w, d = width * float(rng.uniform(0.7, 1.3)), width * float(rng.uniform(0.5, 1.0))
        offset = rng.normal(0.0, 0.2 * width, 2)
        bodies.append(_body(f"plate{i}", BoxShape((w, d, thick)), (offset[0], offset[1], top + thick / 2),
                            mass_kg=2500.0 * w * d * thick, friction=float(rng.uniform(0.3, 0.8)), restitution=0.05,
                            orientation=_yaw(rng.normal(0.0, 0.3))))
        top += thick
    return Scene(name=name, objects=tuple(bodies), support=_floor(rng))


def caps(rng: np.random.Generator, name: str) -> Scene:
    """A tower of 2-5 blocks capped by a cone, a ring or a bowl; in half of them a ball is launched
    at its base (0.6-13 m/s, as heavy as 0.5-3 blocks)."""
    size = float(rng.uniform(0.1, 0.5))
    stack = _stack(rng, "block", int(rng.integers(2, 6)), size, offset_sd=0.08,
                   restitution=float(rng.uniform(0.0, 0.5)))
    top = max(b.position_m[2] + b.shape.extents_m[2] / 2 for b in stack)
    centre = stack[-1].position_m
    kind = rng.choice(["cone", "ring", "bowl"])
    if kind == "cone":
        shape, z = cone(0.45 * size, 0.9 * size), top
    elif kind == "ring":
        tube = 0.08 * size
        shape, z = ring(0.4 * size, tube), top + tube
    else:
        shape, z = bowl(0.3 * size, 0.3 * size, 0.05 * size), top
    offset = rng.normal(0.0, 0.1 * size, 2)
    bodies = [*stack, _body("cap", shape, (centre[0] + offset[0], centre[1] + offset[1], z),
                            mass_kg=300.0 * size ** 3, friction=0.6, restitution=0.2)]
    if rng.random() < 0.5:
        radius = 0.3 * size
        block = float(np.mean([b.mass_kg for b in stack]))
        bodies.append(_body("ball", Sphere(radius), (-size - 0.4, 0.0, radius),
                            mass_kg=block * float(rng.uniform(0.5, 3.0)),
                            friction=0.4, restitution=float(rng.uniform(0.0, 0.6)),
                            linear_velocity_m_s=(float(rng.uniform(0.6, 13.0)), 0.0, 0.0), position_sigma_m=0.0))
    return Scene(name=name, objects=tuple(bodies), support=_floor(rng))


#: the ranges ``stacks`` draws over: those of the self-check's validated envelope (checking/envelope.py;
#: tests/test_zoo.py holds the two together)
STACK_SIDES_M = (0.02, 1.0)
STACK_MAX_ASPECT = 3.0
STACK_MAX_OBJECTS = 12
STACK_FRICTION = (0.4, 1.0)
STACK_MAX_RESTITUTION = 0.0
STACK_MAX_MASS_RATIO = 10.0
STACK_MAX_CARRIED_RATIO = 3.0


def stacks(rng: np.random.Generator, name: str) -> Scene:
    """1-3 stacks of 1-6 boxes at rest side by side (12 at most), over the whole validated envelope:
    sides 2 cm-1 m (a third of the boxes long, up to 3:1), friction 0.4-1, no restitution, masses
    up to 10x apart but no box more than 3x as heavy as any box under it (a light box on a heavy
    one, not under it; a heavy stack beside a light one), each box shifted by 15% of the scene's
    size and turned: some stacks stand, some topple into their neighbours, which stand within reach."""
    size = float(np.exp(rng.uniform(math.log(0.04), math.log(0.5))))
    counts = [int(rng.integers(1, 7)) for _ in range(int(rng.integers(1, 4)))]
    lo, hi = STACK_SIDES_M
    columns = []
    for count in counts[:STACK_MAX_OBJECTS]:
        column, z = [], 0.0
        for _ in range(count):
            ext = size * rng.uniform(0.6, 1.5, 3)
            if rng.random() < 1 / 3:
                ext[int(rng.integers(3))] *= float(rng.uniform(2.0, 3.0))
            ext = np.clip(ext, lo, hi)
            ext = np.minimum(ext, STACK_MAX_ASPECT * ext.min())
            offset = rng.normal(0.0, 0.15 * size, 2)
            column.append((ext, (float(offset[0]), float(offset[1]), z + float(ext[2]) / 2), float(rng.normal(0.0, 0.3)),
                           500.0 * float(np.exp(rng.uniform(0.0, math.log(STACK_MAX_MASS_RATIO)))) * float(np.prod(ext))))
            z += float(ext[2])
        columns.append(column)
    heaviest = max(mass for column in columns for *_, mass in column)
    bodies, right = [], None
    for c, column in enumerate(columns):
        lightest_below = math.inf
        for i, (ext, centre, yaw, mass) in enumerate(column):  # bottom up: none far heavier than a box under it
            mass = min(max(mass, heaviest / STACK_MAX_MASS_RATIO), STACK_MAX_CARRIED_RATIO * lightest_below)
            column[i] = (ext, centre, yaw, mass)
            lightest_below = min(lightest_below, mass)
        # each stack clear of the last by up to half the size (footprints bounded by their diagonals)
        reach = [(centre[0] - math.hypot(*ext[:2]) / 2, centre[0] + math.hypot(*ext[:2]) / 2)
                 for ext, centre, _, _ in column]
        shift = 0.0 if right is None else right - min(a for a, _ in reach) + float(rng.uniform(0.0, 0.5)) * size
        right = shift + max(b for _, b in reach)
        for i, (ext, (x, y, z), yaw, mass) in enumerate(column):
            if len(bodies) == STACK_MAX_OBJECTS:
                break
            bodies.append(_body(f"s{c}b{i}", BoxShape(tuple(float(v) for v in ext)), (x + shift, y, z),
                                mass_kg=mass,
                                friction=float(rng.uniform(*STACK_FRICTION)),
                                restitution=float(rng.uniform(0.0, STACK_MAX_RESTITUTION)), orientation=_yaw(yaw)))
    floor = Floor(friction=float(rng.uniform(*STACK_FRICTION)), restitution=float(rng.uniform(0.0, STACK_MAX_RESTITUTION)))
    return Scene(name=name, objects=tuple(bodies), support=floor)


@functools.lru_cache(maxsize=1)
def _household_meshes() -> tuple[Compound, Compound]:
    """The mug (with a handle) and the bowl of engine/scene/household.py as convex parts, decomposed
    once per machine (the decomposition cache, by their content) and once per process here."""
    from . import household as H
    from .meshes import MeshAccess, triangles_shape

    access = MeshAccess(roots=())
    return tuple(triangles_shape(vertices[faces].reshape(-1, 3), f"household.{what}", access)  # type: ignore[return-value]
                 for what, (vertices, faces) in (("mug", H.mug()), ("bowl", H.bowl())))


#: the household mug's inside (engine/scene/household.py's defaults)
MUG_INNER_RADIUS_M, MUG_HEIGHT_M, MUG_BOTTOM_M = 0.035, 0.1, 0.006

#: the heaviest ladle the household family leans into its mug (``household``)
LADLE_MAX_KG = 0.5
#: how far above the mesh's rim the ladle is placed before the scene sets it down (``Scene.set_down_m``)
LADLE_LIFT_M = 0.006


def household(rng: np.random.Generator, name: str) -> Scene:
    """Kitchen things on a floor, from procedural meshes read as convex parts: a mug (with a handle)
    with a 40 cm rod (a ladle) leaning in it over the rim, a bowl with 1-3 balls dropped 1.5-3 cm
    into it, and a can standing on a box 5-12 cm from the middle of its top (past 9.5 cm, its centre
    is over the edge). The ladle weighs 0.1-0.5 kg: the mug tips under those over about 0.2 kg, in
    `default`, `fine` and `paper` alike (the quasi-static bound, the two together with their centre of
    mass over the base's edge, is 0.31 kg: the ladle settling onto the rim pushes it over sooner).
    The ladle's end stands clear of the wall's convex parts: 3 mm from the wall (its corners inside
    them), `paper` let it slide out over the rim at 0.42 kg where `default`, `fine` and MuJoCo tip
    the mug (benchmarks/results/meshes/rod_on_rim.md)."""
    mug_shape, bowl_shape = _household_meshes()
    # the convex parts reach a little below the mesh's base (and above its rim), and pybullet keeps a
    # convex mesh a collision margin from what it touches: each object stands on its parts
    mug_z, bowl_z = (HULL_MARGIN_M - float(surface_points(shape)[:, 2].min()) for shape in (mug_shape, bowl_shape))
    bodies = []
    mug_xy, mug_yaw = rng.normal(0.0, 0.01, 2), float(rng.uniform(-math.pi, math.pi))
    turn = Rotation.from_euler("z", mug_yaw)
    bodies.append(_body("mug", mug_shape, (*mug_xy, mug_z), mass_kg=2000.0 * mug_shape.volume_m3, friction=0.6,
                        restitution=0.0, orientation=_quat(turn)))
    # the ladle: one end on the inner floor by the far wall, leaning over the near rim (the handle's side)
    far = -MUG_INNER_RADIUS_M + 0.01  # its 12 mm wide end clear of the curved wall
    angle = math.atan2(MUG_HEIGHT_M - MUG_BOTTOM_M, MUG_INNER_RADIUS_M - far)
    along, across = np.array([math.cos(angle), 0, math.sin(angle)]), np.array([-math.sin(angle), 0, math.cos(angle)])
    length, width, thickness = 0.4, 0.012, 0.004
    # LADLE_LIFT_M above the mesh's rim (clear of the parts' thicker one); the scene sets it down onto them
    centre = np.array([far, 0, MUG_BOTTOM_M + mug_z + LADLE_LIFT_M]) + length / 2 * along + thickness / 2 * across
    lean = turn * Rotation.from_euler("y", -angle)
    bodies.append(_body("ladle", BoxShape((length, width, thickness)), (*(turn.apply(centre)[:2] + mug_xy),
                                                                         centre[2]),
                        mass_kg=float(np.exp(rng.uniform(math.log(0.1), math.log(LADLE_MAX_KG)))), friction=0.6,
                        restitution=0.0, orientation=_quat(lean)))
    bowl_x = 0.35 + float(rng.normal(0.0, 0.01))
    bodies.append(_body("bowl", bowl_shape, (bowl_x, 0.0, bowl_z), mass_kg=2000.0 * bowl_shape.volume_m3, friction=0.6,
                        restitution=0.0, orientation=_yaw(rng.uniform(-math.pi, math.pi))))
    for i in range(int(rng.integers(1, 4))):
        radius = float(rng.uniform(0.012, 0.02))
        at = (bowl_x + 0.035 * math.cos(2.1 * i), 0.035 * math.sin(2.1 * i))
        bodies.append(_body(f"ball{i}", Sphere(radius), (*at, bowl_z + 0.045 + radius + float(rng.uniform(0.015, 0.03))),
                            mass_kg=float(rng.uniform(0.02, 0.06)), friction=0.6, restitution=0.0,
                            position_sigma_m=0.0))
    # a cereal box, and a can on it
    box = (0.19, 0.07, 0.28)
    box_x = 0.7 + float(rng.normal(0.0, 0.01))
    bodies.append(_body("box", BoxShape(box), (box_x, 0.0, box[2] / 2), mass_kg=0.45, friction=0.6, restitution=0.0))
    bodies.append(_body("can", Cylinder(0.033, 0.122), (box_x + float(rng.choice([-1, 1]) * rng.uniform(0.05, 0.12)),
                                                       float(rng.uniform(-0.02, 0.02)), box[2] + 0.061),
                        mass_kg=0.35, friction=0.5, restitution=0.0))
    return Scene(name=name, objects=tuple(bodies), support=_floor(rng, restitution=0.0), set_down_m=0.01)


#: What every family is asked: the node's default queries (config.DEFAULT_QUERIES, which scenes may
#: not import: a test keeps the two equal)
ZOO_QUERIES: frozenset[str] = frozenset({"fall", "any_fall", "direction", "far"})
#: What a family is asked besides them: whether the mug has tipped over (its
#: centre drops less than the fall query's threshold when it does)
EXTRA_QUERIES: dict[str, frozenset[str]] = {"household": frozenset({"tipped"})}


def family_queries(family: str) -> frozenset[str]:
    """What the benchmark and the tests ask of a family's scenes: the node's default queries and the
    family's own (``EXTRA_QUERIES``)."""
    return ZOO_QUERIES | EXTRA_QUERIES.get(family, frozenset())


#: Every family, in the order the benchmark and the docs list them.
FAMILIES: dict[str, Callable[[np.random.Generator, str], Scene]] = {
    "launch": launch, "dominoes": dominoes, "ramp": ramp, "drop": drop, "strike": strike, "rings": rings,
    "bouncy": bouncy, "plates": plates, "caps": caps, "stacks": stacks, "household": household,
}


def zoo_scene(family: str, seed: int, index: int) -> Scene:
    """Scene ``index`` of ``family``: a function of (family, seed, index) alone."""
    if family not in FAMILIES:
        raise ValueError(f"family: must be one of {', '.join(FAMILIES)}, got {family!r}")
    rng = np.random.default_rng([seed, zlib.crc32(family.encode()), index])
    return validate_scene(FAMILIES[family](rng, f"zoo_{family}_{seed}_{index:03d}"))


def scene_zoo(seed: int, per_family: int, families: tuple[str, ...] | None = None) -> list[Scene]:
    """``per_family`` scenes of every family (or of ``families``), family by family."""
    return [zoo_scene(family, seed, i) for family in (families or tuple(FAMILIES)) for i in range(per_family)]


def family_of(scene: Scene) -> str:
    """The family a zoo scene's name says it belongs to."""
    return scene.name.split("_")[1]


def zoo_sigma_m(scene: Scene) -> float:
    """The position noise the zoo's benchmark and tests use: 5% of the smallest dynamic body (as the catalogue's)."""
    return 0.05 * min(b.smallest_extent_m for b in scene.dynamic_objects)
