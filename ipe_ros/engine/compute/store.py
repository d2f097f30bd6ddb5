"""Resumable long runs: a ``map`` that keeps every result on disk, keyed by what it is a function of.

A sample's outcome is a function of its task: the scene, the model, the settings, the query and the
sample's own seed (and, for a vision chain, the scene, settings and seed). ``ResumableMap`` wraps any
``map`` (the local pool, a Dask cluster, or none): results already in its folder are read back,
only the missing ones are computed, and each new one is written as soon as its batch returns. An
interrupted ``ipe experiment --resume DIR`` started again continues from what it has, and gives the
answers an uninterrupted run gives (tested).

Results that are not the task's own (a sample lost with its worker, one cut off by a compute
budget) are never stored, so a rerun computes them again.

Entries are data, never code: one JSON document per result (format ``ipe_ros.result``, a version, the
key it answers, a type from a fixed list, arrays as dtype + shape + base64 bytes, scenes through the
validated scene reader). An entry that is not exactly that (truncated, empty, another type, another
key, a link, too large) is reported in one line, ignored and recomputed: a run folder from somebody
else can waste time but cannot run anything (a pickle could).
"""

from __future__ import annotations

import base64
import collections.abc
import dataclasses
import functools
import hashlib
import json
import math
import os
import sys
import types as pytypes
import typing
from pathlib import Path
from typing import Any, Callable, Iterable, TypeVar

import numpy as np

from ..errors import clip, shown
from ..safe_files import UnsafeEntry, open_folder, read_entry, write_entry

T = TypeVar("T")
R = TypeVar("R")

#: Bump when what a stored result means changes (the engine's physics or outcome format).
STORE_VERSION = 4  # 4: a rollout's query values in one mapping (3: JSON entries)
#: An entry's ``format`` field: what tells a result of ours from any other JSON file.
ENTRY_FORMAT = "ipe_ros.result"
#: Larger entries are refused unread (a k-sample vision chain is ~100 kB; a recorded trajectory more).
MAX_ENTRY_BYTES = 64 * 1024 * 1024
#: Array dtypes an entry may hold: numbers and booleans only (an object array would unpickle).
_DTYPES = frozenset({"bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                     "float32", "float64"})


class StoreEntryError(ValueError):
    """A stored entry that is not a result of ours; the message (one line, at most 300 characters)
    says what is wrong with it."""

    def __init__(self, problem: str):
        super().__init__(clip(problem.replace("\n", " "), 300))


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
        # a field keyed "when set" (added after results were stored) is left out at its default
        return (type(value).__qualname__, tuple((f.name, _canonical(getattr(value, f.name)))
                                                for f in dataclasses.fields(value)
                                                if not (f.metadata.get("keyed") == "when set"
                                                        and getattr(value, f.name) == f.default)))
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
    in ``folder``. ``hits``, ``computed`` and ``rejected`` count what the calls read back, ran, and
    refused to read (each refusal is passed to ``report`` as one line; default: stderr)."""

    #: Missing results computed per call of ``inner``: large enough that the map's own overheads (a
    #: cluster's round trip, the last sample's wait) stay small, small enough that an interruption
    #: loses seconds of work (~10 s at 46 rollouts/s).
    DEFAULT_BATCH = 480

    def __init__(self, folder: str | Path, inner: Callable | None = None, batch: int = DEFAULT_BATCH,
                 report: Callable[[str], None] | None = None):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.inner, self.batch = inner, batch
        self.report = report if report is not None else (lambda line: print(line, file=sys.stderr))
        self.hits = self.computed = self.rejected = 0

    def _path(self, key: str) -> Path:
        return self.folder / key[:2] / f"{key}.json"

    def _open_shard(self, key: str, create: bool) -> int | None:
        """A descriptor of the entry's shard folder, opened without following a link (so that every
        file operation below stays inside the store, whatever is planted there meanwhile); None when
        it does not exist (and ``create`` is false). UnsafeEntry when it is not a real folder."""
        return open_folder(self.folder / key[:2], create)

    def _read(self, key: str, item):
        """The stored result for ``key`` (computed for ``item``); None when there is none or it is
        refused (reported)."""
        path = self._path(key)
        shard = None
        try:
            shard = self._open_shard(key, create=False)
            if shard is None:
                return None
            data = read_entry(shard, path.name, MAX_ENTRY_BYTES)
            if data is None:
                return None
            result = decode_entry(data, key)
            _check_against_task(result, item)
            return result
        except (StoreEntryError, UnsafeEntry, OSError) as exc:
            self.rejected += 1
            self.report(f"ipe: ignoring store entry {path} and computing it again: {exc}")
            return None
        finally:
            if shard is not None:
                os.close(shard)

    def map(self, fn: Callable[[T], R], items: Iterable[T], on_lost: Callable[[T, str], R] | None = None) -> list[R]:
        items = list(items)
        keys = [result_key(fn, item) for item in items]
        results: list = [None] * len(items)
        missing = []
        for i, key in enumerate(keys):
            results[i] = self._read(key, items[i])
            if results[i] is None:
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
        """Store one result inside the store only (``safe_files.write_entry``: its shard opened
        without following a link, the temporary file created anew, then renamed over the entry). A
        shard that is not a real folder is reported and the result left unstored."""
        path = self._path(key)
        data = encode_entry(result, key)
        try:
            shard = self._open_shard(key, create=True)
        except (UnsafeEntry, OSError) as exc:
            self.report(f"ipe: not storing {path}: {exc}; remove it to store results there again")
            return
        try:
            write_entry(shard, path.name, data)
        except UnsafeEntry as exc:  # something already at the temporary name (a planted link): never opened
            self.report(f"ipe: not storing {path}: {exc}")
        finally:
            os.close(shard)


# --- the entry format ------------------------------------------------------------------------------

@functools.cache
def _result_types() -> dict[str, type]:
    """The dataclasses an entry may hold, by name (imported here: the vision package imports the engine)."""
    from ..results.outcome import RolloutResult, SampleOutcome
    from ..vision.mcmc import Chain
    from ..vision.perception import PerceivedScenes

    return {t.__name__: t for t in (SampleOutcome, RolloutResult, PerceivedScenes, Chain)}


def encode_entry(result, key: str) -> bytes:
    """``result`` as an entry answering ``key``. Raises TypeError for a value the format has no
    place for (a new result type must be added to ``_result_types``)."""
    types = _result_types()
    document = {"format": ENTRY_FORMAT, "version": STORE_VERSION, "key": key,
                "result": _encode(result, types)}
    return json.dumps(document, separators=(",", ":"), allow_nan=True).encode()


def decode_entry(data: bytes, key: str):
    """The result in an entry, checked to be an entry of this format and version answering ``key``;
    StoreEntryError naming what is wrong otherwise."""
    try:
        document = json.loads(data.decode("utf-8"))
    except RecursionError:
        raise StoreEntryError("nested deeper than any result") from None
    except (UnicodeDecodeError, ValueError) as exc:  # empty, truncated, binary, not JSON
        raise StoreEntryError(f"not a JSON document ({type(exc).__name__}: {str(exc)[:80]})") from None
    if not isinstance(document, dict) or document.get("format") != ENTRY_FORMAT:
        raise StoreEntryError(f"not an {ENTRY_FORMAT} entry")
    if document.get("version") != STORE_VERSION:
        raise StoreEntryError(f"version {shown(document.get('version'))}, this engine writes {STORE_VERSION}")
    if document.get("key") != key:
        raise StoreEntryError("stored under another result's name (its key differs)")
    if "result" not in document:
        raise StoreEntryError("has no result")
    try:
        result = _decode(document["result"], _result_types(), "result")
    except StoreEntryError:
        raise
    except (TypeError, ValueError, KeyError, OverflowError) as exc:  # a constructor refusing what it was given
        raise StoreEntryError(f"result does not fit its type ({type(exc).__name__}: {str(exc)[:80]})") from None
    except RecursionError:
        raise StoreEntryError("nested deeper than any result") from None
    if type(result) not in _result_types().values():  # a bare number, list or null is no result
        raise StoreEntryError(f"result: a {type(result).__name__}, not one of the stored result types")
    _check_shapes(result)
    return result


def _encode(value, types: dict[str, type]):
    if isinstance(value, (np.ndarray, np.generic)):  # first: np.float64 is also a float
        array = np.asarray(value)
        if array.dtype.name not in _DTYPES:
            raise TypeError(f"arrays of {array.dtype} have no place in a store entry")
        return {"array": array.dtype.name, "shape": list(array.shape), "scalar": isinstance(value, np.generic),
                "data": base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")}
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, tuple):
        return {"tuple": [_encode(v, types) for v in value]}
    if isinstance(value, dict):
        if not all(isinstance(k, str) for k in value):
            raise TypeError("a store entry's mappings have text keys")
        return {"dict": [[k, _encode(v, types)] for k, v in value.items()]}
    if isinstance(value, list):
        return [_encode(v, types) for v in value]
    from ..scene.bodies import Scene

    if isinstance(value, Scene):
        from ..scene.format import scene_to_dict

        return {"scene": scene_to_dict(value)}
    if dataclasses.is_dataclass(value) and types.get(type(value).__name__) is type(value):
        return {"dataclass": type(value).__name__,
                "fields": {f.name: _encode(getattr(value, f.name), types) for f in dataclasses.fields(value)}}
    raise TypeError(f"a {type(value).__qualname__} has no place in a store entry")


def _decode(value, types: dict[str, type], where: str):
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        return [_decode(v, types, f"{where}[{i}]") for i, v in enumerate(value)]
    if not isinstance(value, dict) or len(value) == 0:
        raise StoreEntryError(f"{where}: unexpected {type(value).__name__}")
    if "tuple" in value and len(value) == 1 and isinstance(value["tuple"], list):
        return tuple(_decode(v, types, f"{where}[{i}]") for i, v in enumerate(value["tuple"]))
    if "dict" in value and len(value) == 1 and isinstance(value["dict"], list):
        items = value["dict"]
        if not all(isinstance(kv, list) and len(kv) == 2 and isinstance(kv[0], str) for kv in items):
            raise StoreEntryError(f"{where}: a mapping's items are [text, value] pairs")
        return {k: _decode(v, types, f"{where}.{k}") for k, v in items}
    if set(value) == {"array", "shape", "scalar", "data"}:
        return _decode_array(value, where)
    if set(value) == {"scene"}:
        from ..errors import ConfigError
        from ..scene.format import scene_from_dict

        try:
            return scene_from_dict(value["scene"])
        except (ConfigError, ValueError, TypeError) as exc:
            raise StoreEntryError(f"{where}: not a valid scene ({str(exc)[:80]})") from None
    if set(value) == {"dataclass", "fields"}:
        cls = types.get(value["dataclass"]) if isinstance(value["dataclass"], str) else None
        if cls is None:
            raise StoreEntryError(f"{where}: {shown(value['dataclass'])} is not a result type")
        fields = value["fields"]
        names = {f.name for f in dataclasses.fields(cls)}
        # a field added later with a default may be missing from an older entry
        required = {f.name for f in dataclasses.fields(cls)
                    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING}
        if not isinstance(fields, dict) or not required <= set(fields) <= names:
            raise StoreEntryError(f"{where}: a {cls.__name__} with other fields than this engine's")
        hints = _type_hints(cls)
        decoded = {}
        for name, v in fields.items():
            decoded[name] = _decode(v, types, f"{where}.{name}")
            if not _fits(decoded[name], hints[name]):
                raise StoreEntryError(f"{where}.{name}: a {type(decoded[name]).__name__} where a "
                                      f"{hints[name]} belongs")
        return cls(**decoded)
    raise StoreEntryError(f"{where}: an object of unknown kind (keys {shown(sorted(value)[:4])})")


def _decode_array(value: dict[str, Any], where: str):
    dtype, shape, data = value["array"], value["shape"], value["data"]
    if dtype not in _DTYPES:
        raise StoreEntryError(f"{where}: arrays of {shown(dtype)} are not allowed")
    if not (isinstance(shape, list) and len(shape) <= 32 and all(isinstance(n, int) and not isinstance(n, bool)
                                                                 and 0 <= n < 2**40 for n in shape)):
        raise StoreEntryError(f"{where}: shape must be a list of at most 32 counts")
    try:
        raw = base64.b64decode(data, validate=True) if isinstance(data, str) else None
    except ValueError:
        raw = None
    if raw is None:
        raise StoreEntryError(f"{where}: data is not base64")
    if len(raw) != math.prod(shape) * np.dtype(dtype).itemsize:  # Python ints: no overflow
        raise StoreEntryError(f"{where}: {len(raw)} bytes do not fill a {dtype} array of shape {tuple(shape)}")
    array = np.frombuffer(raw, dtype=dtype).reshape(shape).copy()
    if value["scalar"] is True and array.shape == ():
        return array[()]
    return array


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    """``cls``'s annotations resolved once (each entry read holds several dataclasses)."""
    return typing.get_type_hints(cls)


def _fits(value, hint) -> bool:
    """Whether ``value`` is of the annotated type (the annotations our result dataclasses use)."""
    origin = typing.get_origin(hint)
    if origin is typing.Union or origin is pytypes.UnionType:
        return any(_fits(value, h) for h in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if hint is float:
        return isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, (bool, np.bool_))
    if hint is int:
        return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint is np.ndarray:
        return isinstance(value, np.ndarray)
    if hint is typing.Any:
        return True
    if origin is dict or origin is collections.abc.Mapping:
        return isinstance(value, dict) and all(isinstance(k, str) for k in value)
    if origin is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return isinstance(value, tuple) and all(_fits(v, args[0]) for v in value)
        return isinstance(value, tuple) and len(value) == len(args) and all(_fits(v, a) for v, a in zip(value, args))
    if origin is list or hint is list:
        return isinstance(value, list)
    if isinstance(hint, type):
        return isinstance(value, hint)
    return False


def _check_against_task(result, task) -> None:
    """A sample's stored outcome answers the task it is read for: its index, and a value per body
    of the task's scene (a well-formed entry for another scene would be aggregated as this one's)."""
    from ..results.outcome import SampleOutcome

    scene = getattr(task, "scene", None)
    if not isinstance(result, SampleOutcome) or scene is None:
        return
    if result.index != getattr(task, "index", result.index):
        raise StoreEntryError(f"result.index: {result.index}, but it is read for sample {task.index}")
    bodies = len(scene.dynamic_objects)
    if result.initial_positions_m is not None and len(result.initial_positions_m) != bodies:
        raise StoreEntryError(f"result: {len(result.initial_positions_m)} bodies, but the scene it is read for "
                              f"({scene.name or 'unnamed'}) has {bodies}")


def _check_shapes(result) -> None:
    """The arrays of a sample's outcome agree with each other (code reading it indexes them together)."""
    from ..results.outcome import SampleOutcome

    if not isinstance(result, SampleOutcome) or result.initial_positions_m is None:
        return
    n = len(result.initial_positions_m)
    expected = {"initial_positions_m": (n, 3), "initial_orientations_xyzw": (n, 4)}
    arrays = {name: getattr(result, name) for name in expected}
    for i, rollout in enumerate(result.rollouts):
        expected |= {f"rollouts[{i}].final_positions_m": (n, 3), f"rollouts[{i}].final_orientations_xyzw": (n, 4)}
        arrays |= {f"rollouts[{i}].final_positions_m": rollout.final_positions_m,
                   f"rollouts[{i}].final_orientations_xyzw": rollout.final_orientations_xyzw}
        for name in ("fallen", "fell_off"):
            if rollout.get(name) is not None:
                expected[f"rollouts[{i}].values.{name}"] = (n,)
                arrays[f"rollouts[{i}].values.{name}"] = rollout.get(name)
    for name, shape in expected.items():
        if arrays[name] is not None and arrays[name].shape != shape:
            raise StoreEntryError(f"result.{name}: shape {arrays[name].shape}, the sample has {n} bodies so {shape}")
