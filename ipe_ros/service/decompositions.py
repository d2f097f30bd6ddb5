"""Meshes decomposed off the executor: an input whose mesh is not yet in the cache is answered
"decomposing" at once and read again once its parts are ready (``engine.scene.meshes.NotYetDecomposed``).

One thread runs one decomposition at a time (in a spawned process, within the node's
``mesh_decomposition_s``); scenes, questions and everything else go on meanwhile. Distinct meshes
waiting and inputs waiting on them are bounded (beyond: "busy", at once). Per input stream only the
newest scene waits (keep-latest, as for predictions); each question waits, and hears back once.
"""

from __future__ import annotations

import collections
import dataclasses
import threading
import time
from typing import Any, Callable

from ..engine.errors import clip
from ..engine.scene.meshes import DecompositionJob, decompose

#: distinct meshes queued behind the one decomposing; more are refused "busy" at once
MAX_WAITING_MESHES = 4
#: questions waiting on meshes (scenes keep one per stream); more are refused "busy" at once
MAX_QUESTIONS_ON_MESHES = 4


@dataclasses.dataclass
class _Waiter:
    """An input to read again once its mesh is decomposed (``again``), or to be told why never
    (``abandon``, with the reason naming its field ``path``); ``stream`` names a keep-latest slot
    (scenes), None for a question."""

    again: Callable[[], None]
    abandon: Callable[[str], None]
    stream: str | None
    path: str


class DecompositionService:
    """Decompositions in a thread of their own, each input read again when its mesh is ready. Thread-safe."""

    def __init__(self, log_error: Callable[[str], None] = lambda _msg: None,
                 log_info: Callable[[str], None] = lambda _msg: None):
        self._log_error = log_error
        self._log_info = log_info
        self._cond = threading.Condition()
        self._jobs: collections.OrderedDict[str, DecompositionJob] = collections.OrderedDict()  # waiting, by key
        self._waiters: dict[str, list[_Waiter]] = collections.defaultdict(list)
        self._current: DecompositionJob | None = None
        self._current_since: float | None = None
        self._stop = threading.Event()
        self._closing = False
        self.decomposed = 0
        self.refused = 0
        self._thread = threading.Thread(target=self._run, name="ipe-decompositions", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def wait_for(self, job: DecompositionJob, again: Callable[[], None], abandon: Callable[[str], None],
                 stream: str | None = None) -> dict[str, Any] | str:
        """Queue ``job`` (once per mesh) and read the input again (``again``) once it is done: what to
        tell the sender now (``status``'s dict), or why not ("busy", shutting down)."""
        with self._cond:
            if self._closing:
                return "the node is shutting down"
            known = job.key in self._jobs or (self._current is not None and self._current.key == job.key)
            if not known and len(self._jobs) >= MAX_WAITING_MESHES:
                return (f"busy: {len(self._jobs)} meshes are waiting to be decomposed into convex parts; send the "
                        "scene again later, or decompose its meshes ahead (ipe predict caches them)")
            if stream is None:
                questions = sum(w.stream is None for ws in self._waiters.values() for w in ws)
                if questions >= MAX_QUESTIONS_ON_MESHES:
                    return f"busy: {questions} questions are waiting for meshes to be decomposed; ask again later"
            else:  # keep-latest per stream: a newer scene replaces the one waiting
                for ws in self._waiters.values():
                    ws[:] = [w for w in ws if w.stream != stream]
            # looked up only now: a refusal above leaves no empty entry behind
            self._waiters[job.key].append(_Waiter(again, abandon, stream, job.path))
            if not known:
                self._jobs[job.key] = job
                self._cond.notify_all()
            return self._status_locked(job)

    def _status_locked(self, job: DecompositionJob) -> dict[str, Any]:
        keys = list(self._jobs)
        ahead = keys.index(job.key) + (self._current is not None) if job.key in self._jobs else 0
        return {"object": job.path, "mesh": job.what, "triangles": job.triangles, "meshes_ahead": ahead,
                "within_s": job.within_s}

    def status(self) -> dict[str, Any]:
        """What is decomposing (and for how long), what waits, what was done."""
        with self._cond:
            current = None if self._current is None else {
                "object": self._current.path, "mesh": self._current.what,
                "running_s": round(time.monotonic() - (self._current_since or time.monotonic()), 1)}
            return {"decomposing": current, "meshes_waiting": len(self._jobs),
                    "inputs_waiting": sum(len(ws) for ws in self._waiters.values()),
                    "decomposed": self.decomposed, "refused": self.refused}

    def close(self, reason: str = "the node is shutting down", timeout_s: float = 1.0) -> None:
        """Stop: the decomposition running is ended (its process by id), every input waiting is told
        ``reason`` (``abandon``), the thread joined."""
        with self._cond:
            self._closing = True
            self._stop.set()
            abandoned = [w for ws in self._waiters.values() for w in ws]
            self._waiters.clear()
            self._jobs.clear()
            self._cond.notify_all()
        for waiter in abandoned:
            self._tell(waiter.abandon, f"{reason}: the mesh was not decomposed")
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._closing and not self._jobs:
                    self._cond.wait()
                if self._closing:
                    return
                _, job = self._jobs.popitem(last=False)
                self._current, self._current_since = job, time.monotonic()
            start = time.perf_counter()
            try:
                refused = decompose(job, self._stop)
            except Exception as exc:  # noqa: BLE001 - one mesh's trouble never ends the service
                refused = f"its convex decomposition failed ({type(exc).__name__}: {clip(str(exc), 300)})"
            with self._cond:
                self._current = self._current_since = None
                if self._closing:
                    return
                waiters = self._waiters.pop(job.key, [])
                if refused is None:
                    self.decomposed += 1
                else:
                    self.refused += 1
            took = time.perf_counter() - start
            if refused is None:
                self._log_info(f"{job.path}: {job.what} ({job.triangles} triangles) decomposed in {took:.1f} s; "
                               f"reading {len(waiters)} input(s) again")
            for waiter in waiters:  # read again (the parts are cached now), or told why not
                if refused is None:
                    self._tell(waiter.again)
                else:
                    self._tell(waiter.abandon, f"{waiter.path}: {refused}")

    def _tell(self, callback: Callable, *args) -> None:
        try:
            callback(*args)
        except Exception as exc:  # noqa: BLE001 - the reader's trouble must not end the thread
            self._log_error(f"reading an input again after its decomposition failed: {type(exc).__name__}: "
                            f"{clip(str(exc), 500)}")
