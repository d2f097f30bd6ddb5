"""Queries and perception sources from installed packages, found without editing ``ipe`` or
``ipe_node``: a package declares entry points in the groups ``ipe_ros.queries`` and
``ipe_ros.perceptions`` (setup.cfg ``[options.entry_points]``, pyproject ``[project.entry-points]``):

    [ipe_ros.perceptions]
    detections = my_package.detections:SOURCE      # a PerceptionSource, registered here
    [ipe_ros.queries]
    tilt = my_package.tilt                         # a module that registers its query when imported
    tilt2 = my_package.tilt:TILT                   # or a Query, registered here

``load_plugins`` runs once at the start of ``ipe`` and of ``ipe_node``. A plugin that fails to load is
reported by name and skipped: the others, and the built-ins, still serve. Worker processes import a
plugin query's module themselves (``query.spec.plugin_modules``), and a source's chain pickles its
functions by module, so plugins must live in importable modules.
"""

from __future__ import annotations

import types
from importlib.metadata import entry_points
from typing import Callable

from .perceptions import PerceptionSource, perception_names, perception_source, register_perception
from .query import QUERIES
from .query.base import Query
from .query.spec import register

GROUPS = ("ipe_ros.queries", "ipe_ros.perceptions")


def _register(group: str, loaded) -> None:
    if isinstance(loaded, types.ModuleType):
        return  # it registered what it holds when imported
    if group == "ipe_ros.perceptions" and isinstance(loaded, PerceptionSource):
        if loaded.name not in perception_names() or perception_source(loaded.name) is not loaded:
            register_perception(loaded)
        return
    if group == "ipe_ros.queries" and isinstance(loaded, Query):
        if QUERIES.get(loaded.name) is not loaded:
            register(loaded)
        return
    wanted = "a PerceptionSource" if group == "ipe_ros.perceptions" else "a Query"
    raise TypeError(f"names a {type(loaded).__name__}, not a module or {wanted}")


def load_plugins(warn: Callable[[str], None]) -> tuple[str, ...]:
    """Load every installed plugin (``group:name`` of those loaded); ``warn`` hears of each that
    could not be, and why."""
    loaded = []
    for group in GROUPS:
        for point in sorted(entry_points(group=group), key=lambda p: p.name):
            try:
                _register(group, point.load())
            except Exception as exc:  # noqa: BLE001 - a broken plugin must not take the others down
                warn(f"plugin {point.name} ({point.value}, {group}) not loaded: {type(exc).__name__}: {exc}")
                continue
            loaded.append(f"{group}:{point.name}")
    return tuple(loaded)
