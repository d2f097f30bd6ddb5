"""Depth by casting each pixel's ray at the bodies' convex parts, many poses of one body at once.

A convex part is the intersection of its faces' half-spaces ``n . x <= c``: a ray ``o + t r`` enters
it at the largest ``t`` of the faces it crosses inwards and leaves at the smallest of those it
crosses outwards, and hits it where it enters before it leaves. That is the depth at the pixel
centre, exactly (the rasteriser in ``render.py`` interpolates the same planes over triangles), and
it is a few matrix products for every candidate pose of a body together: the depth chain scores a
batch of proposals for one object in one pass (``depth_model.DepthModel.log_likelihoods``).

Poses follow ``render.body_patch``: a body's frame origin at ``position_m``, turned by ``yaw_rad``
about the vertical through it from its orientation in the scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull as QHull

from ..scene import shapes
from ..scene.bodies import Body


@dataclass(frozen=True)
class ConvexBody:
    """One body's convex parts as half-spaces in the scene's orientation, relative to its position:
    inside part p where ``normals[f] . x <= offsets_m[f]`` for its faces ``f`` in
    ``starts[p]:starts[p + 1]``."""

    normals: np.ndarray     # (faces, 3) outward unit normals
    offsets_m: np.ndarray   # (faces,)
    starts: np.ndarray      # (parts,) each part's first face
    vertices_m: np.ndarray  # (n, 3) every part's corners (where the body can show in an image)
    centres_m: np.ndarray   # (parts, 3) each part's bounding sphere: its centre,
    radii_m: np.ndarray     # (parts,) and its radius


def convex_body(body: Body) -> ConvexBody:
    rotation = shapes.rotation_matrix(body.orientation_xyzw)
    parts = body.shape.parts if isinstance(body.shape, shapes.Compound) else (shapes.CompoundPart(body.shape),)
    normals, offsets, starts, vertices = [], [], [], []
    for part in parts:
        points = (shapes.surface_points(part.shape) @ shapes.rotation_matrix(part.orientation_xyzw).T
                  + np.asarray(part.position_m)) @ rotation.T
        # qhull gives one equation per triangle: coplanar triangles repeat a face's plane
        planes = np.unique(np.round(QHull(points).equations, 12), axis=0)
        starts.append(sum(len(n) for n in normals))
        normals.append(planes[:, :3] / np.linalg.norm(planes[:, :3], axis=1, keepdims=True))
        offsets.append(-planes[:, 3] / np.linalg.norm(planes[:, :3], axis=1))
        vertices.append(points)
    centres = np.array([(p.min(axis=0) + p.max(axis=0)) / 2 for p in vertices])
    radii = np.array([np.linalg.norm(p - c, axis=1).max() for p, c in zip(vertices, centres)])
    return ConvexBody(np.vstack(normals), np.concatenate(offsets), np.array(starts), np.vstack(vertices), centres,
                      radii)


def turns(yaws_rad: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations about the vertical."""
    c, s = np.cos(yaws_rad), np.sin(yaws_rad)
    out = np.zeros((len(c), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def tilts(tilts_rad: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations by the rotation vectors (a, b, 0): a tilt about the scene's x and y axes."""
    vectors = np.zeros((len(tilts_rad), 3))
    vectors[:, :2] = tilts_rad
    angle = np.linalg.norm(vectors, axis=1)
    axis = vectors / np.where(angle > 0, angle, 1.0)[:, None]
    cross = np.zeros((len(vectors), 3, 3))
    cross[:, 0, 2], cross[:, 1, 2] = axis[:, 1], -axis[:, 0]
    cross[:, 2, 0], cross[:, 2, 1] = -axis[:, 1], axis[:, 0]
    sin, cos = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + sin * cross + (1 - cos) * (cross @ cross)  # Rodrigues


def pose_rotations(yaws_rad: np.ndarray, tilts_rad: np.ndarray | None = None) -> np.ndarray:
    """(n, 3, 3): a turn about the vertical by the yaw, then the tilt (``tilts``), both about the
    body's frame origin, from its orientation in the scene."""
    turned = turns(np.asarray(yaws_rad, float))
    # no tilt is the identity, exactly: most objects' tilts are not estimated, and the chain asks often
    return turned if tilts_rad is None or not np.any(tilts_rad) else tilts(np.asarray(tilts_rad, float)) @ turned


def pixel_box(body: ConvexBody, camera, positions_m: np.ndarray, rotations: np.ndarray) -> tuple[float, ...] | None:
    """(u0, u1, v0, v1): image coordinates that the body can cover in any of these poses; None when a
    corner is at or behind the camera's plane (then every pixel may be covered)."""
    corners = (body.vertices_m @ rotations.transpose(0, 2, 1) + positions_m[:, None, :]).reshape(-1, 3)
    local = (corners - camera.position_m) @ camera.axes.T
    depth = local[:, 2]
    if depth.min() <= 1e-6:
        return None
    u = camera.fx * local[:, 0] / depth
    v = camera.fy * local[:, 1] / depth
    return u.min() + camera.cx, u.max() + camera.cx, v.min() + camera.cy, v.max() + camera.cy


def ray_depths(body: ConvexBody, origin_m: np.ndarray, rays: np.ndarray, positions_m: np.ndarray,
               rotations: np.ndarray) -> np.ndarray:
    """(poses, pixels) depth along the optical axis at which each ray (``rays``: (pixels, 3), optical
    component 1, from ``origin_m``) first meets the body in each pose; inf where it misses. A body of
    many parts (a mesh) casts each part only at the rays through its bounding sphere in some pose:
    a mug's 27 parts have ~3,000 faces, and every face at every pixel took seconds a batch."""
    if len(body.starts) == 1:
        return _part_depths(body.normals, body.offsets_m, origin_m, rays, positions_m, rotations)
    out = np.full((len(positions_m), len(rays)), np.inf)
    unit = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    centres = positions_m[:, None, :] + body.centres_m @ rotations.transpose(0, 2, 1) - origin_m  # (poses, parts, 3)
    ends = [*body.starts[1:], len(body.normals)]
    for part, (start, end) in enumerate(zip(body.starts, ends)):
        along = centres[:, part] @ unit.T                                          # (poses, pixels)
        off_axis = np.einsum("pk,pk->p", centres[:, part], centres[:, part])[:, None] - along ** 2
        near = np.flatnonzero(((off_axis <= body.radii_m[part] ** 2) & (along > -body.radii_m[part])).any(axis=0))
        if len(near):
            depths = _part_depths(body.normals[start:end], body.offsets_m[start:end], origin_m, rays[near],
                                  positions_m, rotations)
            out[:, near] = np.minimum(out[:, near], depths)
    return out


def _part_depths(normals: np.ndarray, offsets_m: np.ndarray, origin_m: np.ndarray, rays: np.ndarray,
                 positions_m: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """``ray_depths`` of one convex part (its faces' ``normals`` and ``offsets_m``)."""
    normals = normals @ rotations.transpose(0, 2, 1)                          # (poses, faces, 3)
    reach = offsets_m + (normals @ (positions_m - origin_m)[:, :, None])[:, :, 0]  # (poses, faces)
    along = normals @ rays.T                                                   # (poses, faces, pixels)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = reach[:, :, None] / along
    # a ray parallel to a face is inside it everywhere or nowhere
    parallel_outside = (along == 0) & (reach[:, :, None] < 0)
    enters = np.where(along < 0, t, np.where(parallel_outside, np.inf, -np.inf))
    leaves = np.where(along > 0, t, np.inf)
    enter, leave = enters.max(axis=1), leaves.min(axis=1)
    return np.where((enter <= leave) & (enter > 0), enter, np.inf)
