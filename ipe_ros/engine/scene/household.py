"""Household objects as closed meshes, made procedurally: cups, mugs with a handle and bowls (a
cup whose wall flares), for tests, benchmarks and scenes that need a real non-convex object.

``cup`` returns vertices (metres, base at z = 0, +z up) and outward-facing triangles; ``write_obj``
writes them as a Wavefront file a scene's mesh shape can name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def cup(outer_radius_m: float = 0.04, inner_radius_m: float = 0.035, height_m: float = 0.1,
        bottom_m: float = 0.006, top_flare_m: float = 0.0, sides: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """A closed cup: base, outer wall, rim, inner wall and inner floor. ``top_flare_m`` widens the rim
    by that much (a bowl); the wall keeps its thickness."""
    angles = np.linspace(0, 2 * np.pi, sides, endpoint=False)

    def ring(radius: float, z: float) -> np.ndarray:
        return np.c_[radius * np.cos(angles), radius * np.sin(angles), np.full(sides, z)]

    vertices = np.vstack([ring(outer_radius_m, 0.0), ring(outer_radius_m + top_flare_m, height_m),
                          ring(inner_radius_m + top_flare_m, height_m), ring(inner_radius_m, bottom_m),
                          [[0.0, 0.0, 0.0], [0.0, 0.0, bottom_m]]])
    faces = []
    for lower, upper in ((0, sides), (sides, 2 * sides), (2 * sides, 3 * sides)):  # outer wall, rim, inner wall
        for k in range(sides):
            a0, a1, b0, b1 = lower + k, lower + (k + 1) % sides, upper + k, upper + (k + 1) % sides
            faces += [(a0, a1, b1), (a0, b1, b0)]
    base, floor = 4 * sides, 4 * sides + 1
    for k in range(sides):
        faces += [(base, (k + 1) % sides, k), (floor, 3 * sides + k, 3 * sides + (k + 1) % sides)]
    return vertices, np.array(faces, np.int64)


def mug(outer_radius_m: float = 0.04, inner_radius_m: float = 0.035, height_m: float = 0.1, bottom_m: float = 0.006,
        handle_reach_m: float = 0.03, handle_radius_m: float = 0.006, sides: int = 32,
        handle_sides: int = 12, handle_segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A cup with a handle on its +x side: a closed tube of radius ``handle_radius_m`` along a half
    circle in the xz plane, reaching ``handle_reach_m`` out from the wall at mid-height, its capped
    ends at the wall. Two closed shells in one mesh: one rigid object, whose volume is the two
    shells' together (they touch the wall's line at y = 0 and do not overlap it)."""
    vertices, faces = cup(outer_radius_m, inner_radius_m, height_m, bottom_m, sides=sides)
    # the centre line: out from the wall, round a half circle, back to the wall; the arc as tall as
    # half the cup's inside, its outer point ``handle_reach_m`` from the wall with the tube
    arc_radius = (height_m / 2 - bottom_m) / 2
    stub = max(0.0, handle_reach_m - arc_radius - handle_radius_m)
    arc = np.linspace(-np.pi / 2, np.pi / 2, handle_segments - 1)
    line = np.vstack([[outer_radius_m, 0.0, height_m / 2 - arc_radius],
                      np.c_[outer_radius_m + stub + arc_radius * np.cos(arc), np.zeros_like(arc),
                            height_m / 2 + arc_radius * np.sin(arc)],
                      [outer_radius_m, 0.0, height_m / 2 + arc_radius]])
    tangents = np.gradient(line, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    around = np.linspace(0, 2 * np.pi, handle_sides, endpoint=False)
    rings = []
    for point, tangent in zip(line, tangents):
        normal = np.cross(tangent, [0.0, 1.0, 0.0])
        normal /= np.linalg.norm(normal)
        rings.append(point + handle_radius_m * (np.outer(np.cos(around), normal) + np.outer(np.sin(around), [0, 1.0, 0])))
    start = len(vertices)
    tube = np.vstack(rings)
    tube_faces = []
    for i in range(handle_segments):
        for k in range(handle_sides):
            a0, a1 = start + i * handle_sides + k, start + i * handle_sides + (k + 1) % handle_sides
            b0, b1 = a0 + handle_sides, a1 + handle_sides
            tube_faces += [(a0, b0, b1), (a0, b1, a1)]
    first, last = start + len(tube), start + len(tube) + 1
    end = start + handle_segments * handle_sides
    for k in range(handle_sides):
        tube_faces += [(first, start + k, start + (k + 1) % handle_sides),
                       (last, end + (k + 1) % handle_sides, end + k)]
    vertices = np.vstack([vertices, tube, line[0], line[-1]])
    return vertices, np.vstack([faces, np.array(tube_faces, np.int64)])


def bowl(sides: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """A bowl 0.16 m across at the rim, 0.06 m deep."""
    return cup(outer_radius_m=0.05, inner_radius_m=0.045, height_m=0.06, bottom_m=0.006, top_flare_m=0.03,
               sides=sides)


def write_obj(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    path = Path(path)
    with open(path, "w") as handle:
        handle.writelines(f"v {x!r} {y!r} {z!r}\n" for x, y, z in np.asarray(vertices, float).tolist())
        handle.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.asarray(faces).tolist())
    return path
