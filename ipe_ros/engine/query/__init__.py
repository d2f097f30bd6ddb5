"""The questions a prediction answers, one module per query (see base.py for what a query is).

A new query is a module defining ``QUERY`` (a :class:`Query`) and one line in ``_MODULES``; its
name is then accepted by QuerySpec, the CLI's ``--query`` and the node's ``queries`` parameter, and
its fields appear in every answer (None where it was not asked).
"""

from __future__ import annotations

from . import any_fall, bump, contact, direction, fall, far, final_pose, rest
from .base import Query, Reading, Samples, StepWatch

_MODULES = (fall, any_fall, direction, far, bump, contact, rest, final_pose)

#: every query by name, in the order answers list them
QUERIES: dict[str, Query] = {m.QUERY.name: m.QUERY for m in _MODULES}
ALL_QUERIES: tuple[str, ...] = tuple(QUERIES)
#: every answer field a query fills, in order
ANSWER_FIELDS: tuple[str, ...] = tuple(f for q in QUERIES.values() for f in q.fields)

__all__ = ["ALL_QUERIES", "ANSWER_FIELDS", "QUERIES", "Query", "Reading", "Samples", "StepWatch"]
