"""One row of the table of inputs (engine/inputs.py): what an input is, once, and how each door
spells it. Apart from the table so that a perception source can declare its own rows (its CLI
options and node parameters, engine/evidence.py) without importing the table, which imports the
perception registry."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Literal, Sequence

Caller = Literal["cli", "ros"]
#: int, float, bool; ``floats``: one or more numbers; ``name``: one of ``choices`` (or any text
#: without them); ``names``: several; ``pairs``: (A, B) object-name pairs
Kind = Literal["int", "float", "floats", "bool", "name", "names", "pairs"]


@dataclass(frozen=True)
class Input:
    """One input. ``field``: the request's argument (``build_request``) or, with ``in_request``
    False, the door's own setting; ``default`` None: not set (the engine chooses); ``range``:
    inclusive bounds of a number; ``choices``: what a name may be (called when the option or
    descriptor is made, so registered plugins count); ``unset_means``: what not setting it
    does; ``requires``: a bool input that must be on
    for this one to mean anything (the CLI refuses it given without)."""

    field: str
    kind: Kind
    default: Any
    unit: str
    help: str
    flag: str | None = None
    parameter: str | None = None
    range: tuple[float, float] | None = None
    choices: Callable[[], Sequence[str]] | None = None
    unset: Any = None
    unset_means: str = ""
    errors_as: tuple[str, ...] = ()
    in_request: bool = True
    fixed_at_start: bool = False
    requires: str | None = None
    metavar: str | None = None
    constraints: str = ""

    def __post_init__(self) -> None:
        if self.default is None and self.parameter is not None and self.unset is None:
            raise TypeError(f"input {self.field}: a node parameter cannot be None; give the value meaning unset")
        if self.default is None and not self.unset_means:
            raise TypeError(f"input {self.field}: say what leaving it unset does (unset_means)")
