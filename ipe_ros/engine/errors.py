"""Named errors of the engine. Every message says what is wrong and what to do about it.

Messages are bounded and printable whatever the input: an offending value is shown cut to
``MAX_SHOWN_CHARS`` (a 5 MB list must not be echoed into logs, diagnostics and replies), and text
that is not valid Unicode (a lone surrogate) is escaped, since loggers and ROS strings refuse it.
"""

from __future__ import annotations

from typing import Any

#: The most characters of an offending value that a message repeats.
MAX_SHOWN_CHARS = 200
#: The most characters of a whole problem description (a value plus the advice around it).
MAX_PROBLEM_CHARS = 600


def printable(text: str) -> str:
    """``text`` with anything that is not encodable Unicode (lone surrogates) escaped as \\udXXX."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def clip(text: str, limit: int) -> str:
    text = printable(text)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def json_type(value: Any) -> str:
    """The JSON name of a value's type (what the sender wrote, not Python's name for it)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, (list, tuple)):
        return "an array"
    return "an object"


def shown(value: Any) -> str:
    """An offending value for a message, at most MAX_SHOWN_CHARS characters: numbers and strings as
    Python writes them, null / true / false and arrays as JSON does (never a Python type name)."""
    try:
        text = _format(value, MAX_SHOWN_CHARS)
    except RecursionError:
        text = f"<{json_type(value)} nested too deeply to show>"
    return clip(text, MAX_SHOWN_CHARS)


def _format(value: Any, budget: int) -> str:
    """Only as much of ``value`` as ``budget`` characters can show (a 5 MB list costs no more)."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return repr(value[:budget + 1])
    if isinstance(value, (list, tuple)):
        items = [_format(v, budget) for v in value[:budget // 3 + 1]]
        return "[" + ", ".join(items) + (", ...]" if len(value) > len(items) else "]")
    if isinstance(value, dict):
        items = [f"{_format(k, budget)}: {_format(v, budget)}" for k, v in list(value.items())[:budget // 6 + 1]]
        return "{" + ", ".join(items) + (", ...}" if len(value) > len(items) else "}")
    return repr(value)[:budget + 1]


class _NamedError(ValueError):
    def __init__(self, field: str, problem: str):
        self.field = clip(str(field), MAX_SHOWN_CHARS)
        self.problem = clip(str(problem), MAX_PROBLEM_CHARS)
        super().__init__(f"{self.field}: {self.problem}")

    def __reduce__(self):  # raised in a worker process, it arrives whole (field and problem), not as a TypeError
        return self.__class__, (self.field, self.problem)


class SceneError(_NamedError):
    """A scene (or a model setting) is invalid.

    ``field`` is the dotted path of the offending value (``boxes[3].extents_m``), so a caller can
    point at it; the message repeats it and says what is allowed.
    """


class ConfigError(_NamedError):
    """A model, query or simulation setting is out of range."""


class PhysicsError(RuntimeError):
    """One rollout produced non-finite or impossible states (the solver diverged).

    Raised inside a rollout and turned into a counted ``failed_samples`` entry by the sampler;
    it never ends a prediction on its own.
    """


class BudgetExceeded(RuntimeError):
    """A rollout was still running when its prediction's compute budget ran out (or started after).

    The sampler leaves such samples out of the answer (they are not physics failures) and reports
    ``stopped_by: "budget"``.
    """
