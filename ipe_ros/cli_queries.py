"""The command line's options for the queries' own parameters (engine/query/parameters.py): one
``--<query>-<field>`` per parameter of every registered query, for ``ipe predict`` and the robot
questions of ``ipe ask``."""

from __future__ import annotations

from typing import Any

from .engine.query.parameters import QueryParameter, parse_cli_value, query_parameters


def _dest(row: QueryParameter) -> str:
    return f"query_parameter__{row.query}__{row.field}"


def add_query_parameter_options(parser) -> None:
    for row in query_parameters():
        parser.add_argument(row.flag, dest=_dest(row), default=None, metavar=row.type.__name__.upper(),
                            help=f"the {row.query} query: {row.meaning} (default {row.default})")


def given_query_parameters(args) -> dict[str, Any]:
    """The parameters given on the command line, by name (``<query>.<field>``), as their types."""
    return {row.name: parse_cli_value(row, getattr(args, _dest(row)))
            for row in query_parameters() if getattr(args, _dest(row), None) is not None}
