"""Building worlds again and again keeps no memory: the node builds one for every question's
geometry, and a week of questions must not grow it (issue 50's soak)."""

from __future__ import annotations

import ctypes
import gc
import sys
import tracemalloc

import numpy as np

from ipe_ros.engine.actions.geometry import contacts, geometry_world
from ipe_ros.engine.config import preset
from ipe_ros.engine.scene.catalogue import capped_tower
from ipe_ros.engine.simulation import bullet, world


def test_references_a_call_keeps_are_given_back_and_others_left():
    leaked, kept = (1.5, 2.5), (3.5, 4.5)  # fresh tuples, referenced only here
    before = sys.getrefcount(leaked), sys.getrefcount(kept)
    result = bullet.without_leaked_references(lambda: ctypes.pythonapi.Py_IncRef(ctypes.py_object(leaked)) or 7,
                                             (leaked, kept))
    assert result == 7 and (sys.getrefcount(leaked), sys.getrefcount(kept)) == before


def test_a_scene_with_a_convex_hull_built_600_times_keeps_no_python_memory():
    """pybullet 3.2.7 kept every hull's vertex lists (~1.8 KB a world, for ever) before the fix."""
    scene = capped_tower(3.0)  # its cone is a convex hull
    bodies = scene.dynamic_objects
    positions = np.array([b.centre_of_mass_m for b in bodies])
    masses = np.array([b.resolved_mass_kg for b in bodies])
    settings = preset("default")
    for _ in range(300):  # warm-up: caches and free lists fill (bounded)
        world.build_world(scene, positions, masses, settings)
    tracemalloc.start()
    try:
        gc.collect()
        start = tracemalloc.take_snapshot()
        for _ in range(600):
            world.build_world(scene, positions, masses, settings)
        gc.collect()
        grown = sum(s.size_diff for s in tracemalloc.take_snapshot().compare_to(start, "filename"))
    finally:
        tracemalloc.stop()
    assert grown < 30_000, f"{grown} bytes kept by 600 worlds (the leak kept ~1,100,000)"


def test_a_geometry_world_never_switches_to_the_direct_solver():
    """It is never stepped; each switch allocates memory pybullet never frees."""
    scene = capped_tower(3.0)
    masses = [b.resolved_mass_kg for b in scene.dynamic_objects]
    assert world.uses_direct_solver(scene, preset("paper"), masses)  # a `paper` rollout of it uses the direct solver
    assert geometry_world(scene).direct_solver is False
    assert contacts(scene).pairs  # and its contacts are still read


def test_hull_files_are_bounded_and_a_hull_used_again_is_written_again(monkeypatch):
    """A compound's hull parts reach pybullet as files, one per distinct hull: a node sent new shapes
    for a week keeps the last MAX_HULL_FILES of them (here 4), not all; a hull whose file went is
    written again under a new name (pybullet may cache a mesh by its file's name)."""
    import os

    from ipe_ros.engine.scene.bodies import Body, Floor, Scene
    from ipe_ros.engine.scene.shapes import Compound, CompoundPart, ConvexHull
    from ipe_ros.engine.simulation import hull_files

    monkeypatch.setattr(hull_files, "MAX_HULL_FILES", 4)

    def scene_with(size: float) -> Scene:
        corners = tuple((x * size, y * 0.05, z * 0.05) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1))
        part = CompoundPart(ConvexHull(corners + ((0.0, 0.0, 0.07),)))
        body = Body(name="roof", shape=Compound(parts=(part, CompoundPart(ConvexHull(corners), position_m=(0.0, 0.0, -0.1)))),
                    position_m=(0.0, 0.0, 0.2), orientation_xyzw=(0.0, 0.0, 0.0, 1.0), friction=0.5, restitution=0.0,
                    mass_kg=1.0)
        return Scene(name="hulls", objects=(body,), support=Floor(friction=0.5, restitution=0.0),
                     gravity_m_s2=(0.0, 0.0, -9.81))

    def build(scene: Scene) -> None:
        body = scene.dynamic_objects[0]
        world.build_world(scene, np.array([body.centre_of_mass_m]), np.array([body.resolved_mass_kg]),
                          preset("default"))

    first = scene_with(0.05)
    build(first)
    names = set(hull_files._HULL_FILES.values())
    for i in range(12):  # 24 new hulls
        build(scene_with(0.06 + 0.01 * i))
        assert len(hull_files._HULL_FILES) <= 4
    on_disk = [n for n in os.listdir(hull_files.hull_folder()) if n.endswith(".obj")]
    assert len(on_disk) <= 4 and not names & set(hull_files._HULL_FILES.values())
    build(first)  # its files went: written again, under new names
    assert not names & set(hull_files._HULL_FILES.values()) and all(os.path.exists(p) for p in hull_files._HULL_FILES.values())
