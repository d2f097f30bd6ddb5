"""Progress of long command-line work: a tqdm bar on a terminal, plain lines otherwise (logs, CI)."""

from __future__ import annotations

import sys
from typing import Iterable, Iterator, TypeVar

from tqdm import tqdm

T = TypeVar("T")


def progress(message: str) -> None:
    """One line of progress on stderr (stdout stays the result)."""
    print(message, file=sys.stderr, flush=True)


def steps(items: Iterable[T], label: str, total: int | None = None, every: int = 20) -> Iterator[T]:
    """Yield ``items``, showing how far along: a bar when stderr is a terminal, else a line every
    ``every`` items and at the end (a bar's carriage returns would garble a log file)."""
    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    if sys.stderr.isatty():
        yield from tqdm(items, desc=label, total=total, file=sys.stderr, leave=False, dynamic_ncols=True)
        return
    done = 0
    for item in items:
        yield item
        done += 1
        if done % every == 0 or done == total:
            progress(f"  {label}: {done}/{total if total is not None else '?'}")
