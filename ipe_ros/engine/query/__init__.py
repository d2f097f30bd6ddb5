"""The questions a prediction answers, one module per query (see base.py for what a query is).

A new built-in query is a module defining ``QUERY`` (a :class:`Query`) and one line in ``_MODULES``;
its name is then accepted by QuerySpec (spec.py), the CLI's ``--query`` and the node's ``queries``
parameter, and its fields appear in every answer (None where it was not asked). ``register`` adds
one at run time.
"""

from __future__ import annotations

from . import any_fall, bump, contact, direction, fall, far, final_pose, rest, tipped
from .base import Query, Reading, Samples, StepWatch
from .spec import QUERIES, QuerySpec, parse_queries, register

_MODULES = (fall, any_fall, direction, far, bump, contact, rest, final_pose, tipped)

for _module in _MODULES:
    register(_module.QUERY)

#: the built-in queries' names, in the order answers list them
ALL_QUERIES: tuple[str, ...] = tuple(QUERIES)


def answer_fields() -> tuple[str, ...]:
    """Every registered query's answer fields, in the registry's order (queries registered at run
    time included)."""
    return tuple(f for q in QUERIES.values() for f in q.fields)


#: every answer field a built-in query fills, in order
ANSWER_FIELDS: tuple[str, ...] = answer_fields()

__all__ = ["ALL_QUERIES", "ANSWER_FIELDS", "QUERIES", "answer_fields", "Query", "QuerySpec", "Reading", "Samples", "StepWatch",
           "parse_queries", "register"]
