"""The command line's options made from the table of inputs (engine/inputs.py), and what was given
turned back into the request's arguments.

``ipe predict`` takes every input with a flag; ``ipe ask`` the ones a question uses, some with a
default of its own (16 samples per variant, the self-check off). A ``bool`` input is a switch
``--x``/``--no-x``; an input that ``requires`` another (``--verify-samples`` the self-check) is
refused given while that one is off, where it would be ignored.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, Iterable, Mapping

from .engine import ConfigError, parse_queries
from .engine.inputs import Input, request_arguments, row
from .engine.query.contact import parse_pair


def finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def float_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return values


def query_set(text: str) -> frozenset[str]:
    try:
        return parse_queries(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None


def contact_pair(text: str) -> tuple[str, str]:
    """One ``--contact`` (ipe predict and ipe ask)."""
    try:
        return parse_pair(text, "--contact")
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(exc.problem) from None


_TYPES = {"int": int, "float": finite, "floats": float_list, "names": query_set, "pairs": contact_pair}


def _help(found: Input, default: Any, note: str | None) -> str:
    text = (note or found.help).replace("%", "%%")
    if default is None and found.unset_means:
        return f"{text} (default: {found.unset_means})"
    if found.kind == "pairs" or default is None or "default" in text:
        return text
    shown = ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in default) \
        if isinstance(default, (tuple, list, frozenset)) else f"{default:g}" if isinstance(default, float) else default
    return f"{text} (default {shown})"


def add_input_options(parser: argparse.ArgumentParser, fields: Iterable[str], *,
                      defaults: Mapping[str, Any] | None = None, notes: Mapping[str, str] | None = None) -> None:
    """One option per input in ``fields``, each stored under its field; ``defaults`` and ``notes``
    (help texts) where this command's differ from the table's."""
    defaults, notes = defaults or {}, notes or {}
    for field in fields:
        found = row(field)
        _add_row(parser, found, defaults.get(field, found.default), notes.get(field))


def add_rows(parser, rows: Iterable[Input]) -> None:
    """An option per row not in the table (a perception source's own, engine/evidence.py)."""
    for found in rows:
        _add_row(parser, found, found.default, None)


def _add_row(parser, found: Input, default: Any, note: str | None) -> None:
    field = found.field
    if found.kind == "bool":
        parser.add_argument(found.flag, dest=field, default=default, action=argparse.BooleanOptionalAction,
                            help=(note or found.help).replace("%", "%%") + (" (default: on)" if default else ""))
        return
    kw: dict[str, Any] = dict(dest=field, metavar=found.metavar or found.flag[2:].upper(), type=_TYPES.get(found.kind))
    if found.choices is not None and found.kind == "name":
        kw.update(choices=list(found.choices()), metavar=None)
    elif found.choices is not None:  # several names: their type checks each
        note = f"{note or found.help}; comma-separated, from {','.join(found.choices())}"
    if found.kind == "pairs":
        kw.update(action="append", default=None)
    else:
        kw["default"] = None if found.requires else default
    parser.add_argument(found.flag, help=_help(found, default, note), **kw)


def add_inputs_from_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--inputs-from", default=None, metavar="FILE",
                        help="model inputs from a parameter set (ipe fit's output, engine/input_sets.py): they "
                             "replace the defaults; an option given here wins over the file")


def _typed(token: str, flag: str) -> bool:
    """``token`` gives option ``flag`` (whole, with ``=value``, or abbreviated as argparse allows)."""
    name = token.split("=", 1)[0]
    return name.startswith("--") and len(name) > 3 and flag.startswith(name)


def typed_option(args: argparse.Namespace, flag: str) -> bool:
    """Whether ``flag`` was typed on the command line (``args.argv``), not left at its default."""
    return any(_typed(t, flag) for t in getattr(args, "argv", ()))


def given_request_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The request's arguments (``build_request``'s keywords) from the options the command has; an
    input given while the one it ``requires`` is off is refused naming both. With ``--inputs-from``,
    the file's inputs stand in for the defaults of the options not typed (``args.argv``: the command line)."""
    given = dict(vars(args))
    if getattr(args, "inputs_from", None) is not None:
        from .engine.input_sets import load_input_set

        typed = getattr(args, "argv", ())
        try:
            loaded = load_input_set(args.inputs_from)
        except ConfigError as exc:
            raise ConfigError("--inputs-from", exc.problem) from None
        for field, value in loaded.items():
            if field in given and not any(_typed(t, row(field).flag) for t in typed):
                given[field] = value
    for name, value in list(given.items()):
        found = _row_or_none(name)
        if found is None:
            continue
        if found.kind == "pairs":
            given[name] = tuple(value or ())
        if found.requires is not None and value is None:
            given[name] = found.default
        elif found.requires is not None and not given.get(found.requires):
            raise ConfigError(found.flag, f"needs {row(found.requires).flag}, which is off; drop one of them")
    return request_arguments(given)


def _row_or_none(name: str) -> Input | None:
    try:
        found = row(name)
    except KeyError:
        return None
    return found if found.field == name and found.flag is not None else None

