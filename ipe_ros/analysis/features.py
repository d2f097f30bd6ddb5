"""The geometric features of the paper's Table S2: what a feature-based (model-free) account could use.

Towers (Exps. 1-4, S1, S2):
    F_F(1) tower height: highest box corner above the support, m
    F_F(2) height of the centre of mass above the support, m (mass-sensitive: uses mu)
    F_F(3) critical angle of the tower, rad: the angle of its centre of mass about the nearest edge
           of the convex hull of its base (the footprints of the boxes on the support); negative when
           the centre of mass is outside the hull
    F_F(4) minimum critical angle across sub-towers (groups of boxes that touch each other but no
           other group)
    F_D(1), F_D(2) the xy directions (rad) in which those critical angles point: outward across the
           nearest edge, i.e. where the tower would tip
Tables (Exp. 5), each the ratio of the value over the ``group`` boxes (red) to that over all boxes:
    F_B(1..7) average distance from the table's centre, average xy distance from it, average height,
    average distance from the nearest edge, average xy distance from it, average (xy distance from
    the nearest edge + height), average xy distance from the nearest open (wall-free) edge;
    F_B(8..14) the same with the maximum (1-3) or minimum (4-7) instead of the average.
    Table S2 words F_B(7) as "minimum x,y distance from the nearest edge"; read literally it repeats
    F_B(5), so here it is the distance to the nearest edge without a wall, the one a block can
    actually fall over.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..engine.scene.disjoint import DisjointSets
from ..engine.scene.generators import convex_hull
from ..engine.sampling.perturb import dynamic_masses
from ..engine.scene.bodies import Body, Scene, Table, box_corners, quaternion_to_matrix, support_top_below

#: Boxes closer than this fraction of the smallest box extent count as touching.
CONTACT_TOLERANCE_FRACTION = 0.02

TOWER_FEATURES = ("F_F1_height_m", "F_F2_com_height_m", "F_F3_critical_angle_rad", "F_F4_min_subtower_angle_rad")
DIRECTION_FEATURES = ("F_D1_critical_direction_rad", "F_D2_subtower_direction_rad")
TABLE_FEATURES = tuple(f"F_B{i}" for i in range(1, 15))


@dataclass(frozen=True)
class CriticalAngle:
    """angle_rad: atan2(signed distance from the hull's nearest edge, height of the centre of mass);
    positive inside. direction_rad: the xy direction from the centre of mass out across that edge."""

    angle_rad: float
    direction_rad: float


def _corners(box: Body) -> np.ndarray:
    return box_corners(np.asarray(box.extents_m, float), np.asarray(box.position_m, float),
                       np.asarray(box.orientation_xyzw, float))


def _support_top(scene: Scene, x: float, y: float) -> float:
    top = support_top_below(scene.support, x, y)
    return scene.support.top_m if top is None else top


def footprint_xy(scene: Scene, boxes: tuple[Body, ...], tolerance_m: float) -> np.ndarray:
    """xy corners of the box faces that rest on the support (empty (0, 2) when none does)."""
    points = []
    for box in boxes:
        corners = _corners(box)
        for corner in corners:
            if corner[2] <= _support_top(scene, corner[0], corner[1]) + tolerance_m:
                points.append(corner[:2])
    return np.array(points, float).reshape(-1, 2)


def critical_angle(base_xy: np.ndarray, com_xyz: np.ndarray, base_z_m: float) -> CriticalAngle:
    """The angle of a centre of mass about the nearest edge of the convex hull of ``base_xy``."""
    hull = convex_hull(np.unique(np.round(base_xy, 12), axis=0))
    height = float(com_xyz[2] - base_z_m)
    c = np.asarray(com_xyz[:2], float)
    if len(hull) < 3:  # a point or a line of contact: no area, the centre of mass is never inside
        nearest = hull[np.argmin(np.linalg.norm(hull - c, axis=1))]
        away = c - nearest
        distance = -float(np.linalg.norm(away))
        direction = math.atan2(away[1], away[0]) if np.linalg.norm(away) > 0 else 0.0
        return CriticalAngle(angle_rad=math.atan2(distance, height), direction_rad=direction)
    best_inside, best_dir = math.inf, 0.0
    outside_distance, outside_dir = math.inf, 0.0
    inside = True
    for i in range(len(hull)):
        a, b = hull[i], hull[(i + 1) % len(hull)]
        edge = b - a
        outward = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)  # hull is counter-clockwise
        signed = float(np.dot(c - a, -outward))  # > 0 inside this edge
        if signed < 0:
            inside = False
        if signed < best_inside:
            best_inside, best_dir = signed, math.atan2(outward[1], outward[0])
        # distance to the edge segment, for a centre of mass outside the hull
        t = float(np.clip(np.dot(c - a, edge) / np.dot(edge, edge), 0.0, 1.0))
        nearest = a + t * edge
        d = float(np.linalg.norm(c - nearest))
        if d < outside_distance:
            away = c - nearest
            outside_distance = d
            outside_dir = math.atan2(away[1], away[0]) if d > 0 else math.atan2(outward[1], outward[0])
    if inside:
        return CriticalAngle(angle_rad=math.atan2(best_inside, height), direction_rad=best_dir)
    return CriticalAngle(angle_rad=math.atan2(-outside_distance, height), direction_rad=outside_dir)


def _obb_gap(a: Body, b: Body) -> float:
    """Largest separation (m) along the 15 separating axes of two boxes; <= 0 means they overlap."""
    ra, rb = quaternion_to_matrix(a.orientation_xyzw), quaternion_to_matrix(b.orientation_xyzw)
    ha, hb = np.asarray(a.extents_m) / 2, np.asarray(b.extents_m) / 2
    t = np.asarray(b.position_m, float) - np.asarray(a.position_m, float)
    axes = [ra[:, i] for i in range(3)] + [rb[:, i] for i in range(3)]
    for i in range(3):
        for j in range(3):
            cross = np.cross(ra[:, i], rb[:, j])
            if np.linalg.norm(cross) > 1e-9:
                axes.append(cross / np.linalg.norm(cross))
    gap = -math.inf
    for axis in axes:
        pa = float(np.sum(ha * np.abs(ra.T @ axis)))
        pb = float(np.sum(hb * np.abs(rb.T @ axis)))
        gap = max(gap, abs(float(np.dot(t, axis))) - pa - pb)
    return gap


def subtowers(scene: Scene) -> list[tuple[Body, ...]]:
    """Groups of dynamic boxes connected by contact (paper: disjoint, non-contacting subsets)."""
    boxes = scene.dynamic_objects
    tolerance = CONTACT_TOLERANCE_FRACTION * min(min(b.extents_m) for b in boxes)
    sets = DisjointSets(len(boxes))
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            if _obb_gap(boxes[i], boxes[j]) <= tolerance:
                sets.union(i, j)
    return [tuple(boxes[i] for i in members) for members in sets.groups().values()]


def _com(boxes: tuple[Body, ...], masses: np.ndarray) -> np.ndarray:
    positions = np.array([b.position_m for b in boxes], float)
    return (positions * masses[:, None]).sum(axis=0) / masses.sum()


def tower_features(scene: Scene, mu: float | None = None) -> dict[str, float]:
    """F_F(1..4) and F_D(1..2) of one tower; ``mu`` as in ModelConfig (None: the scene's masses)."""
    boxes = scene.dynamic_objects
    masses = dynamic_masses(scene, mu)
    mass_of = {b.name: m for b, m in zip(boxes, masses)}
    tolerance = CONTACT_TOLERANCE_FRACTION * min(min(b.extents_m) for b in boxes)
    base_z = scene.support.top_m
    top = max(float(_corners(b)[:, 2].max()) for b in boxes)
    com = _com(boxes, masses)
    whole = critical_angle(footprint_xy(scene, boxes, tolerance), com, base_z)
    worst = None
    for group in subtowers(scene):
        base = footprint_xy(scene, group, tolerance)
        if len(base) == 0:  # resting on nothing (cannot happen in a valid scene); ignore
            continue
        angle = critical_angle(base, _com(group, np.array([mass_of[b.name] for b in group])), base_z)
        if worst is None or angle.angle_rad < worst.angle_rad:
            worst = angle
    worst = worst or whole
    return {
        "F_F1_height_m": top - base_z,
        "F_F2_com_height_m": float(com[2] - base_z),
        "F_F3_critical_angle_rad": whole.angle_rad,
        "F_F4_min_subtower_angle_rad": worst.angle_rad,
        "F_D1_critical_direction_rad": whole.direction_rad,
        "F_D2_subtower_direction_rad": worst.direction_rad,
    }


def _edge_distances_xy(table: Table, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per point: xy distance to the nearest table edge, and to the nearest edge without a wall."""
    cx, cy = table.center_xy_m
    hx, hy = table.size_m[0] / 2, table.size_m[1] / 2
    d = {"+x": cx + hx - xy[:, 0], "-x": xy[:, 0] - (cx - hx), "+y": cy + hy - xy[:, 1], "-y": xy[:, 1] - (cy - hy)}
    walled = set()
    for wall in table.obstacles:
        wx, wy = wall.position_m[0] - cx, wall.position_m[1] - cy
        # a wall lies along the edge it is nearest to
        edge = min(d, key=lambda e: {"+x": abs(hx - wx), "-x": abs(hx + wx), "+y": abs(hy - wy),
                                     "-y": abs(hy + wy)}[e])
        walled.add(edge)
    all_edges = np.min(np.stack(list(d.values())), axis=0)
    open_edges = [d[e] for e in d if e not in walled]
    nearest_open = np.min(np.stack(open_edges), axis=0) if open_edges else np.full(len(xy), np.inf)
    return all_edges, nearest_open


def _table_quantities(scene: Scene, boxes: tuple[Body, ...]) -> dict[int, np.ndarray]:
    table = scene.support
    assert isinstance(table, Table)  # checked by table_features
    pos = np.array([b.position_m for b in boxes], float)
    centre = np.array([*table.center_xy_m, table.top_height_m])
    height = pos[:, 2] - table.top_height_m
    xy_edge, xy_open = _edge_distances_xy(table, pos[:, :2])
    return {
        1: np.linalg.norm(pos - centre, axis=1),
        2: np.linalg.norm(pos[:, :2] - centre[:2], axis=1),
        3: height,
        4: np.hypot(xy_edge, height),  # to the nearest edge line at the table top
        5: xy_edge,
        6: xy_edge + height,
        7: xy_open,
    }


def table_features(scene: Scene, group: str = "red") -> dict[str, float]:
    """F_B(1..14) of one Exp. 5 scene: value over ``group`` boxes / value over all boxes."""
    if not isinstance(scene.support, Table):
        raise ValueError(f"scene {scene.name!r}: table features need a Table support")
    members = tuple(b for b in scene.dynamic_objects if b.group == group)
    if not members:
        raise ValueError(f"scene {scene.name!r}: no box in group {group!r}")
    sub, every = _table_quantities(scene, members), _table_quantities(scene, scene.dynamic_objects)
    out = {}
    for i in range(1, 8):
        out[f"F_B{i}"] = float(np.mean(sub[i]) / np.mean(every[i]))
        reduce = np.max if i <= 3 else np.min
        whole = reduce(every[i])
        out[f"F_B{i + 7}"] = float(reduce(sub[i]) / whole) if whole != 0 and np.isfinite(whole) else math.nan
    return out


def feature_matrix(rows: list[dict[str, float]], names: tuple[str, ...]) -> np.ndarray:
    return np.array([[row[n] for n in names] for row in rows], float)
