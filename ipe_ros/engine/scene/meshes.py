"""Objects from mesh files: read with trimesh, decomposed into convex parts with CoACD, cached on disk.

A scene names a mesh as a shape ``{"type": "mesh", "uri": ..., "scale": ...}``; reading the scene
turns it into a compound of convex parts in the mesh's own frame (metres, +z up), so everything
downstream (validation, the physics, markers, recordings) sees a shape it already knows. The
decomposition is the slow part (seconds for a mug): it is cached under ``cache_dir`` by the file's
content, the scale and the decomposition's settings, so a mesh is decomposed once per machine.

Where meshes may come from is the caller's to say (``MeshAccess``): the command line reads them
beside the scene file and under folders it is given; the node only under the folders its operator
configured (a scene arrives over the network, and must not make the node read arbitrary files).
Files are sized before they are read, vertices and parts are bounded, and a mesh that does not
enclose a volume is refused with the fix.

A reader that must answer at once (the node's executor) sets ``MeshAccess.defer``: a mesh not yet
decomposed then raises :class:`NotYetDecomposed` carrying the job (``decompose``), which the
caller runs elsewhere and then reads the input again. A decomposition that failed or ran out of
time is remembered (``mesh_cache.remembered_refusal``), so asking again is refused at once.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import os
import stat
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SceneError, shown
from . import limits
from ..safe_files import UnreadableFile, is_folder, read_file_bounded
from .mesh_cache import has_parts, mass_properties, remember_refusal, remembered_refusal, store_parts, verified_parts
from .shapes import Compound, CompoundPart, ConvexHull, MeshSource

#: what trimesh reads without extra libraries (DAE needs pycollada; glTF with external buffers reads
#: other files): name a GLB instead
MESH_FORMATS = ("obj", "stl", "ply", "glb")
MAX_MESH_BYTES = 32 * 2**20
MAX_MESH_VERTICES = 200_000
#: every part's hull is kept to this many vertices (CoACD's max_ch_vertex), so that a mesh's parts
#: stay within the compound limits (limits.MAX_COMPOUND_VERTICES)
MAX_PART_VERTICES = 64
#: bump when the cached decomposition's meaning changes (4: hulls decimated to MAX_PART_VERTICES,
#: and the parts together thinned to limits.MAX_COMPOUND_VERTICES; 5: within the mesh's bounds)
_CACHE_VERSION = 5


@dataclass(frozen=True)
class Decomposition:
    """CoACD's settings: ``threshold`` the concavity a part may keep (a fraction of the mesh's size;
    smaller: more, tighter parts), ``max_parts`` the most parts (-1: as many as the threshold needs,
    within limits.MAX_COMPOUND_PARTS)."""

    threshold: float = 0.05
    max_parts: int = 32
    seed: int = 0


@dataclass(frozen=True)
class MeshAccess:
    """Where a scene's meshes may be read from: files under one of ``roots`` (after following
    links); relative paths from ``base``; ``package://NAME/...`` through the ROS package index when
    it is there, else ``roots/NAME/...``. Decompositions are cached in ``cache_dir`` (default:
    $IPE_CACHE_DIR, else ~/.cache/ipe_ros)."""

    roots: tuple[Path, ...]
    base: Path | None = None
    cache_dir: Path | None = None
    decomposition: Decomposition = field(default_factory=Decomposition)
    #: the most seconds a mesh's decomposition (not yet cached) may take, None: no limit. With a
    #: limit it runs in a process of its own (spawned), ended when over: CoACD has no time limit of
    #: its own, and a large mesh can take minutes, which the node must not spend on one scene
    decompose_within_s: float | None = None
    #: a mesh not yet decomposed raises NotYetDecomposed (its job) instead of being decomposed here
    defer: bool = False

    @property
    def reads_files(self) -> bool:
        return bool(self.roots) or self.base is not None

    def cache(self) -> Path:
        if self.cache_dir is not None:
            return Path(self.cache_dir)
        return Path(os.environ.get("IPE_CACHE_DIR") or Path.home() / ".cache" / "ipe_ros") / "convex_parts"


def mesh_shape(data: dict, path: str, access: MeshAccess | None, uri_field: str | None = None) -> Compound:
    """The compound of convex parts of the mesh shape ``data`` (``uri``, ``scale``), or a SceneError
    naming ``path`` (the URI as ``uri_field``, default ``<path>.uri``) and the fix."""
    where = uri_field or f"{path}.uri"
    if access is None or not access.reads_files:
        raise SceneError(where, "mesh shapes are read from files, which this input may not reach; give the object "
                                "as convex parts (type compound), or send the scene where meshes are allowed (ipe "
                                "predict reads them beside the scene file; the node under its mesh_roots)")
    uri = data["uri"]
    if not isinstance(uri, str) or not uri.strip():
        raise SceneError(where, f"must be a file path, file:// or package:// URI, got {shown(uri)}")
    if any(ord(c) < 32 for c in uri):  # a NUL ends a path in the OS: refused here, not deep in os.path
        raise SceneError(where, f"{shown(uri)} holds a control character (a NUL, a newline); give the path as it is")
    scale = _scale(data.get("scale", 1.0), f"{path}.scale")
    policy = data.get("open", "repair")
    if policy not in OPEN_POLICIES:
        raise SceneError(f"{path}.open", f"must be one of {', '.join(OPEN_POLICIES)} (what to do with a mesh that is "
                                         f"not closed), got {shown(policy)}")
    file = _resolve(uri, where, access)
    content = _read_bounded(file, where)
    key = hashlib.sha256(b"%d|%s|%r|%r" % (_CACHE_VERSION, file.suffix.lower().encode(), scale,
                                           access.decomposition) + (b"|refuse" if policy == "refuse" else b"")
                         + content).hexdigest()
    compound, repaired = _compound(key, lambda: _load(content, file, scale, where, policy), access, where, file.name)
    # a package:// URI as given (it resolves on any machine with the package); a path as the file read
    shown_uri = uri.strip() if uri.strip().startswith("package://") else FILE_URI + str(file)
    return dataclasses.replace(compound, source=MeshSource(shown_uri, scale, read_from=file, repaired=repaired))


#: a file:// URI is this and the absolute path, as ROS writes it (no percent-escapes): read and
#: written by the one rule, so that a source read back names the same file
FILE_URI = "file://"


def source_triangles(source: MeshSource) -> tuple[np.ndarray, np.ndarray] | None:
    """The mesh a compound was read from, as drawn (vertices in metres in the object frame, +z up, and
    triangles), for recordings: read again from the file this module read it from under the
    reader's own roots (``MeshSource.read_from``), never from a URI a scene merely names; None
    where there is none (a source given as data, a file moved or changed into something
    unreadable): draw the parts then."""
    if source.read_from is None:
        return None
    return _triangles_of(Path(source.read_from), tuple(source.scale))


def readable_source(uri: str, access: MeshAccess | None) -> Path | None:
    """The file a compound's ``source`` URI names where ``access`` would read it as a mesh (inside its
    roots, a known format), else None: drawn from its parts."""
    if access is None or not access.reads_files or any(ord(c) < 32 for c in uri):
        return None
    try:
        return _resolve(uri.strip(), "source.uri", access)
    except (SceneError, OSError, ValueError):
        return None


@functools.lru_cache(maxsize=32)
def _triangles_of(file: Path, scale: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray] | None:
    try:
        mesh = _load(_read_bounded(file, "source.uri"), file, scale, "source.uri")
    except (SceneError, OSError):
        return None
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def triangles_shape(points_m: np.ndarray, path: str, access: MeshAccess) -> Compound:
    """The compound of convex parts of the closed surface whose triangles are ``points_m`` taken three
    at a time (a TRIANGLE_LIST marker's points, scaled; vertices shared by position), or a
    SceneError naming ``path`` (decomposed and cached as a mesh file is)."""
    import trimesh

    points = np.asarray(points_m, float).reshape(-1, 3)
    if len(points) < 12 or len(points) % 3:
        raise SceneError(path, f"a closed surface needs triangles, 3 points each (at least 4 triangles), got "
                               f"{len(points)} points")
    if len(points) > 3 * MAX_MESH_VERTICES:
        raise SceneError(path, f"{len(points)} points, more than the {3 * MAX_MESH_VERTICES} read; simplify it")
    key = hashlib.sha256(b"%d|triangles|%r" % (_CACHE_VERSION, access.decomposition) + points.tobytes()).hexdigest()

    def load():
        mesh = trimesh.Trimesh(points, np.arange(len(points)).reshape(-1, 3), process=True)
        return _closed(mesh, path, "the triangles", "repair")

    compound, repaired = _compound(key, load, access, path, "a TRIANGLE_LIST")
    return compound  # a marker names no file: how it was closed is in the decomposition's log only


class NotYetDecomposed(Exception):
    """A mesh not yet in the cache, read where it may not be decomposed now (``MeshAccess.defer``):
    run ``job`` (``decompose``) elsewhere, then read the input again."""

    def __init__(self, job: "DecompositionJob"):
        super().__init__(f"{job.path}: {job.what} is not decomposed into convex parts yet")
        self.job = job


@dataclass(frozen=True, eq=False)
class DecompositionJob:
    """One mesh's decomposition, taken out of the reader: the cache ``key`` it is stored under, the
    input's field ``path``, ``what`` it is (a file name), its solid (``vertices``, ``faces``) and
    mass properties, the settings and the time it may take."""

    key: str
    path: str
    what: str
    vertices: np.ndarray
    faces: np.ndarray
    mass_properties: tuple
    cache: Path
    decomposition: Decomposition
    within_s: float | None
    #: how an open mesh was closed (``_closed``), None: it was closed
    repaired: str | None = None

    @property
    def triangles(self) -> int:
        return len(self.faces)


def decompose(job: DecompositionJob, stop: threading.Event | None = None) -> str | None:
    """Run ``job`` and cache its parts, or remember why not: None when the parts are cached, else the
    refusal (also what reading the input again will say). ``stop`` set: ended without a verdict
    (the refusal says so, nothing is remembered)."""
    refused = remembered_refusal(job.cache, job.key, job.within_s)
    if refused is not None or has_parts(job.cache, job.key):  # done meanwhile (another reader's job)
        return refused
    try:
        hulls = _decompose(job.vertices, job.faces, job.decomposition, job.path, job.within_s, stop)
    except DecompositionStopped as exc:
        return exc.problem
    except SceneError as exc:
        remember_refusal(job.cache, job.key, exc.problem, job.within_s if isinstance(exc, DecompositionTimeout) else None)
        return exc.problem
    store_parts(job.cache, job.key, hulls, *job.mass_properties, repaired=job.repaired)
    return None


def _compound(key: str, load, access: MeshAccess, path: str, what: str) -> tuple[Compound, str | None]:
    """The mesh's compound from the cache under ``key`` (``mesh_cache.verified_parts``), else refused
    as before (``remembered_refusal``), else decomposed from ``load()`` and cached (or handed back
    as a job: ``access.defer``); the mesh loaded once either way. With how it was closed, if open."""
    load = functools.cache(load)
    cached = verified_parts(access.cache(), key, load)
    if cached is None:
        refused = remembered_refusal(access.cache(), key, access.decompose_within_s)
        if refused is not None:
            raise SceneError(path, refused)
        mesh = load()
        job = DecompositionJob(key, path, what, np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64),
                               mass_properties(mesh), access.cache(), access.decomposition, access.decompose_within_s,
                               mesh.metadata.get(REPAIRED))
        if access.defer:
            raise NotYetDecomposed(job)
        refused = decompose(job)
        if refused is not None:
            raise SceneError(path, refused)
        cached = verified_parts(access.cache(), key, load)
        if cached is None:  # the cache could not be written (a read-only home): decomposed for this answer
            cached = (_decompose(job.vertices, job.faces, job.decomposition, path, job.within_s),
                      *job.mass_properties, job.repaired)
    parts, volume, centre, inertia, repaired = cached
    return Compound(tuple(CompoundPart(ConvexHull(tuple(tuple(map(float, v)) for v in part))) for part in parts),
                    volume_m3=volume, centre_of_mass_m=centre, inertia_diagonal_per_kg_m2=inertia), repaired


def _scale(value: Any, path: str) -> tuple[float, float, float]:
    values = [value] * 3 if isinstance(value, (int, float)) and not isinstance(value, bool) else value
    if not (isinstance(values, list | tuple) and len(values) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0
                    for v in values)):
        raise SceneError(path, f"must be a positive number or three ([sx, sy, sz]; metres per file unit), got "
                               f"{shown(value)}")
    return tuple(float(v) for v in values)  # type: ignore[return-value]


def _resolve(uri: str, path: str, access: MeshAccess) -> Path:
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        candidate = _package_file(package, rest, access)
        if candidate is None:
            raise SceneError(path, f"package {shown(package)} is not in the ROS package index nor under "
                                   f"{', '.join(map(str, access.roots)) or 'any mesh root'}; source its workspace or "
                                   "add its parent folder to the mesh roots")
    elif uri.startswith(FILE_URI):
        candidate = Path(uri[len(FILE_URI):])
    elif "://" in uri:
        raise SceneError(path, f"{shown(uri)}: only file paths, file:// and package:// URIs are read")
    else:
        candidate = Path(uri) if Path(uri).is_absolute() or access.base is None else access.base / uri
    real = Path(os.path.realpath(candidate))
    if not any(real.is_relative_to(os.path.realpath(root)) for root in access.roots):
        raise SceneError(path, f"{shown(uri)} is outside the folders meshes may be read from "
                               f"({', '.join(map(str, access.roots)) or 'none configured'})")
    suffix = real.suffix.lower().lstrip(".")
    if suffix not in MESH_FORMATS:
        raise SceneError(path, f"{shown(uri)}: unknown mesh format {shown(suffix)}; give one of "
                               f"{', '.join(MESH_FORMATS)} (export DAE or glTF as GLB)")
    return real


def _package_file(package: str, rest: str, access: MeshAccess) -> Path | None:
    if not package or ".." in Path(rest).parts:
        return None
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            return Path(get_package_share_directory(package)) / rest
        except (PackageNotFoundError, OSError, ValueError):  # OSError: no workspace sourced (AMENT_PREFIX_PATH)
            pass
    except ImportError:  # no ROS here: the roots are the search path
        pass
    return next((Path(root) / package / rest for root in access.roots if is_folder(Path(root) / package)), None)



def _read_bounded(file: Path, path: str) -> bytes:
    try:
        return read_file_bounded(file, MAX_MESH_BYTES, "a mesh")
    except UnreadableFile as exc:
        raise SceneError(path, f"{exc}; simplify it (fewer triangles)" if "bytes" in str(exc) else str(exc)) from None


def _load(content: bytes, file: Path, scale: tuple[float, float, float], path: str, policy: str = "repair"):
    """The file's one closed mesh (a ``trimesh.Trimesh``) in metres, +z up; an open one closed by
    ``_closed`` (``policy`` "repair"), or refused ("refuse")."""
    import io

    import trimesh

    kind = file.suffix.lower().lstrip(".")
    try:
        scene = trimesh.load_scene(io.BytesIO(content), file_type=kind, process=True)
        # counted before the copies are laid out, from the graph alone (a node's transform walks its
        # chain of parents: a GLB of 100 000 nested nodes took 58 s for one): a GLB places one mesh at
        # any number of nodes, so a file of a few MB can expand to millions of vertices
        depth = _deepest(scene.graph.transforms.parents)
        placed = {name: len(nodes) for name, nodes in scene.graph.geometry_nodes.items() if name in scene.geometry}
        expanded = sum(len(scene.geometry[name].vertices) * count for name, count in placed.items())
        mesh = scene.to_mesh() if expanded <= MAX_MESH_VERTICES and depth <= MAX_NODE_DEPTH else None
    except Exception as exc:  # trimesh raises what its parsers raise
        raise SceneError(path, f"{file}: not a readable {kind.upper()} mesh ({type(exc).__name__}: "
                               f"{str(exc)[:120]})") from None
    if depth > MAX_NODE_DEPTH:
        raise SceneError(path, f"{file}: its nodes are nested {depth} deep, more than the {MAX_NODE_DEPTH} read; "
                               "flatten its node hierarchy (export it with the transforms applied)")
    if mesh is None:
        raise SceneError(path, f"{file}: {expanded} vertices once its {sum(placed.values())} placed parts are laid "
                               f"out, more than the {MAX_MESH_VERTICES} read; simplify it")
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise SceneError(path, f"{file}: holds no triangles")
    if len(mesh.vertices) > MAX_MESH_VERTICES:
        raise SceneError(path, f"{file}: {len(mesh.vertices)} vertices, more than the {MAX_MESH_VERTICES} read; "
                               "simplify it")
    with np.errstate(over="ignore", invalid="ignore"):  # judged before anything is scaled (no overflow warnings)
        size_m = float(np.max(mesh.extents * np.asarray(scale)))
    if not limits.MIN_SIZE_M <= size_m <= limits.MAX_SIZE_M:
        raise SceneError(path, f"{file}: {size_m:.3g} m across at scale {list(scale)}; an object is "
                               f"{limits.MIN_SIZE_M:g}-{limits.MAX_SIZE_M:g} m: give scale in metres per file unit "
                               "(0.001 for millimetres)")
    # OBJ files split a vertex where texture (UV) seams or normals meet: merged by position only, a
    # closed surface reads as closed
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    transform = np.diag([*scale, 1.0])
    if kind == "glb":  # glTF's up is +y: turn it to +z (x stays), then scale along the object's axes
        transform = transform @ np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])
    mesh.apply_transform(transform)
    if not np.all(np.isfinite(mesh.vertices)):
        raise SceneError(path, f"{file}: has vertices that are not finite numbers")
    return _closed(mesh, path, str(file), policy)


#: a scene graph's nodes nested deeper than this are refused before any transform is resolved (an
#: object model's hierarchy is a few levels; trimesh resolves a node's transform along its whole chain)
MAX_NODE_DEPTH = 256


def _deepest(parents: dict) -> int:
    """The longest chain of parents in a scene graph (child -> parent), in linear time."""
    depth: dict = {}
    for node in parents:
        chain = []
        while node in parents and node not in depth:
            chain.append(node)
            node = parents[node]
            if len(chain) > len(parents):  # a cycle: no tree
                return len(parents) + 1
        known = depth.get(node, 0)
        for n in reversed(chain):
            known += 1
            depth[n] = known
    return max(depth.values(), default=0)


#: what to do with a mesh that is not closed (a mesh shape's ``open``)
OPEN_POLICIES = ("repair", "refuse")
#: trimesh metadata key: how an open mesh was closed
REPAIRED = "ipe_repaired"
#: holes are filled (rung 1) where their caps add at most this share of the surface: small holes
MAX_CAP_SHARE = 0.1
#: the watertight remesh's voxels across the mesh's largest extent (rung 2): at 24 a mug's remesh
#: decomposes in ~12 s here (48: 70 s; its stair steps smoothed or not), its thin walls a voxel or
#: two thick (the open mug of tests/test_meshes.py holds 1.6x its walls' volume: the answer says it)
REMESH_VOXELS = 24


def _closed(mesh, path: str, what: str, policy: str):
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
    vertices, faces, caps_area, holes = list(mesh.vertices), [], 0.0, 0
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


def _coacd_hulls(vertices: np.ndarray, faces: np.ndarray, settings: Decomposition) -> list[np.ndarray]:
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


def _coacd_in_process(connection, vertices: np.ndarray, faces: np.ndarray, settings: Decomposition) -> None:
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


def _coacd_within(vertices: np.ndarray, faces: np.ndarray, settings: Decomposition, within_s: float,
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


def _decompose(vertices: np.ndarray, faces: np.ndarray, settings: Decomposition, path: str,
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
