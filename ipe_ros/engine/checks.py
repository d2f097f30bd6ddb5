"""Checks of one input value, shared by every frozen settings type of the engine: each raises
:class:`~.errors.ConfigError` naming the field (as its caller spells it) and what it must be."""

from __future__ import annotations

import math
from typing import Any

from .errors import ConfigError, shown


def boolean(value: Any, field: str) -> None:
    if not isinstance(value, bool):
        raise ConfigError(field, f"must be true or false, got {shown(value)}")


def positive(value: float, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value <= 0:
        raise ConfigError(field, f"must be a finite number > 0, got {shown(value)}")


def non_negative(value: float, field: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < 0:
        raise ConfigError(field, f"must be a finite number >= 0, got {shown(value)}")


def at_most(value: float, field: str, limit: float, unit: str) -> None:
    if value > limit:
        raise ConfigError(field, f"must be at most {limit:g} {unit}, got {shown(value)}")


def integer(value: Any, field: str, lo: int, hi: int, meaning: str = "") -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(field, f"must be an integer in [{lo}, {hi}]{meaning}, got {shown(value)}")
