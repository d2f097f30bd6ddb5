"""Islands: groups of bodies that never come near each other, each simulated in a world of its own.

One world steps every body at the step its smallest body needs (``SimSettings.time_step_for``) and
runs until everything in it is at rest. A kitchen counter with a 4 mm ladle in a mug, a bowl with
balls rolling in it and a can on a box steps all of them at the ladle's 0.8 ms for the whole 2 s,
although the can on its box is settled after 0.3 s and would need 3.3 ms steps. Apart, each island
gets its own step and its own end, and the answer is the one the island would get alone.

That holds only while no island reaches another, which nothing known at the start can promise (a
mug tips its ladle onto the bowl). So the islands run side by side, each in a pybullet client of
its own, the one furthest behind in simulated time stepped on to its next read; at every read each
body's bounding box and fastest corner speed are recorded (``Footprint``), and where each body can
have been since the last read (``_stretch``) must not meet where any body of another island can
have been at the same time: their boxes first, then, where those overlap, their own shapes
(``ShapeGaps``; a long body leaning across fills a box far larger than itself). Once two islands
could have met, their rollouts are dropped and the sample is simulated as one world from the
start (``SimSettings.islands``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..scene.disjoint import DisjointSets
from .bullet import pybullet
from .world import bounding_boxes, gap_between_m, move_body


#: the most islands (pybullet clients) a sample is split into: 200 scattered boxes must not open 200
MAX_ISLANDS = 8
#: how much coarser than the island before it a group must step to be simulated apart (``by_step``)
MIN_STEP_GAIN = 2.0


@dataclass(frozen=True)
class Footprint:
    """Where an island's bodies were at one read: each body's bounding box ((n, 3) corners, m), how
    fast its fastest corner moved ((n,) m/s), and its pose (centre of mass (n, 3), xyzw (n, 4); None:
    the boxes alone are known)."""

    t_s: float
    low_m: np.ndarray
    high_m: np.ndarray
    corner_speeds_m_s: np.ndarray
    positions_m: np.ndarray | None = None
    orientations_xyzw: np.ndarray | None = None


def partition(world, velocities_m_s: np.ndarray, horizon_s: float, gap_m: float) -> list[np.ndarray]:
    """The dynamic bodies (indices in ``world.dynamic_ids`` order) in groups that nothing at the start
    brings together, largest first. Each body's bounding box is stretched down to the lowest body
    (what it stands on, or what it would fall onto) and along its initial velocity for the horizon
    (where it is thrown); a body joins every body whose stretched box comes within ``gap_m`` of its
    own. Whatever else brings two groups together later (a tipping body's reach) the footprints see.
    At most ``MAX_ISLANDS``: the smallest groups beyond share the last."""
    boxes = bounding_boxes(world)
    travel = np.asarray(velocities_m_s, float).reshape(len(boxes), 3) * horizon_s
    low, high = np.minimum(boxes[:, 0], boxes[:, 0] + travel), np.maximum(boxes[:, 1], boxes[:, 1] + travel)
    low[:, 2] = np.minimum(low[:, 2], boxes[:, 0, 2].min())
    low, high = low - gap_m / 2, high + gap_m / 2
    near = np.all((low[:, None, :] <= high[None, :, :]) & (low[None, :, :] <= high[:, None, :]), axis=2)
    sets = DisjointSets(len(boxes))
    for i, j in zip(*np.nonzero(np.triu(near, 1))):
        sets.union(int(i), int(j))
    groups = sorted((np.array(members) for members in sets.groups().values()), key=lambda g: (-len(g), g[0]))
    if len(groups) > MAX_ISLANDS:  # the smallest together: one world holds any groups, only slower
        groups = groups[:MAX_ISLANDS - 1] + [np.sort(np.concatenate(groups[MAX_ISLANDS - 1:]))]
    return groups


def by_step(groups: list[np.ndarray], steps_s: list[float]) -> list[np.ndarray]:
    """``groups`` (with the step each would take alone) put together where apart would not step
    coarser: from the finest step up, a group joins the island before it unless its own step is at
    least ``MIN_STEP_GAIN`` times that island's. Apart, islands cost clients and footprint checks and
    start again as one world where they meet (a domino chain split into one island per domino met at
    0.5 s); they pay only where a group steps coarser than the thin body that sets the whole world's
    step (a can on its box beside a 4 mm ladle)."""
    islands: list[list[np.ndarray]] = []
    finest: list[float] = []
    for step, group in sorted(zip(steps_s, groups), key=lambda pair: (pair[0], int(pair[1][0]))):
        if islands and step < MIN_STEP_GAIN * finest[-1]:
            islands[-1].append(group)
        else:
            islands.append([group])
            finest.append(step)
    return [np.sort(np.concatenate(members)) for members in islands]


@dataclass(frozen=True)
class _Stretch:
    """Where an island's bodies can have been between two reads: each within ``reach_m`` of its
    bounding boxes (``low_m``, ``high_m``), and of its shape at either read (``poses``: the two
    footprints' (positions, orientations), or None)."""

    start_s: float
    end_s: float
    low_m: np.ndarray
    high_m: np.ndarray
    reach_m: np.ndarray
    poses: tuple | None


def _stretch(a: Footprint, b: Footprint, clearance_m: float) -> _Stretch:
    """Where each body can have been between reads ``a`` and ``b``. It moves from one pose to the
    other along a path no longer than twice its fastest corner's speed times the time (the faster of
    the two reads, doubled: an impact can speed it up and slow it down again in between), and such a
    path stays within half its length (the reach) of the two boxes."""
    reach = np.maximum(a.corner_speeds_m_s, b.corner_speeds_m_s) * (b.t_s - a.t_s) + clearance_m
    poses = None if a.positions_m is None or b.positions_m is None else \
        ((a.positions_m, a.orientations_xyzw), (b.positions_m, b.orientations_xyzw))
    return _Stretch(a.t_s, b.t_s, np.minimum(a.low_m, b.low_m) - reach[:, None],
                    np.maximum(a.high_m, b.high_m) + reach[:, None], reach, poses)


class ShapeGaps:
    """The distance between two bodies' own shapes, for pairs whose boxes overlap: a long body
    leaning across (a ladle over a mug's rim) fills a bounding box far larger than itself. Every
    dynamic body of the scene in one geometry world (``build``, called on the first question) that
    is never stepped; each question moves the two to their poses. ``members``: per island, its
    bodies' indices in the scene (``partition``'s groups)."""

    def __init__(self, build, members: tuple[np.ndarray, ...]):
        self._build, self._members, self._world = build, members, None

    def distance_m(self, island_a: int, body_a: int, pose_a, island_b: int, body_b: int, pose_b,
                   up_to_m: float) -> float:
        """How far body ``body_a`` of ``island_a`` at ``pose_a`` ((positions, orientations) of its
        island) is from ``body_b`` of ``island_b`` at ``pose_b``; inf beyond ``up_to_m``."""
        if self._world is None:
            self._world = self._build()
        handles = []
        for island, body, (positions, orientations) in ((island_a, body_a, pose_a), (island_b, body_b, pose_b)):
            handle = self._world.dynamic_ids[int(self._members[island][body])]
            move_body(self._world, handle, positions[body], orientations[body])
            handles.append(handle)
        return gap_between_m(self._world, handles[0], handles[1], float(up_to_m))

    def close(self) -> None:
        if self._world is not None:
            pybullet().resetSimulation(physicsClientId=self._world.client)
            self._world = None


def _meets(island: int, stretch: _Stretch, others: list[tuple[int, _Stretch]], gaps: ShapeGaps | None) -> bool:
    """Some body in ``stretch`` meets some body of another island in a stretch that overlaps it in
    time: their boxes overlap, and (where ``gaps`` knows the shapes) so could the shapes. A body's
    path between two reads is at most twice its reach long (``_stretch``), so at any moment its
    distances from where it was at the two reads add up to that at most: two bodies can have come
    within the clearance only if their gaps at the first reads and at the last add up to at most
    twice their reaches together (the clearance is in the reaches)."""
    for other_island, other in others:
        if not (other.start_s <= stretch.end_s and stretch.start_s <= other.end_s):
            continue
        near = np.all((stretch.low_m[:, None, :] <= other.high_m[None, :, :])
                      & (other.low_m[None, :, :] <= stretch.high_m[:, None, :]), axis=2)
        for i, j in zip(*np.nonzero(near)):
            if gaps is None or stretch.poses is None or other.poses is None:
                return True
            most = 2 * (stretch.reach_m[i] + other.reach_m[j])
            first = gaps.distance_m(island, i, stretch.poses[0], other_island, j, other.poses[0], most)
            if first <= most and first + gaps.distance_m(island, i, stretch.poses[1], other_island, j,
                                                         other.poses[1], most - first) <= most:
                return True
    return False


class IslandsMet(Exception):
    """Two islands could have come near each other: the sample is simulated as one world."""


class Tracks:
    """The islands' footprints as their rollouts read them, side by side: each new stretch of one
    island is checked against every stretch the others have made so far, so that every two stretches
    that overlap in time are checked once the later of them is made, and a rollout that reaches
    another island stops there (``IslandsMet``). ``gaps``: where boxes overlap, the shapes decide."""

    def __init__(self, islands: int, horizon_s: float, clearance_m: float, gaps: ShapeGaps | None = None):
        self._horizon_s, self._clearance_m, self._gaps = horizon_s, clearance_m, gaps
        self._last: list[Footprint | None] = [None] * islands
        self._stretches: list[list[_Stretch]] = [[] for _ in range(islands)]

    def add(self, island: int, footprint: Footprint) -> None:
        """Island ``island``'s rollout read ``footprint`` (the stepper's ``on_footprint``)."""
        last, self._last[island] = self._last[island], footprint
        # collapse steps undone go back to an earlier read (config.CollapseSettings): the stretches
        # made since stay, as places the island may have been, and it goes on from there
        if last is not None and footprint.t_s >= last.t_s:
            self._check(island, _stretch(last, footprint, self._clearance_m / 2))

    def ended(self, island: int) -> None:
        """The island's rollout is over: at the horizon, or at rest (its bodies stay where they are
        until the horizon; the early end's own promise)."""
        last = self._last[island]
        still = dataclasses.replace(last, corner_speeds_m_s=np.zeros_like(last.corner_speeds_m_s))
        until = dataclasses.replace(still, t_s=max(self._horizon_s, last.t_s))
        self._check(island, _stretch(still, until, self._clearance_m / 2))

    def _check(self, island: int, stretch: _Stretch) -> None:
        others = [(i, s) for i, stretches in enumerate(self._stretches) if i != island for s in stretches]
        if _meets(island, stretch, others, self._gaps):
            raise IslandsMet(f"two islands could have met between t = {stretch.start_s:.3f} s and {stretch.end_s:.3f} s")
        self._stretches[island].append(stretch)
