"""How far along a long analysis is, told to whoever runs it.

The analyses are library code: they say what they are doing through ``steps`` and ``progress``,
and the caller decides how that is shown (the CLI installs its progress bars with ``use``). Without
one, plain lines go to stderr (stdout stays the result).
"""

from __future__ import annotations

import sys
from typing import Callable, Iterable, Iterator, TypeVar

T = TypeVar("T")

_shown: dict[str, Callable] = {}


def use(steps_fn: Callable[..., Iterator], progress_fn: Callable[[str], None]) -> None:
    """Show the analyses' progress with these (``ipe_ros.progress.steps`` / ``progress``)."""
    _shown.update(steps=steps_fn, progress=progress_fn)


def progress(message: str) -> None:
    """One line of progress."""
    if "progress" in _shown:
        _shown["progress"](message)
    else:
        print(message, file=sys.stderr, flush=True)


def steps(items: Iterable[T], label: str, total: int | None = None, every: int = 20) -> Iterator[T]:
    """Yield ``items``, telling how far along (a line every ``every`` items and at the end)."""
    if "steps" in _shown:
        yield from _shown["steps"](items, label, total=total, every=every)
        return
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    done = 0
    for item in items:
        yield item
        done += 1
        if done % every == 0 or done == total:
            progress(f"  {label}: {done}/{total if total is not None else '?'}")
