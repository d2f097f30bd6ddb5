"""Resumable long runs: a ``map`` that keeps every result on disk, keyed by what it is a function of.

A sample's outcome is a function of its task: the scene, the model, the settings, the query and the
sample's own seed (and, for a vision chain, the scene, settings and seed). ``ResumableMap`` wraps any
``map`` (the local pool, a Dask cluster, or none): results already in its folder are read back,
only the missing ones are computed, and each new one is written as soon as its batch returns. An
interrupted ``ipe experiment --resume DIR`` started again continues from what it has, and gives the
answers an uninterrupted run gives (tested).

Results that are not the task's own (a sample lost with its worker, one cut off by a compute
budget) are never stored, so a rerun computes them again.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
from pathlib import Path
from typing import Callable, Iterable, TypeVar

import numpy as np

T = TypeVar("T")
R = TypeVar("R")

#: Bump when what a stored result means changes (the engine's physics or outcome format).
STORE_VERSION = 2  # 2: bump-only rollouts end once what fell off is decided


def result_key(fn: Callable, item) -> str:
    """A digest of the function's name and the task. Left out: a deadline (when, not what) and the
    model's k (sample i has the i-th seed whatever k is, so a k = 48 run reuses a k = 24 run's samples)."""
    if dataclasses.is_dataclass(item):
        names = {f.name for f in dataclasses.fields(item)}
        if "deadline_unix_s" in names:
            item = dataclasses.replace(item, deadline_unix_s=None)
        if "model" in names and hasattr(item.model, "samples"):
            item = dataclasses.replace(item, model=dataclasses.replace(item.model, samples=1))
    payload = repr((STORE_VERSION, fn.__module__, fn.__qualname__, _canonical(item))).encode()
    return hashlib.sha256(payload).hexdigest()


def _canonical(value):
    """A representation that is the same in every process (pickle's is not: a frozenset's order
    follows string hashing, which Python salts per process)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return (type(value).__qualname__, tuple((f.name, _canonical(getattr(value, f.name)))
                                                for f in dataclasses.fields(value)))
    if isinstance(value, (set, frozenset)):
        return ("set", tuple(sorted((_canonical(v) for v in value), key=repr)))
    if isinstance(value, dict):
        return ("dict", tuple(sorted(((repr(k), _canonical(v)) for k, v in value.items()))))
    if isinstance(value, (list, tuple)):
        return tuple(_canonical(v) for v in value)
    if isinstance(value, np.ndarray):
        return ("array", str(value.dtype), value.shape, value.tobytes().hex())
    if isinstance(value, np.random.SeedSequence):
        return ("seed", value.entropy, value.spawn_key, value.pool_size)
    if isinstance(value, float):
        return float.hex(value)
    if value is None or isinstance(value, (bool, int, str)):
        return value
    return repr(value)


def _own_result(result) -> bool:
    """A result of the task itself, worth keeping: not one cut off by the budget or answered for a
    lost worker (both would come out otherwise in another run)."""
    return not getattr(result, "budget_stopped", False) and not getattr(result, "worker_lost", False)


class ResumableMap:
    """``map(fn, items, on_lost=None)`` through ``inner`` (None: in this process), remembering results
    in ``folder``. ``hits`` and ``computed`` count what the last calls read back and ran."""

    #: Missing results computed per call of ``inner``: large enough that the map's own overheads (a
    #: cluster's round trip, the last sample's wait) stay small, small enough that an interruption
    #: loses seconds of work (~10 s at 46 rollouts/s).
    DEFAULT_BATCH = 480

    def __init__(self, folder: str | Path, inner: Callable | None = None, batch: int = DEFAULT_BATCH):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.inner, self.batch = inner, batch
        self.hits = self.computed = 0

    def _path(self, key: str) -> Path:
        return self.folder / key[:2] / f"{key}.pkl"

    def map(self, fn: Callable[[T], R], items: Iterable[T], on_lost: Callable[[T, str], R] | None = None) -> list[R]:
        items = list(items)
        keys = [result_key(fn, item) for item in items]
        results: list = [None] * len(items)
        missing = []
        for i, key in enumerate(keys):
            path = self._path(key)
            if path.exists():
                with path.open("rb") as handle:
                    results[i] = pickle.load(handle)
            else:
                missing.append(i)
        self.hits += len(items) - len(missing)
        for first in range(0, len(missing), self.batch):  # written batch by batch: an interruption keeps them
            chunk = missing[first:first + self.batch]
            todo = [items[i] for i in chunk]
            done = self.inner(fn, todo, on_lost=on_lost) if self.inner is not None else [fn(t) for t in todo]
            for i, result in zip(chunk, done):
                results[i] = result
                if _own_result(result):
                    self._write(keys[i], result)
            self.computed += len(chunk)
        return results

    def _write(self, key: str, result) -> None:
        path = self._path(key)
        path.parent.mkdir(exist_ok=True)
        partial = path.with_suffix(f".{os.getpid()}.part")
        with partial.open("wb") as handle:
            pickle.dump(result, handle, protocol=5)
        os.replace(partial, path)  # atomic: a crash leaves a .part, never a half-written result
