"""A scene turned about the vertical and shifted: the same physics in another frame.

Physics does not know which way a scene happens to point, so an answer must not either (beyond
chaos): the direct solver's friction once did (a box slid at 30 deg veered to 18 deg;
simulation/impacts.py), and tests/test_invariance.py holds every zoo family to it with this.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..errors import SceneError
from .bodies import Body, Floor, Scene, Table
from .shapes import quaternion_product


def turned(scene: Scene, yaw_rad: float, shift_m: tuple[float, float] = (0.0, 0.0)) -> Scene:
    """``scene`` turned by ``yaw_rad`` about the vertical through the origin, then shifted
    horizontally by ``shift_m``: every body's pose and velocities, and gravity (an incline's tilt).
    A table is axis-aligned (``size_m`` along x and y), so it turns by quarter turns only."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    dx, dy = float(shift_m[0]), float(shift_m[1])

    def vector(v):
        return (c * v[0] - s * v[1], s * v[0] + c * v[1], float(v[2]))

    def point(v):
        x, y, z = vector(v)
        return (x + dx, y + dy, z)

    yaw = np.array([0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2)])

    def body(b: Body) -> Body:
        orientation = quaternion_product(yaw, np.asarray(b.orientation_xyzw, float))
        return replace(b, position_m=point(b.position_m), orientation_xyzw=tuple(float(v) for v in orientation),
                       linear_velocity_m_s=vector(b.linear_velocity_m_s),
                       angular_velocity_rad_s=vector(b.angular_velocity_rad_s))

    support = scene.support
    if isinstance(support, Table):
        quarter_turns = yaw_rad / (math.pi / 2)
        if abs(quarter_turns - round(quarter_turns)) > 1e-9:
            raise SceneError("support", f"a table's sides lie along x and y: turn it by a multiple of 90 deg, "
                                        f"not {math.degrees(yaw_rad):g} deg")
        width, depth = support.size_m if round(quarter_turns) % 2 == 0 else support.size_m[::-1]
        cx, cy, _ = point((*support.center_xy_m, 0.0))
        support = replace(support, size_m=(width, depth), center_xy_m=(cx, cy),
                          obstacles=tuple(body(b) for b in support.obstacles))
    elif not isinstance(support, Floor):
        raise SceneError("support", f"cannot turn a {type(support).__name__}")
    return replace(scene, objects=tuple(body(b) for b in scene.objects), support=support,
                   gravity_m_s2=vector(scene.gravity_m_s2))
