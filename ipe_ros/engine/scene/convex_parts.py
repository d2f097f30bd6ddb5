"""A closed mesh's convex parts, by CoACD: in this process, or in a spawned one ended by its process
id when over its time (CoACD has no time limit of its own) or when its reader closes; the parts kept
within the mesh's bounds and the compound limits (``limits``).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ..errors import SceneError
from . import limits

#: every part's hull is kept to this many vertices (CoACD's max_ch_vertex), so that a mesh's parts
#: stay within the compound limits (limits.MAX_COMPOUND_VERTICES)
MAX_PART_VERTICES = 64


def _coacd_hulls(vertices: np.ndarray, faces: np.ndarray, settings) -> list[np.ndarray]:
    import coacd

    coacd.set_log_level("error")
    most = limits.MAX_COMPOUND_PARTS if settings.max_parts < 0 else min(settings.max_parts, limits.MAX_COMPOUND_PARTS)
    # CoACD keeps a hull to max_ch_vertex only when it decimates
    parts = coacd.run_coacd(coacd.Mesh(vertices, faces), threshold=settings.threshold, max_convex_hull=most,
                            decimate=True, max_ch_vertex=MAX_PART_VERTICES, seed=settings.seed)
    return within_vertex_budget([np.asarray(v, float) for v, _ in parts if len(v) >= 4])


def within_vertex_budget(hulls: list[np.ndarray], budget: int = limits.MAX_COMPOUND_VERTICES) -> list[np.ndarray]:
    """The hulls, those of a decomposition over ``budget`` vertices together each thinned to its share
    (at least 8) by farthest-point sampling of its own vertices: every part stays inside its hull and
    keeps its extremes. The mass, centre of mass and inertia come from the mesh, not from the parts."""
    total = sum(len(h) for h in hulls)
    if total <= budget:
        return hulls
    out = []
    for hull in hulls:
        share = max(8, int(budget * len(hull) / total))
        out.append(hull if len(hull) <= share else _farthest_points(hull, share))
    return out


def _farthest_points(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` of ``points``, each the farthest from those already taken (the first: the farthest
    from the centroid): deterministic, and spread over the hull's extremes."""
    taken = [int(np.argmax(np.linalg.norm(points - points.mean(axis=0), axis=1)))]
    distance = np.linalg.norm(points - points[taken[0]], axis=1)
    for _ in range(count - 1):
        taken.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[taken[-1]], axis=1))
    return points[sorted(taken)]


def _coacd_in_process(connection, vertices: np.ndarray, faces: np.ndarray, settings) -> None:
    """A spawned process's work: the hulls, or the error, sent back."""
    try:
        connection.send(("hulls", _coacd_hulls(vertices, faces, settings)))
    except Exception as exc:  # noqa: BLE001 - the parent names the object and the fix
        connection.send(("error", f"{type(exc).__name__}: {exc}"))
    finally:
        connection.close()


class DecompositionTimeout(SceneError):
    """A decomposition ran past its time (remembered with that time: more time may succeed)."""


class DecompositionStopped(SceneError):
    """A decomposition ended because its reader is closing (nothing remembered)."""


def _coacd_within(vertices: np.ndarray, faces: np.ndarray, settings, within_s: float,
                  path: str, stop: threading.Event | None = None) -> list[np.ndarray]:
    """``_coacd_hulls`` in a spawned process, ended (by its process id) when it takes longer than
    ``within_s`` or ``stop`` is set: a SceneError naming ``path`` and the fix."""
    import multiprocessing
    import time

    context = multiprocessing.get_context("spawn")  # never fork: the node's process holds rclpy
    receive, send = context.Pipe(duplex=False)
    worker = context.Process(target=_coacd_in_process, args=(send, vertices, faces, settings), daemon=True)
    worker.start()
    send.close()
    deadline = time.monotonic() + within_s
    answer = None
    try:
        while answer is None and (stop is None or not stop.is_set()):
            left = deadline - time.monotonic()
            if left <= 0:
                break
            if receive.poll(min(left, 0.1)):
                answer = receive.recv()
    except EOFError:  # the process died without an answer
        answer = ("error", f"the decomposition's process ended with code {worker.exitcode}")
    finally:
        receive.close()
        if worker.is_alive():
            worker.kill()
        worker.join()
    if answer is None and stop is not None and stop.is_set():
        raise DecompositionStopped(path, "its convex decomposition was stopped (the reader is closing)")
    if answer is None:
        raise DecompositionTimeout(path, f"its convex decomposition did not finish within {within_s:g} s; decompose "
                                         "it once ahead (`ipe predict` of a scene naming it caches the parts by the "
                                         "file's content, in $IPE_CACHE_DIR, for every later scene), simplify the "
                                         "mesh, or allow more time (the node's mesh_decomposition_s, ipe predict's --budget)")
    kind, value = answer
    if kind == "error":
        raise SceneError(path, f"its convex decomposition failed ({value})")
    return value


def decompose_hulls(vertices: np.ndarray, faces: np.ndarray, settings, path: str,
               within_s: float | None = None, stop: threading.Event | None = None) -> list[np.ndarray]:
    if within_s is None and stop is not None:  # stoppable only in a process of its own
        within_s = math.inf
    hulls = (_coacd_hulls(vertices, faces, settings) if within_s is None
             else _coacd_within(vertices, faces, settings, within_s, path, stop))
    if not hulls:
        raise SceneError(path, "its convex decomposition is empty (a flat or degenerate mesh)")
    # CoACD remeshes a surface that is not a manifold (a union of overlapping shells, as collision
    # meshes are) on a grid, and its parts then reach up to a cell past the mesh: a can set on its
    # lowest point sank 0.4-0.9 mm into the floor and was refused. The parts stay within the mesh's bounds
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    clipped = [np.clip(hull, low, high) for hull in hulls]
    kept = [hull for hull in clipped if _solid(hull)]  # a sliver wholly past the bounds is flat once clipped
    if not kept:
        raise SceneError(path, "its convex decomposition is empty (a flat or degenerate mesh)")
    return kept


def _solid(points: np.ndarray) -> bool:
    from scipy.spatial import ConvexHull as QHull

    try:
        return QHull(points).volume > 0
    except Exception:  # noqa: BLE001 - qhull's errors: coplanar points
        return False
