"""Open meshes closed down a stated ladder (a mesh shape's ``open``: "repair", the default, or
"refuse"): 1. holes filled where small; 2. a watertight remesh from voxels; 3. the convex hull. How
is kept in the mesh's metadata (``REPAIRED``) and travels with the parts (``MeshSource.repaired``).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError

#: what to do with a mesh that is not closed (a mesh shape's ``open``)
OPEN_POLICIES = ("repair", "refuse")
#: trimesh metadata key: how an open mesh was closed
REPAIRED = "ipe_repaired"


def repaired_sources(scene) -> dict:
    """Per object read from an open mesh file, its ``MeshSource`` (``repaired``: how it was closed)."""
    return {b.name: b.shape.source for b in scene.objects
            if getattr(b.shape, "source", None) is not None and b.shape.source.repaired}
#: holes are filled (rung 1) where their caps add at most this share of the surface: small holes
MAX_CAP_SHARE = 0.1
#: the watertight remesh's voxels across the mesh's largest extent (rung 2): at 24 a mug's remesh
#: decomposes in ~12 s here (48: 70 s; its stair steps smoothed or not), its thin walls a voxel or
#: two thick (the open mug of tests/test_meshes.py holds 1.6x its walls' volume: the answer says it)
REMESH_VOXELS = 24


def closed_solid(mesh, path: str, what: str, policy: str):
    """``mesh`` if closed; else, by ``policy`` "refuse", a SceneError; by "repair", the first rung of
    the ladder that gives a closed solid: 1. its holes filled, where small (``MAX_CAP_SHARE``); 2. a
    watertight remesh, the solid its surface encloses in voxels (``REMESH_VOXELS`` across); 3. its
    convex hull. How (and the volume it then has) is in ``mesh.metadata[REPAIRED]``."""
    if mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0:
        return mesh
    if policy == "refuse":
        raise SceneError(path, f"{what} is not closed (it has holes or loose edges), so it encloses no volume to "
                               "give a mass; close it (fill its holes), give the object as convex parts, or let it "
                               "be repaired (open: repair)")
    import trimesh

    try:  # a flat surface has no hull with a volume (trimesh fails on it deep in its repairs)
        hull = mesh.convex_hull
    except Exception:  # noqa: BLE001
        hull = None
    if hull is None or not hull.volume > 0:
        raise SceneError(path, f"{what} is flat (no two sides to it), so it encloses no volume to give a mass; give "
                               "the object as a closed mesh or as convex parts")
    hull_cm3 = float(hull.volume) * 1e6
    filled = _holes_filled(mesh)
    if filled is not None and filled[1] <= MAX_CAP_SHARE:
        solid, share, holes = filled
        how = f"{holes} hole(s) filled, the caps {100 * share:.1f}% of its surface"
    else:
        solid = _voxel_remesh(mesh)
        how = f"remeshed watertight from {REMESH_VOXELS} voxels across (its holes too large to fill)"
        if solid is None:
            solid = hull
            how = "its convex hull (the last resort: its holes too large to fill, no watertight remesh)"
    if not isinstance(solid, trimesh.Trimesh) or not solid.is_watertight or solid.volume <= 0:
        raise SceneError(path, f"{what} is not closed and could not be repaired; close it (fill its holes) or give "
                               "the object as convex parts")
    solid.metadata[REPAIRED] = (f"open: {how}; the solid holds {float(solid.volume) * 1e6:.4g} cm3, its convex hull "
                                f"{hull_cm3:.4g} cm3")
    return solid


def _holes_filled(mesh):
    """(the mesh with each hole capped by a fan about its boundary's centroid, the caps' share of the
    surface, the holes), or None where its boundary is not simple loops (a pinched or loose edge)."""
    import trimesh

    mesh = mesh.copy()
    try:
        trimesh.repair.fix_winding(mesh)
    except Exception:  # noqa: BLE001 - it walks the faces with networkx where it must: judged below instead
        pass
    boundary = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
    if len(boundary) == 0:
        return None
    following: dict[int, int] = {}
    for a, b in mesh.edges[boundary]:  # as the faces run: a cap runs each the other way
        if a in following:
            return None
        following[int(a)] = int(b)
    vertices, faces, holes = list(mesh.vertices), [], 0
    while following:
        start = next(iter(following))
        loop = [start]
        while True:
            nxt = following.pop(loop[-1], None)
            if nxt is None:
                return None  # a chain, not a loop
            if nxt == start:
                break
            loop.append(nxt)
        centre = len(vertices)
        vertices.append(np.mean(mesh.vertices[loop], axis=0))
        for a, b in zip(loop, loop[1:] + loop[:1]):
            faces.append((b, a, centre))
        holes += 1
    capped = trimesh.Trimesh(np.asarray(vertices), np.vstack([mesh.faces, np.asarray(faces)]), process=True)
    caps_area = float(capped.area - mesh.area)
    if not capped.is_watertight or not capped.is_winding_consistent:
        return None
    if capped.volume < 0:
        capped.invert()
    return capped, caps_area / float(mesh.area), holes


def _voxel_remesh(mesh):
    """The solid ``mesh``'s surface encloses, as the outer faces of its voxels (``REMESH_VOXELS``
    across; its surface's voxels, and inside them what no hole opens to the outside), edge-manifold
    (voxels touching along an edge only are joined), or None where nothing is left."""
    import trimesh

    pitch = float(np.max(mesh.extents)) / REMESH_VOXELS
    try:
        grid = mesh.voxelized(pitch).fill()
    except Exception:  # noqa: BLE001 - trimesh's voxelisation of a degenerate surface
        return None
    filled = np.pad(np.asarray(grid.matrix, bool), 1)
    for _ in range(8):  # two voxels meeting along an edge alone make a non-manifold edge: fill one corner
        added = False
        for axis in range(3):
            a, b = [ax for ax in range(3) if ax != axis]
            x = np.moveaxis(filled, (a, b), (0, 1))
            diagonal = (x[:-1, :-1] & x[1:, 1:] & ~x[1:, :-1] & ~x[:-1, 1:]) | \
                       (x[1:, :-1] & x[:-1, 1:] & ~x[:-1, :-1] & ~x[1:, 1:])
            if diagonal.any():
                x[:-1, :-1] |= diagonal
                x[1:, :-1] |= diagonal
                added = True
        if not added:
            break
    if not filled.any():
        return None
    quads = []
    for axis in range(3):
        for step in (1, -1):
            neighbour = np.roll(filled, -step, axis=axis)
            cells = np.argwhere(filled & ~neighbour)
            if not len(cells):
                continue
            quads.append(cells[:, None, :] + _face_square(axis, step)[None, :, :])
    points = np.concatenate(quads).reshape(-1, 3)
    faces = np.arange(len(points)).reshape(-1, 4)
    triangles = np.vstack([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    origin = np.asarray(grid.transform)[:3, 3] - pitch * (1 + 0.5)  # the padding, and cell centres to corners
    solid = trimesh.Trimesh(points * pitch + origin, triangles, process=True)
    if not solid.is_watertight:
        return None
    trimesh.smoothing.filter_taubin(solid, iterations=20)  # stair steps are concavities the decomposition chases
    # the surface's voxels reach up to one past it: fitted back to the mesh's own bounds (an object
    # set down on its lowest point stays there)
    low, high = solid.bounds
    own_low, own_high = mesh.bounds
    solid.vertices = own_low + (solid.vertices - low) * (own_high - own_low) / np.maximum(high - low, 1e-12)
    if solid.volume < 0:
        solid.invert()
    return solid


def _face_square(axis: int, step: int) -> np.ndarray:
    """The corners (in cell units, from the cell's lower corner) of a cell's face towards ``step``
    along ``axis``, counter-clockwise seen from outside."""
    u, v = [(axis + 1) % 3, (axis + 2) % 3]
    square = np.zeros((4, 3))
    square[:, axis] = 1.0 if step > 0 else 0.0
    for n, (du, dv) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1))):
        square[n, u], square[n, v] = du, dv
    return square if step > 0 else square[::-1]
