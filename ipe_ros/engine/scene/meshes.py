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
from .convex_parts import DecompositionStopped, DecompositionTimeout, decompose_hulls
from .mesh_repair import OPEN_POLICIES, REPAIRED, closed_solid
from .mesh_cache import has_parts, mass_properties, remember_refusal, remembered_refusal, store_parts, verified_parts
from .shapes import Compound, CompoundPart, ConvexHull, MeshSource

#: what trimesh reads without extra libraries (DAE needs pycollada; glTF with external buffers reads
#: other files): name a GLB instead
MESH_FORMATS = ("obj", "stl", "ply", "glb")
MAX_MESH_BYTES = 32 * 2**20
MAX_MESH_VERTICES = 200_000
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
        return closed_solid(mesh, path, "the triangles", "repair")

    compound, _ = _compound(key, load, access, path, "a TRIANGLE_LIST")
    return compound  # a marker names no file: its compound has no source to say how an open one was closed


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
    #: how an open mesh was closed (``mesh_repair.closed_solid``), None: it was closed
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
        _decomposed(job, stop)
    except SceneError as exc:
        return exc.problem
    return None


def _decomposed(job: DecompositionJob, stop: threading.Event | None = None) -> list[np.ndarray]:
    """The job's parts, cached (where the cache can be written); a SceneError naming the job's field
    where it cannot be decomposed, remembered unless ``stop`` ended it."""
    try:
        hulls = decompose_hulls(job.vertices, job.faces, job.decomposition, job.path, job.within_s, stop)
    except DecompositionStopped:
        raise
    except SceneError as exc:
        remember_refusal(job.cache, job.key, exc.problem, job.within_s if isinstance(exc, DecompositionTimeout) else None)
        raise
    store_parts(job.cache, job.key, hulls, *job.mass_properties, repaired=job.repaired)
    return hulls


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
        cached = (_decomposed(job), *job.mass_properties, job.repaired)
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
        raise SceneError(path, f"{exc}; simplify it (fewer triangles)" if exc.too_large else str(exc)) from None


def _load(content: bytes, file: Path, scale: tuple[float, float, float], path: str, policy: str = "repair"):
    """The file's one closed mesh (a ``trimesh.Trimesh``) in metres, +z up; an open one closed by
    ``mesh_repair.closed_solid`` (``policy`` "repair"), or refused ("refuse")."""
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
    return closed_solid(mesh, path, str(file), policy)


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
