"""Convex hulls as Wavefront files: pybullet takes a compound's mesh parts only as files. One file per
distinct hull and process, the ``MAX_HULL_FILES`` last used, in a temporary folder removed at exit."""

from __future__ import annotations

import collections
import contextlib
import itertools
import os

import numpy as np

#: distinct hulls whose files are kept (least recently used first out): a node that is sent new
#: hull shapes for a week must not fill its memory and disk with them
MAX_HULL_FILES = 4096

_HULL_FILES: "collections.OrderedDict[tuple, str]" = collections.OrderedDict()
_HULL_FILES_WRITTEN = itertools.count()  # file names are never reused (pybullet may cache a mesh by its name)


def hull_file(vertices_m: np.ndarray) -> str:
    """A Wavefront file of one convex hull: pybullet takes compound parts that are meshes only as
    files. One per distinct hull and process (the ``MAX_HULL_FILES`` last used), in a temporary
    folder removed at exit."""
    # the rounded coordinates' bytes (+ 0.0: no negative zeros), not tuples of floats: this runs for
    # every part of every compound in every world built (a kitchen took 2.6 ms a world as tuples, 0.4 as bytes)
    key = (vertices_m.shape, (np.round(vertices_m, 12) + 0.0).tobytes())
    path = _HULL_FILES.get(key)
    if path is not None and os.path.exists(path):
        _HULL_FILES.move_to_end(key)
        return path
    from scipy.spatial import ConvexHull as QHull

    folder = hull_folder()
    path = os.path.join(folder, f"hull_{next(_HULL_FILES_WRITTEN)}.obj")
    faces = QHull(vertices_m).simplices
    with open(path, "w") as handle:
        handle.writelines(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in vertices_m)
        handle.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)
    _HULL_FILES[key] = path
    while len(_HULL_FILES) > MAX_HULL_FILES:
        _, old = _HULL_FILES.popitem(last=False)
        with contextlib.suppress(OSError):  # read by pybullet when its shape was made; not needed after
            os.remove(old)
    return path


def hull_folder() -> str:
    global _HULL_FOLDER
    if _HULL_FOLDER is None or not os.path.isdir(_HULL_FOLDER):
        import atexit
        import shutil
        import tempfile

        _HULL_FOLDER = tempfile.mkdtemp(prefix="ipe_hulls_")
        atexit.register(shutil.rmtree, _HULL_FOLDER, True)
        _HULL_FILES.clear()
    return _HULL_FOLDER


_HULL_FOLDER: str | None = None
