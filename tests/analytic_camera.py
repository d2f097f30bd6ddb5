"""Depth images written from the OpenCV / ROS camera_info pinhole model alone, by ray casting: the
evidence that tests and benchmarks hold the engine's camera against. Shares no code with the engine
(its quaternions, rays and box intersections are written out here), so a convention the engine gets
wrong shows up as a disagreement instead of cancelling out.

Convention (image_geometry's PinholeCameraModel): pixel (u, v) - column u, row v - has its centre at
image coordinates (u, v); its ray in the optical frame (x right, y down, z forward) is
((u - cx) / fx, (v - cy) / fy, 1).
"""

from __future__ import annotations

import math

import numpy as np

#: what a ray hit: the floor, or nothing (box i is i >= 0)
FLOOR, NOTHING = -1, -2


def optical_orientation(eye, target, roll_rad: float = 0.0) -> tuple[float, float, float, float]:
    """xyzw of an optical frame at ``eye`` looking at ``target`` (image up towards +z), turned
    ``roll_rad`` about its view axis."""
    z = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    x = np.cross(z, (0.0, 0.0, 1.0))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    x, y = c * x + s * y, -s * x + c * y
    m = np.stack([x, y, z], axis=1)  # columns: the optical axes in the scene frame
    # Shepperd's method: the branch of the largest of w, x, y, z keeps the division well away from 0
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    largest = int(np.argmax([trace, m[0, 0], m[1, 1], m[2, 2]]))
    if largest == 0:
        w = math.sqrt(1 + trace) / 2
        q = np.array([(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w), w])
    else:
        i = largest - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        r = math.sqrt(1 + m[i, i] - m[j, j] - m[k, k]) / 2
        q = np.zeros(4)
        q[i], q[j], q[k], q[3] = r, (m[j, i] + m[i, j]) / (4 * r), (m[k, i] + m[i, k]) / (4 * r), (m[k, j] - m[j, k]) / (4 * r)
    return tuple(float(v) for v in q / np.linalg.norm(q))


def pixel_rays(fx, fy, cx, cy, width, height, orientation_xyzw) -> np.ndarray:
    """(height, width, 3) scene-frame rays ((u - cx) / fx, (v - cy) / fy, 1) of every pixel."""
    x, y, z, w = orientation_xyzw
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    local = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u, float)], axis=-1)
    return local @ rotation.T


def cast(rays, eye, boxes) -> tuple[np.ndarray, np.ndarray]:
    """Depth along the optical axis of the floor z = 0 and of upright boxes ``(centre, yaw, half
    sizes)`` by ray casting (slab test), and which was hit (box index, FLOOR or NOTHING); depth NaN
    where a ray meets nothing."""
    eye = np.asarray(eye, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor_t = -eye[2] / rays[..., 2]
    depth = np.where(floor_t > 0, floor_t, np.inf)
    hit_by = np.where(np.isfinite(depth), FLOOR, NOTHING)
    for i, (centre, yaw, half) in enumerate(boxes):
        near = box_entry(rays, eye, centre, yaw, half)
        closer = near < depth
        depth, hit_by = np.where(closer, near, depth), np.where(closer, i, hit_by)
    return np.where(np.isfinite(depth), depth, np.nan), hit_by


def box_entry(rays, eye, centre, yaw, half) -> np.ndarray:
    """Where each ray enters one box (depth along the optical axis; inf: it misses). ``yaw``: its turn
    about the vertical, or (yaw, a, b): that turn, then a tilt by the rotation vector (a, b, 0)."""
    yaw, a, b = (yaw, 0.0, 0.0) if np.isscalar(yaw) else yaw
    c, s = math.cos(yaw), math.sin(yaw)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    angle = math.hypot(a, b)
    k = np.array([[0.0, 0.0, b], [0.0, 0.0, -a], [-b, a, 0.0]]) / (angle or 1.0)  # the tilt axis's cross matrix
    tilt = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)
    to_box = (tilt @ turn).T  # scene -> box frame
    origin, direction = to_box @ (np.asarray(eye, float) - np.asarray(centre, float)), rays @ to_box.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-np.asarray(half) - origin) / direction, (np.asarray(half) - origin) / direction
    near, far = np.minimum(t1, t2).max(axis=-1), np.maximum(t1, t2).min(axis=-1)
    return np.where((near <= far) & (near > 0), near, np.inf)


def analytic_depth(rays, eye, boxes) -> np.ndarray:
    return cast(rays, eye, boxes)[0]


def visible_fraction(rays, eye, boxes, hit_by, i: int) -> float:
    """Share of box i's pixels (its own silhouette) where it is the nearest thing."""
    own = np.isfinite(box_entry(rays, eye, *boxes[i]))
    return float((hit_by[own] == i).mean()) if own.any() else 0.0


def triangles_entry(rays, eye, triangles) -> np.ndarray:
    """Where each ray first meets a triangle mesh (``triangles``: (n, 3, 3) corners in the scene frame;
    depth along the optical axis; inf: it misses), by Moller-Trumbore, ray by triangle; only rays
    through the mesh's bounding sphere are cast."""
    rays = np.asarray(rays, float)
    eye = np.asarray(eye, float)
    flat = rays.reshape(-1, 3)
    corners = triangles.reshape(-1, 3)
    centre = (corners.min(axis=0) + corners.max(axis=0)) / 2
    radius = np.linalg.norm(corners - centre, axis=1).max()
    along = (centre - eye) @ flat.T / np.einsum("ij,ij->i", flat, flat)  # the ray point nearest the centre
    near = np.linalg.norm(eye + along[:, None] * flat - centre, axis=1) <= radius
    out = np.full(len(flat), np.inf)
    a, edge1, edge2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    for chunk in np.array_split(np.flatnonzero(near), max(1, int(near.sum()) // 256)):
        d = flat[chunk][:, None, :]                                  # (rays, 1, 3)
        p = np.cross(d, edge2[None])                                  # (rays, tris, 3)
        det = np.einsum("rtk,tk->rt", p, edge1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = 1.0 / det
            s = eye - a                                               # (tris, 3)
            u = np.einsum("rtk,tk->rt", p, s) * inverse
            q = np.cross(s, edge1)                                    # (tris, 3)
            v = np.einsum("rk,tk->rt", d[:, 0], q) * inverse
            t = np.einsum("tk,tk->t", q, edge2)[None] * inverse
        hit = (np.abs(det) > 1e-15) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out[chunk] = np.where(hit, t, np.inf).min(axis=1)
    return out.reshape(rays.shape[:-1])
