"""Disjoint sets (union-find) over 0..n-1: which objects belong together, by contact or by reach.

Used by the robot questions' contact groups (actions.geometry) and the paper's sub-towers
(analysis.features).
"""

from __future__ import annotations


class DisjointSets:
    def __init__(self, n: int):
        self._parent = list(range(n))

    def find(self, i: int) -> int:
        """The representative of i's set (paths halved on the way)."""
        parent = self._parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def union(self, i: int, j: int) -> None:
        self._parent[self.find(i)] = self.find(j)

    def groups(self) -> dict[int, list[int]]:
        """Each set's members in increasing order, keyed by representative, sets in order of their
        first member."""
        members: dict[int, list[int]] = {}
        for i in range(len(self._parent)):
            members.setdefault(self.find(i), []).append(i)
        return members
