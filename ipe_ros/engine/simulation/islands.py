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
have been at the same time. Once two islands could have met, their rollouts are dropped and the
sample is simulated as one world from the start (``SimSettings.islands``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene.disjoint import DisjointSets
from .world import bounding_boxes


#: the most islands (pybullet clients) a sample is split into: 200 scattered boxes must not open 200
MAX_ISLANDS = 8
#: how much coarser than the island before it a group must step to be simulated apart (``by_step``)
MIN_STEP_GAIN = 2.0


@dataclass(frozen=True)
class Footprint:
    """Where an island's bodies were at one read: each body's bounding box ((n, 3) corners, m), and
    how fast its fastest corner moved ((n,) m/s)."""

    t_s: float
    low_m: np.ndarray
    high_m: np.ndarray
    corner_speeds_m_s: np.ndarray


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


def _stretch(a: Footprint, b: Footprint, clearance_m: float) -> tuple[float, float, np.ndarray, np.ndarray]:
    """(start, end, low (n, 3), high (n, 3)): where each body can have been between reads ``a`` and
    ``b``. It moves from one box to the other along a path no longer than its fastest corner's speed
    times the time (the faster of the two reads, doubled: an impact can speed it up and slow it down
    again in between), and such a path stays within half its length of the two boxes."""
    reach = np.maximum(a.corner_speeds_m_s, b.corner_speeds_m_s) * (b.t_s - a.t_s) + clearance_m
    return (a.t_s, b.t_s, np.minimum(a.low_m, b.low_m) - reach[:, None],
            np.maximum(a.high_m, b.high_m) + reach[:, None])


def _meets(stretch: tuple[float, float, np.ndarray, np.ndarray], others: list) -> bool:
    """Some body in ``stretch`` meets some body of another island in a stretch that overlaps it in time."""
    start, end, low, high = stretch
    for other_start, other_end, other_low, other_high in others:
        if other_start <= end and start <= other_end and np.any(np.all(
                (low[:, None, :] <= other_high[None, :, :]) & (other_low[None, :, :] <= high[:, None, :]), axis=2)):
            return True
    return False


class IslandsMet(Exception):
    """Two islands could have come near each other: the sample is simulated as one world."""


class Tracks:
    """The islands' footprints as their rollouts read them, side by side: each new stretch of one
    island is checked against every stretch the others have made so far, so that every two stretches
    that overlap in time are checked once the later of them is made, and a rollout that reaches
    another island stops there (``IslandsMet``)."""

    def __init__(self, islands: int, horizon_s: float, clearance_m: float):
        self._horizon_s, self._clearance_m = horizon_s, clearance_m
        self._last: list[Footprint | None] = [None] * islands
        self._stretches: list[list] = [[] for _ in range(islands)]

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
        reach = self._clearance_m / 2
        self._check(island, (last.t_s, max(self._horizon_s, last.t_s), last.low_m - reach, last.high_m + reach))

    def _check(self, island: int, stretch) -> None:
        others = [s for i, stretches in enumerate(self._stretches) if i != island for s in stretches]
        if _meets(stretch, others):
            raise IslandsMet(f"two islands could have met between t = {stretch[0]:.3f} s and {stretch[1]:.3f} s")
        self._stretches[island].append(stretch)
