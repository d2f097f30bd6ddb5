"""Household objects as closed meshes, made procedurally: cups, mugs without handles and bowls (a
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
