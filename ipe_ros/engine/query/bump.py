"""``bump``: what falls off a bumped table (paper Exp. 5): per group, the expected fraction of its
objects that end below the table top, and its parameter ``group``'s share of those that fell off."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import predicates
from ..errors import ConfigError
from ..scene.bodies import Table
from .base import Query, Reading, Samples


@dataclass(frozen=True)
class BumpParameters:
    group: str = field(default="red", metadata={
        "meaning": "the group whose share of what fell off bump_ratio reports (paper: red / (red + yellow))"})

    def __post_init__(self) -> None:
        if not isinstance(self.group, str) or not self.group.strip():
            raise ConfigError("bump.group", f"must be a group name, got {self.group!r}")


class Bump(Query):
    name = "bump"
    Parameters = BumpParameters
    fields = ("fell_off_fraction_by_group", "bump_group", "bump_ratio", "bump_rollouts")
    summary = "what falls off a bumped table, by group (needs a table)"

    def check(self, scene, spec) -> None:
        if not isinstance(scene.support, Table):
            raise ConfigError("queries", "the bump query needs a table support (it counts boxes that fall "
                                         "off the table's edge); drop 'bump' or give the scene a table")

    def decided_below_z(self, scene, spec, initial_m):
        # below the table top a body is beside or under the table: nothing lifts it back
        if not isinstance(scene.support, Table):
            return None
        return np.full(len(initial_m), scene.support.top_height_m)

    def read(self, reading: Reading) -> dict[str, Any]:
        support = reading.scene.support
        if not isinstance(support, Table):
            return {}
        # started on or above the table top and ended below it: beside or under the table (an object
        # that starts on the floor beside the table has not fallen off it)
        fell_off = (reading.initial_m[:, 2] >= support.top_height_m) \
            & predicates.fell_off_mask(reading.final_m, support.top_height_m)
        groups = tuple(b.group for b in reading.scene.dynamic_objects)
        return {"fell_off": fell_off, "bump_ratio": predicates.bump_ratio(fell_off, groups,
                                                                                reading.spec.parameters_of("bump").group)}

    def aggregate(self, samples: Samples) -> dict[str, Any]:
        fell_off = np.array([r.get("fell_off") for r in samples.rollouts if r.get("fell_off") is not None])
        if not len(fell_off):
            return {}
        groups = [b.group for b in samples.scene.dynamic_objects]
        by_group = {}
        for group in dict.fromkeys(groups):
            members = np.array([g == group for g in groups])
            by_group[group] = float(fell_off[:, members].mean())
        ratios = [r.get("bump_ratio") for r in samples.rollouts if r.get("bump_ratio") is not None]
        return {"fell_off_fraction_by_group": by_group, "bump_ratio": float(np.mean(ratios)) if ratios else None,
                "bump_rollouts": len(ratios), "bump_group": samples.spec.parameters_of("bump").group}

    def flags(self, rollout) -> dict[str, Any]:
        return {} if rollout.get("fell_off") is None else {"fell_off": rollout.value("fell_off")}


QUERY = Bump()
