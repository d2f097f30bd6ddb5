"""Scene generators: the paper's block towers (Exps. 1-4) and bump tables (Exp. 5). Seeded, pure.

Towers: 10 blocks of aspect 3:1:1 stacked inside a square column by a sequential random process
such that no single placed block would fall off its own support (later blocks may still topple it):
each new block gets a random axis-aligned orientation and a random horizontal position, is dropped
onto what lies below, and is kept only if its centre of mass lies over the convex hull of its
contact patches. Long axes lie along x, y or z, as in the paper's stimuli.

Tables (paper Exp. 5): red and yellow cubes in stacks on a table top, crossed with five tables:
T0 flat and T1..T4 with two short walls on different edges.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .bodies import Body, Box, Floor, Scene, Table

from .validation import validate_scene

_IDENTITY = (0.0, 0.0, 0.0, 1.0)
_HALF = math.sqrt(0.5)
#: Orientations of a 1 x 3 x 1 block (long axis along y in its own frame): long axis y, x, z.
_ORIENTATIONS = {
    "y": (0.0, 0.0, 0.0, 1.0),
    "x": (0.0, 0.0, _HALF, _HALF),   # 90 degrees about z
    "z": (_HALF, 0.0, 0.0, _HALF),   # 90 degrees about x
}


def _footprint(extents: np.ndarray, long_axis: str) -> np.ndarray:
    """Scene-frame (dx, dy, dz) full sizes of a block with the given long axis."""
    short, long_ = extents[0], extents[1]
    return {"x": np.array([long_, short, short]), "y": np.array([short, long_, short]),
            "z": np.array([short, short, long_])}[long_axis]


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain; returns hull vertices counter-clockwise."""
    pts = sorted(set(map(tuple, np.round(points, 12))))
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def _inside_hull(point: np.ndarray, hull: np.ndarray, margin: float) -> bool:
    """True when ``point`` is inside the hull by at least ``margin`` (hull counter-clockwise)."""
    if len(hull) < 3:
        return False
    for i in range(len(hull)):
        a, b = hull[i], hull[(i + 1) % len(hull)]
        edge = b - a
        # signed distance of point to the edge's line (positive inside for CCW)
        dist = (edge[0] * (point[1] - a[1]) - edge[1] * (point[0] - a[0])) / np.linalg.norm(edge)
        if dist < margin:
            return False
    return True


def generate_tower(rng: np.random.Generator, name: str, n_blocks: int = 10, short_side_m: float = 0.2,
                   column_half_width_m: float | None = None, friction: float = 0.894427,
                   mass_kg: float = 4.08, heavy_mask: str | None = None, heavy_ratio: float = 1.0,
                   max_tries_per_block: int = 200) -> Scene:
    """A paper-style tower. ``heavy_mask`` (one char per block, '1' = heavy) sets the groups; heavy
    blocks get ``heavy_ratio`` times the mass. Block centres stay within the column half width
    (default 1.5 short sides, as in the stimuli: +-0.3 m for 0.2 m blocks)."""
    extents = np.array([short_side_m, 3 * short_side_m, short_side_m])
    half_width = 1.5 * short_side_m if column_half_width_m is None else column_half_width_m
    placed: list[tuple[np.ndarray, np.ndarray, str]] = []  # (centre, scene-frame size, axis)
    margin = 0.02 * short_side_m
    eps = 1e-9
    for index in range(n_blocks):
        for _ in range(max_tries_per_block):
            axis = ("x", "y", "z")[int(rng.integers(3))]
            size = _footprint(extents, axis)
            xy = rng.uniform(-half_width, half_width, size=2)
            lo, hi = xy - size[:2] / 2, xy + size[:2] / 2
            # Rest on the highest top among overlapping blocks (or the floor).
            support_z, patches = 0.0, []
            for centre, other, _axis in placed:
                olo, ohi = centre[:2] - other[:2] / 2, centre[:2] + other[:2] / 2
                if np.all(np.minimum(hi, ohi) - np.maximum(lo, olo) > eps):
                    top = centre[2] + other[2] / 2
                    if top > support_z + eps:
                        support_z, patches = top, []
                    if abs(top - support_z) <= eps:
                        patches.append((np.maximum(lo, olo), np.minimum(hi, ohi)))
            if support_z == 0.0:
                break  # on the floor: always stable
            corners = np.array([[x, y] for plo, phi in patches for x in (plo[0], phi[0])
                                for y in (plo[1], phi[1])])
            if _inside_hull(xy, convex_hull(corners), margin):
                break
        else:
            raise RuntimeError(f"could not place block {index} of {name!r} stably in "
                               f"{max_tries_per_block} tries; widen the column")
        placed.append((np.array([xy[0], xy[1], support_z + size[2] / 2]), size, axis))

    mask = heavy_mask if heavy_mask is not None else "0" * n_blocks
    if len(mask) != n_blocks or set(mask) - {"0", "1"}:
        raise ValueError(f"heavy_mask: must be {n_blocks} characters of 0/1, got {mask!r}")
    boxes = tuple(
        Box(name=f"block{i}", extents_m=tuple(map(float, extents)),  # type: ignore[arg-type]
            position_m=tuple(float(v) for v in centre),  # type: ignore[arg-type]
            orientation_xyzw=_ORIENTATIONS[axis], friction=friction, restitution=0.0,
            mass_kg=mass_kg * (heavy_ratio if mask[i] == "1" else 1.0),
            group="heavy" if mask[i] == "1" else "light")
        for i, (centre, _size, axis) in enumerate(placed))
    return validate_scene(Scene(name=name, objects=boxes, support=Floor(friction=1.0, restitution=0.0),
                                gravity_m_s2=(0.0, 0.0, -9.8)))


def generate_towers(seed: int, count: int, **kwargs) -> list[Scene]:
    """``count`` towers named ``gen_tower_<seed>_<i>``, each from its own child seed."""
    children = np.random.SeedSequence(seed).spawn(count)
    return [generate_tower(np.random.default_rng(s), f"gen_tower_{seed}_{i:03d}", **kwargs)
            for i, s in enumerate(children)]


def state_pair(scene: Scene, rng: np.random.Generator, ratio: float = 10.0,
               n_heavy: int | None = None) -> tuple[Scene, Scene]:
    """The same geometry with two complementary heavy/light assignments (paper Exps. 3-4)."""
    boxes = scene.dynamic_objects
    n = len(boxes)
    n_heavy = n // 2 if n_heavy is None else n_heavy
    chosen = set(rng.choice(n, size=n_heavy, replace=False).tolist())
    masks = ("".join("1" if i in chosen else "0" for i in range(n)),
             "".join("0" if i in chosen else "1" for i in range(n)))
    light_mass = min(b.resolved_mass_kg for b in boxes)
    out = []
    for mask in masks:
        new_boxes = tuple(replace(b, mass_kg=light_mass * (ratio if m == "1" else 1.0), density_kg_m3=None,
                                  group="heavy" if m == "1" else "light") for b, m in zip(boxes, mask))
        out.append(replace(scene, name=f"{scene.name}_{mask}", objects=new_boxes))
    return out[0], out[1]


# ------------------------------------------------------------------------------------------------
# Exp. 5 tables

#: Which table edges carry the two short walls, per table (T0 is flat).
TABLE_WALLS = {
    "T0": (),
    "T1": ("+x", "-x"),
    "T2": ("+y", "-y"),
    "T3": ("+x", "+y"),
    "T4": ("-x", "-y"),
}


def make_table(kind: str, size_m: tuple[float, float] = (2.4, 1.6), wall_height_m: float = 0.2,
               wall_thickness_m: float = 0.1, floor_drop_m: float = 1.0) -> Table:
    """Table ``kind`` (T0..T4): top at z = 0 (as in the paper), a floor ``floor_drop_m`` below."""
    if kind not in TABLE_WALLS:
        raise ValueError(f"table: must be one of {', '.join(TABLE_WALLS)}, got {kind!r}")
    sx, sy = size_m
    walls = []
    for edge in TABLE_WALLS[kind]:
        sign = 1.0 if edge[0] == "+" else -1.0
        if edge[1] == "x":
            ext = (wall_thickness_m, sy, wall_height_m)
            pos = (sign * (sx / 2 - wall_thickness_m / 2), 0.0, wall_height_m / 2)
        else:
            ext = (sx, wall_thickness_m, wall_height_m)
            pos = (0.0, sign * (sy / 2 - wall_thickness_m / 2), wall_height_m / 2)
        walls.append(Box(name=f"wall{edge}", extents_m=ext, position_m=pos, orientation_xyzw=_IDENTITY,
                         friction=0.5, restitution=0.0, group="wall", static=True))
    return Table(top_height_m=0.0, size_m=size_m, center_xy_m=(0.0, 0.0), thickness_m=0.05, friction=0.5,
                 restitution=0.0, floor_z_m=-floor_drop_m, obstacles=tuple(walls))


def generate_block_configuration(rng: np.random.Generator, cube_m: float = 0.2,
                                 table_size_m: tuple[float, float] = (2.4, 1.6)) -> list[Body]:
    """Red/yellow blocks in stacks: random number (2-4) and heights (1-4) of stacks, random
    positions, and per stack a random shape (cube, or a box 2 cubes long); half red, half yellow."""
    n_stacks = int(rng.integers(2, 5))
    usable = np.array(table_size_m) / 2 - 2.5 * cube_m
    boxes: list[Body] = []
    centres: list[np.ndarray] = []
    for stack in range(n_stacks):
        for _ in range(100):
            xy = rng.uniform(-usable, usable)
            if all(np.linalg.norm(xy - c) > 3 * cube_m for c in centres):
                break
        centres.append(xy)
        long_block = bool(rng.random() < 0.3)
        ext = (2 * cube_m, cube_m, cube_m) if long_block else (cube_m, cube_m, cube_m)
        height = int(rng.integers(1, 5))
        for level in range(height):
            boxes.append(Box(name=f"s{stack}b{level}", extents_m=ext,
                             position_m=(float(xy[0]), float(xy[1]), cube_m * (level + 0.5)),
                             orientation_xyzw=_IDENTITY, friction=0.5, restitution=0.0, mass_kg=1.0))
    colours = ["red"] * (len(boxes) // 2) + ["yellow"] * (len(boxes) - len(boxes) // 2)
    order = rng.permutation(len(boxes))
    return [replace(b, group=colours[j]) for b, j in zip(boxes, order)]


def generate_tables(seed: int, configurations: int = 12, tables: tuple[str, ...] = tuple(TABLE_WALLS),
                    cube_m: float = 0.2) -> list[Scene]:
    """Every block configuration crossed with every table (paper: 12 x 5 = 60 scenes)."""
    children = np.random.SeedSequence(seed).spawn(configurations)
    scenes = []
    for i, child in enumerate(children):
        blocks = tuple(generate_block_configuration(np.random.default_rng(child), cube_m))
        for kind in tables:
            scene = Scene(name=f"gen_table_{seed}_c{i:02d}_{kind}", objects=blocks, support=make_table(kind),
                          gravity_m_s2=(0.0, 0.0, -9.81))
            scenes.append(validate_scene(scene))
    return scenes
