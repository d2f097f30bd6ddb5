"""A z-buffered numpy rasteriser of the bodies' convex hulls into grey images.

Each face is flat-shaded by its angle to a fixed light (ambient + Lambert), over a uniform
background (the floor). The SI rendered its stimuli with OpenGL; what the likelihood needs is the
silhouettes and the shading boundaries of the blocks, which this gives at a fraction of pybullet's
software-renderer cost (``benchmarks/vision.py`` measures both on the same scenes, and
``tests/test_vision.py`` checks that their silhouettes agree with ``tinyrenderer.grey_with_pybullet``).
Pixels are sampled at their centres as CameraInfo places them (``camera.py``).

A :class:`SceneMesh` is built once per scene: the bodies' hull triangles in the scene frame's
orientation, relative to each body's position, so a state that only moves bodies is rendered by
adding positions.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ..scene import shapes
from ..scene.bodies import Scene
from .camera import PinholeCamera

BACKGROUND_GREY = 90.0
AMBIENT_GREY = 40.0
DIFFUSE_GREY = 200.0
LIGHT_DIRECTION = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


@dataclass(frozen=True)
class SceneMesh:
    """Triangles of every body (dynamic ones first, in ``scene.dynamic_objects`` order), relative to
    the body's position and already rotated; ``owner[t]`` is triangle t's body, ``grey[t]`` its shade."""

    triangles_m: np.ndarray  # (T, 3, 3)
    owner: np.ndarray        # (T,)
    grey: np.ndarray         # (T,)
    normals: np.ndarray      # (T, 3) outward
    positions_m: np.ndarray  # (bodies, 3): the bodies' positions in the scene

    @functools.cached_property
    def parts(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per body: its triangles, normals and shades (sliced once: a chain rasterises one body per
        proposal)."""
        return [(self.triangles_m[mine], self.normals[mine], self.grey[mine])
                for mine in (self.owner == b for b in range(len(self.positions_m)))]


def outward_faces(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The hulls' triangles wound counter-clockwise seen from outside (qhull's are not consistent):
    each judged from the centre of its own hull (a compound's parts are separate hulls, joined by no
    triangle; judged from the whole body's centre, faces of a non-convex body turned inwards)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(vertices),) * 2)
    _, part = connected_components(graph, directed=False)
    centres = np.array([vertices[part == p].mean(axis=0) for p in range(part.max() + 1)])
    tris = vertices[faces]
    normal = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    inward = np.einsum("ij,ij->i", normal, tris.mean(axis=1) - centres[part[faces[:, 0]]]) < 0
    return np.where(inward[:, None], faces[:, ::-1], faces)


def scene_mesh(scene: Scene) -> SceneMesh:
    bodies = [*scene.dynamic_objects, *(b for b in scene.objects if b.static)]
    triangles, owner, normals = [], [], []
    for i, body in enumerate(bodies):
        vertices, faces = shapes.hull_faces(body.shape)
        rotated = vertices @ shapes.rotation_matrix(body.orientation_xyzw).T
        tris = rotated[outward_faces(rotated, faces)]
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        triangles.append(tris)
        normals.append(n)
        owner.append(np.full(len(tris), i))
    normals_all = np.vstack(normals)
    grey = AMBIENT_GREY + DIFFUSE_GREY * np.clip(normals_all @ LIGHT_DIRECTION, 0.0, 1.0)
    return SceneMesh(triangles_m=np.vstack(triangles), owner=np.concatenate(owner), grey=grey, normals=normals_all,
                     positions_m=np.array([b.position_m for b in bodies], float))


@dataclass(frozen=True)
class Patch:
    """One body's rasterised front faces: rows v0..v1-1, columns u0..u1-1 of the image; ``depth`` is
    inf where the body does not cover a pixel."""

    v0: int
    v1: int
    u0: int
    u1: int
    depth: np.ndarray
    grey: np.ndarray


EMPTY = Patch(0, 0, 0, 0, np.zeros((0, 0)), np.zeros((0, 0)))


def body_patch(mesh: SceneMesh, camera: PinholeCamera, body: int, position_m, yaw_rad: float = 0.0) -> Patch:
    """Rasterise one body at ``position_m``, turned by ``yaw_rad`` about the vertical through it from
    its orientation in the scene: its front faces together, vectorised over its triangles (a convex
    hull's front faces do not overlap, so each pixel takes the one covering it). ``camera``: anything
    with ``project``, ``position_m``, ``width_px`` and ``height_px``."""
    tris, normals, grey = mesh.parts[body]
    if yaw_rad:
        c, s = np.cos(yaw_rad), np.sin(yaw_rad)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        tris, normals = tris @ turn.T, normals @ turn.T
    tris = tris + np.asarray(position_m, float)
    front = np.einsum("ij,ij->i", normals, tris.mean(axis=1) - np.asarray(camera.position_m, float)) < 0
    pixels, depth = camera.project(tris[front].reshape(-1, 3))
    p, z, shade = pixels.reshape(-1, 3, 2), depth.reshape(-1, 3), grey[front]
    if len(p) == 0 or (z <= 1e-6).any():
        return EMPTY
    u0, u1 = max(int(np.floor(p[..., 0].min())), 0), min(int(np.ceil(p[..., 0].max())) + 1, camera.width_px)
    v0, v1 = max(int(np.floor(p[..., 1].min())), 0), min(int(np.ceil(p[..., 1].max())) + 1, camera.height_px)
    if u0 >= u1 or v0 >= v1:
        return EMPTY
    # pixel centres at integer image coordinates (CameraInfo's convention, vision/camera.py)
    u = np.arange(u0, u1, dtype=float)[None, None, :]
    v = np.arange(v0, v1, dtype=float)[None, :, None]
    a, b, c = (p[:, i, :, None, None] for i in range(3))  # (T, 2, 1, 1)
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    area = np.where(np.abs(area) < 1e-12, np.nan, area)
    # barycentric weights from edge functions: inside where all three are >= 0
    wa = ((b[:, 0] - u) * (c[:, 1] - v) - (b[:, 1] - v) * (c[:, 0] - u)) / area
    wb = ((c[:, 0] - u) * (a[:, 1] - v) - (c[:, 1] - v) * (a[:, 0] - u)) / area
    wc = 1.0 - wa - wb
    with np.errstate(invalid="ignore", divide="ignore"):
        inside = (wa >= 0) & (wb >= 0) & (wc >= 0)
        inverse = wa / z[:, 0, None, None] + wb / z[:, 1, None, None] + wc / z[:, 2, None, None]
        depth_here = np.where(inside, 1.0 / inverse, np.inf)  # perspective-correct depth
    which = depth_here.argmin(axis=0)
    nearest = np.take_along_axis(depth_here, which[None], axis=0)[0]
    return Patch(v0, v1, u0, u1, nearest, shade[which])


def render(mesh: SceneMesh, camera: PinholeCamera, positions_m: np.ndarray | None = None) -> np.ndarray:
    """One grey image (float, 0..255) of the bodies at ``positions_m`` (default: the scene's),
    nearest body in front."""
    positions = mesh.positions_m if positions_m is None else np.asarray(positions_m, float)
    image = np.full((camera.height_px, camera.width_px), BACKGROUND_GREY)
    nearest = np.full((camera.height_px, camera.width_px), np.inf)
    for body in range(len(positions)):
        patch = body_patch(mesh, camera, body, positions[body])
        window = nearest[patch.v0:patch.v1, patch.u0:patch.u1]
        closer = patch.depth < window
        window[closer] = patch.depth[closer]
        image[patch.v0:patch.v1, patch.u0:patch.u1][closer] = patch.grey[closer]
    return image


def render_views(mesh: SceneMesh, cameras, positions_m: np.ndarray | None = None) -> np.ndarray:
    """(views, height, width) grey images."""
    return np.stack([render(mesh, camera, positions_m) for camera in cameras])
