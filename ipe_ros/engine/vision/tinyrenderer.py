"""Images of a scene from pybullet's software renderer (TinyRenderer): evidence made by a path that
shares nothing with our rasteriser, for tests and benchmarks.

TinyRenderer takes an OpenGL frustum and samples its pixels off the frustum's pixel centres: column c
at c pixel widths from the frustum's left edge, row r at r + 1 from its top (measured against the
analytic depth of a tilted plane: with the frustum below its depth equals a CameraInfo camera's to
4 um; with glFrustum's usual edges at -0.5 and width - 0.5, 10 mm apart at 1.5 m; tests/test_camera.py).
"""

from __future__ import annotations

import numpy as np

from ..scene import shapes
from ..scene.bodies import Floor, Scene
from .camera import PinholeCamera
from .render import outward_faces


def _frustum(camera: PinholeCamera, near_m: float) -> tuple[float, float, float, float]:
    """(left, right, bottom, top) on the near plane that make TinyRenderer sample CameraInfo's pixel centres."""
    w, h, cy = camera.width_px, camera.height_px, camera.cy + 1.0
    return (-camera.cx * near_m / camera.fx, (w - camera.cx) * near_m / camera.fx,
            -(h - cy) * near_m / camera.fy, cy * near_m / camera.fy)


def tiny_render(bodies, camera: PinholeCamera, near_m: float = 0.3,
                far_m: float = 8.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``bodies``: (vertices, faces, position, orientation xyzw) meshes. Returns the (height, width, 4)
    RGBA image, the depth in metres along the optical axis (NaN where the ray meets nothing) and the
    segmentation (the body's index in ``bodies``, -1 for none)."""
    from ..simulation.bullet import pybullet

    p = pybullet()
    client = p.connect(p.DIRECT)
    try:
        for vertices, faces, position, orientation in bodies:
            visual = p.createVisualShape(p.GEOM_MESH, vertices=np.asarray(vertices).tolist(),
                                         indices=outward_faces(np.asarray(vertices), faces).ravel().tolist(),
                                         physicsClientId=client)
            p.createMultiBody(baseMass=0, baseVisualShapeIndex=visual, basePosition=list(position),
                              baseOrientation=list(orientation), physicsClientId=client)
        axes, eye = camera.axes, np.asarray(camera.position_m, float)
        view = p.computeViewMatrix(eye.tolist(), (eye + axes[2]).tolist(), (-axes[1]).tolist(), physicsClientId=client)
        projection = p.computeProjectionMatrix(*_frustum(camera, near_m), near_m, far_m, physicsClientId=client)
        w, h = camera.width_px, camera.height_px
        _, _, rgba, buffer, segmentation = p.getCameraImage(w, h, view, projection, renderer=p.ER_TINY_RENDERER,
                                                            physicsClientId=client)
    finally:
        p.disconnect(client)
    buffer = np.reshape(np.asarray(buffer, float), (h, w))
    depth = far_m * near_m / (far_m - (far_m - near_m) * buffer)
    return (np.reshape(np.asarray(rgba, float), (h, w, 4)), np.where(buffer >= 1.0 - 1e-7, np.nan, depth),
            np.reshape(np.asarray(segmentation), (h, w)))


def _hull(body) -> tuple:
    vertices, faces = shapes.hull_faces(body.shape)
    return vertices, faces, body.position_m, body.orientation_xyzw


def _slab(centre, size) -> tuple:
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * np.asarray(size) / 2
    vertices, faces = shapes.hull_faces(shapes.ConvexHull(tuple(map(tuple, corners))))
    return vertices, faces, centre, (0.0, 0.0, 0.0, 1.0)


def grey_with_pybullet(scene: Scene, camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """(grey image 0..255, mask of the pixels the scene's bodies cover): the bodies as their hulls'
    meshes, nothing else in the world."""
    bodies = [*scene.dynamic_objects, *(b for b in scene.objects if b.static)]
    distance = float(np.linalg.norm(np.mean([b.position_m for b in bodies], axis=0) - np.asarray(camera.position_m)))
    rgba, _, segmentation = tiny_render([_hull(b) for b in bodies], camera, distance / 100, distance * 10)
    return rgba[..., :3].mean(axis=2), segmentation >= 0


def depth_with_pybullet(scene: Scene, camera: PinholeCamera, near_m: float = 0.3, far_m: float = 8.0) -> np.ndarray:
    """The depth image of ``scene``: its bodies as their hulls' meshes and its support (the floor as a
    large slab, a table as its top). Metres along the optical axis; NaN where the ray meets nothing."""
    support = scene.support
    slabs = []
    if isinstance(support, Floor):
        slabs.append(((0.0, 0.0, support.height_m - 0.05), (100.0, 100.0, 0.1)))
    else:
        slabs.append(((*support.center_xy_m, support.top_height_m - support.thickness_m / 2),
                      (*support.size_m, support.thickness_m)))
        if support.floor_z_m is not None:
            slabs.append(((0.0, 0.0, support.floor_z_m - 0.05), (100.0, 100.0, 0.1)))
    meshes = [_hull(b) for b in scene.objects] + [_slab(c, s) for c, s in slabs]
    return tiny_render(meshes, camera, near_m, far_m)[1]
