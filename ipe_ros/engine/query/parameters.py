"""Queries' own parameters as the CLI and the node spell them.

Every registered query with ``Parameters`` (``base.Query``) gives one row per field: the node's
parameter ``<query>.<field>`` (also the engine's name for it in errors) and the CLI's option
``--<query>-<field>`` (underscores as dashes), typed by the field's annotation (float, int, bool or
str), with its default and meaning. A query registered at run time, before the CLI's parser or the
node is made, is settable from both with nothing else edited. ``spec_parameters`` turns values
given by those names into ``QuerySpec.parameters``; each query's dataclass checks its own values.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, Mapping

from ..errors import ConfigError, shown
from .spec import QUERIES

#: the types a query parameter may have: each has a CLI conversion and a ROS parameter type
PARAMETER_TYPES = (float, int, bool, str)


@dataclass(frozen=True)
class QueryParameter:
    """One field of a query's ``Parameters``."""

    query: str
    field: str
    type: type
    default: Any
    meaning: str

    @property
    def name(self) -> str:
        """The node's parameter, and the name errors use."""
        return f"{self.query}.{self.field}"

    @property
    def flag(self) -> str:
        """The CLI's option."""
        return "--" + f"{self.query}-{self.field}".replace("_", "-")


def query_parameters() -> list[QueryParameter]:
    """Every registered query's parameters, in the registry's order."""
    rows = []
    for name, query in QUERIES.items():
        cls = getattr(query, "Parameters", None)
        if cls is None:
            continue
        if not (dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen):
            raise TypeError(f"{name}.Parameters must be a frozen dataclass")
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if hints[f.name] not in PARAMETER_TYPES or f.default is dataclasses.MISSING:
                raise TypeError(f"{name}.Parameters.{f.name}: a parameter is a float, int, bool or str with a default")
            rows.append(QueryParameter(name, f.name, hints[f.name], f.default, f.metadata.get("meaning", "")))
    return rows


def spec_parameters(queries: frozenset[str], given: Mapping[str, Any]) -> tuple[tuple[str, Any], ...]:
    """``QuerySpec.parameters`` for the asked ``queries`` from values by parameter name
    (``"<query>.<field>"``); values for a query not asked are left out (the node declares every
    query's parameters). ConfigError naming the parameter for an unknown name or a wrong type."""
    rows = {row.name: row for row in query_parameters()}
    by_query: dict[str, dict[str, Any]] = {}
    for key, value in given.items():
        row = rows.get(key)
        if row is None:
            query = str(key).split(".", 1)[0]
            own = [name for name, r in rows.items() if r.query == query]
            if own:
                raise ConfigError(key, f"not a parameter of the {query} query; choose from {', '.join(own)}")
            raise ConfigError(key, f"not a parameter of any query; choose from {', '.join(rows) or 'none'}")
        if row.query in queries:
            by_query.setdefault(row.query, {})[row.field] = typed(row, value)
    return tuple((name, QUERIES[name].Parameters(**by_query[name])) for name in QUERIES if name in by_query)


def typed(row: QueryParameter, value: Any) -> Any:
    """``value`` as the parameter's type (an int given for a float is a float), or a ConfigError."""
    if row.type is float and isinstance(value, (int, float)) and not isinstance(value, bool) \
            and math.isfinite(value):
        return float(value)
    if row.type is not float and type(value) is row.type:
        return value
    raise ConfigError(row.name, f"must be a{'n' if row.type is int else ''} {row.type.__name__}"
                                f"{' (finite)' if row.type is float else ''}, got {shown(value)}")


def parse_cli_value(row: QueryParameter, text: str) -> Any:
    """The CLI's text for a parameter, as its type (ConfigError naming the option otherwise)."""
    try:
        if row.type is bool:
            if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return text.lower() in ("true", "1", "yes")
        return row.type(text)
    except ValueError:
        raise ConfigError(row.flag, f"must be a{'n' if row.type is int else ''} {row.type.__name__}, "
                                    f"got {shown(text)}") from None
