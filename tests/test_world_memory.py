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
    assert world.can_bounce(scene)  # a rollout of it uses the direct solver
    assert geometry_world(scene).direct_solver is False
    assert contacts(scene).pairs  # and its contacts are still read
