"""Small scene builders for tests."""

from __future__ import annotations

from ipe_ros.engine import Box, Floor, Scene

IDENTITY = (0.0, 0.0, 0.0, 1.0)


def block(name: str, x: float, y: float, z: float, extents=(0.2, 0.6, 0.2), **kw) -> Box:
    kw.setdefault("mass_kg", 1.0)
    return Box(name=name, extents_m=tuple(extents), position_m=(x, y, z), orientation_xyzw=IDENTITY,
               friction=0.9, restitution=0.0, **kw)


def floor_scene(*boxes: Box, name: str = "test") -> Scene:
    return Scene(name=name, objects=tuple(boxes), support=Floor(friction=1.0, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


def without_timing(d: dict) -> dict:
    d = dict(d)
    d.pop("wall_s")
    return d
