"""A persistent pool of worker processes, each with its own pybullet client.

Workers start with ``forkserver`` (default) or ``spawn``, never ``fork``: forking a process that
runs rclpy or DDS threads has hung on shutdown. ``map`` keeps input order, so results never depend
on the worker count or on scheduling. A worker that dies (crash, OOM kill, ``kill -9``) breaks the
executor; the pool replaces it with a fresh one and runs each lost item once more on its own, and
items lost twice are answered by ``on_lost`` instead of being dropped.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import signal
import threading
import time
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Callable, Iterable, TypeVar

from ..query.spec import plugin_modules

T = TypeVar("T")
R = TypeVar("R")

START_METHODS = ("forkserver", "spawn")
#: Workers are replaced by fresh ones, between two ``map`` calls, once they have run this many items
#: each on average, or once one of them has grown by ``DEFAULT_MAX_WORKER_GROWTH_MB`` since it
#: started: a bound whatever leaks. pybullet leaks native memory it never frees (disconnecting does
#: not free it either) around its direct solver: a world built on it leaked ~30 kB a bouncing sample
#: in a 30-minute soak of the node (+290 MB), 110 kB a sample on the zoo's capped towers. Worlds are
#: now built on the sequential-impulse solver and take the direct one for impacts only
#: (simulation/impacts.py): ~1 kB a sample there (2026-11-29). Fresh workers cost ~0.3 s.
#: (ProcessPoolExecutor's own max_tasks_per_child hangs on Python 3.11.)
DEFAULT_MAX_TASKS_PER_WORKER = 1000
DEFAULT_MAX_WORKER_GROWTH_MB = 150.0


#: Environment variables that size the BLAS/OpenMP thread pools numpy's linear algebra may start.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _init_worker(owner_pid: int, plugins: tuple[str, ...] = ()) -> None:
    # Ctrl-C goes to the whole process group: let the parent decide how to shut down.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for module in plugins:  # queries registered at run time register again when their module loads
        importlib.import_module(module)
    # A worker's parent is the fork server, not the process that owns the pool. When the owner dies
    # without closing the pool (SIGKILL, a crash), end this worker too instead of leaving it behind.
    threading.Thread(target=_exit_when_gone, args=(owner_pid,), name="owner-watch", daemon=True).start()
    from ..simulation import world
    world.client()  # connect pybullet now, not in the first sample


def _exit_when_gone(pid: int, period_s: float = 1.0) -> None:
    while True:
        time.sleep(period_s)
        try:
            os.kill(pid, 0)  # signal 0: only asks whether the process exists
        except ProcessLookupError:
            os._exit(0)
        except PermissionError:
            pass  # it exists (owned by someone else after a pid reuse): keep going


def resident_mb(pid: int) -> float | None:
    """Process ``pid``'s resident memory in MB (Linux's /proc), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/statm") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        return None


def _worker_pid(hold_s: float = 0.0) -> int:
    time.sleep(hold_s)
    return os.getpid()


class WorkerPool:
    """``WorkerPool(workers).map(fn, items)``: an ordered, crash-tolerant parallel map."""

    def __init__(self, workers: int, start_method: str = "forkserver",
                 max_tasks_per_worker: int | None = DEFAULT_MAX_TASKS_PER_WORKER,
                 max_worker_growth_mb: float | None = DEFAULT_MAX_WORKER_GROWTH_MB):
        if not isinstance(workers, int) or workers < 1:
            raise ValueError(f"workers: must be an integer >= 1, got {workers!r}")
        if max_tasks_per_worker is not None and (not isinstance(max_tasks_per_worker, int) or max_tasks_per_worker < 1):
            raise ValueError(f"max_tasks_per_worker: must be an integer >= 1 or None, got {max_tasks_per_worker!r}")
        self.max_tasks_per_worker = max_tasks_per_worker
        if max_worker_growth_mb is not None and not (isinstance(max_worker_growth_mb, (int, float))
                                                     and not isinstance(max_worker_growth_mb, bool)
                                                     and max_worker_growth_mb > 0):
            raise ValueError(f"max_worker_growth_mb: must be a number > 0 or None, got {max_worker_growth_mb!r}")
        self.max_worker_growth_mb = max_worker_growth_mb
        self._started_mb: dict[int, float] = {}  # each worker's resident memory when first seen
        if start_method not in START_METHODS:
            raise ValueError(f"start_method: must be one of {', '.join(START_METHODS)}, got {start_method!r}")
        self.workers = workers
        # Each worker process is one core's worth of work; a BLAS thread pool in each on top of that
        # oversubscribes the cores (two 256 px vision chains ran 2.2x slower). Set before the fork
        # server starts, since BLAS reads it when numpy loads; a user's own setting is kept.
        for variable in BLAS_THREAD_VARIABLES:
            os.environ.setdefault(variable, "1")
        self._context = multiprocessing.get_context(start_method)
        if start_method == "forkserver":
            # Import numpy and pybullet once in the fork server rather than in every worker.
            self._context.set_forkserver_preload(["ipe_ros.engine.sampling.rollout"])
        self._lock = threading.Lock()
        self._executor: ProcessPoolExecutor | None = None
        self.replacements = 0  # how many times dead workers forced a new executor
        self.recycles = 0  # how many times workers were renewed after max_tasks_per_worker items
        self._items_run = 0
        self._closed = False
        self._shut_down = threading.Event()  # set once close() has stopped the executor

    # -- lifecycle -------------------------------------------------------------------------
    def _get_executor(self) -> ProcessPoolExecutor:
        with self._lock:
            if self._closed:
                raise RuntimeError("the worker pool is closed")
            if self._executor is None:
                self._executor = ProcessPoolExecutor(max_workers=self.workers, mp_context=self._context,
                                                     initializer=_init_worker,
                                                     initargs=(os.getpid(), plugin_modules()))
                self._items_run = 0
            return self._executor

    def _replace_executor(self, broken: ProcessPoolExecutor) -> None:
        with self._lock:
            if self._executor is broken:
                broken.shutdown(wait=True, cancel_futures=True)
                self._executor = None
                self.replacements += 1

    def warm(self) -> list[int]:
        """Start every worker now (imports, pybullet client) and return their process ids.

        Submitting ``workers`` items back to back makes the executor start ``workers`` processes
        (it starts one per submission while none is idle), each running the initializer. A worker
        left idle by earlier work (a map rerun after a worker died) takes such an item instead of a
        new process starting, so the items are submitted again, each holding its worker a moment,
        until every worker runs.
        """
        executor = self._get_executor()
        for hold_s in (0.0, 0.05, 0.2, 0.5):
            for future in [executor.submit(_worker_pid, hold_s) for _ in range(self.workers)]:
                future.result()
            if len(self.worker_pids()) >= self.workers:
                break
        return self.worker_pids()

    def worker_pids(self) -> list[int]:
        """Process ids of the live workers (empty before the first use)."""
        executor = self._executor
        if executor is None:
            return []
        # A copy first: the executor's management thread adds and removes processes meanwhile
        # (iterating the live dict raised "dictionary changed size during iteration").
        processes = dict(getattr(executor, "_processes", None) or {})
        return sorted(pid for pid, proc in processes.items() if proc.is_alive())

    def close(self, grace_s: float | None = None) -> None:
        """Stop the workers and wait for them to exit; safe to call twice.

        ``grace_s``: how long running items may go on; workers still busy then are terminated (by
        their process id: they are this pool's own children). None waits for them however long.
        """
        with self._lock:
            self._closed = True
            executor, self._executor = self._executor, None
        if executor is not None:
            processes = list(dict(getattr(executor, "_processes", None) or {}).values())
            executor.shutdown(wait=grace_s is None, cancel_futures=True)
            if grace_s is not None:
                end = time.monotonic() + grace_s
                for process in processes:
                    process.join(max(0.0, end - time.monotonic()))
                for process in processes:
                    if process.is_alive():
                        process.terminate()
                        process.join(1.0)
                    if process.is_alive():
                        process.kill()
                        process.join()
                executor.shutdown(wait=True)
        self._shut_down.set()

    def __enter__(self) -> "WorkerPool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- work --------------------------------------------------------------------------------
    def map(self, fn: Callable[[T], R], items: Iterable[T],
            on_lost: Callable[[T, str], R] | None = None) -> list[R]:
        """``[fn(x) for x in items]`` in parallel, in order.

        Items whose worker died are retried once on a replaced pool, each on its own: a dying worker
        breaks the whole executor and takes every item in flight or queued with it, so only an item
        that kills a worker while it runs alone is blamed. Items lost a second time are answered by
        ``on_lost(item, reason)``, or raise BrokenProcessPool when no ``on_lost`` is given. Items
        cancelled because ``close()`` ran meanwhile (shutdown) are answered by ``on_lost`` too.
        """
        items = list(items)
        self._recycle_if_due()
        results: list[R | None] = [None] * len(items)
        lost_once = self._run_round(fn, items, list(range(len(items))), results) if items else []
        lost_twice: list[int] = []
        for i in lost_once:  # one at a time: rare (a crash, an OOM kill), so speed matters less here
            lost_twice += [i] if self._closed else self._run_round(fn, items, [i], results)
        if lost_twice:
            reason = ("cancelled: the worker pool was closed (shutdown)" if self._closed
                      else "a worker process died twice while running this item")
            if on_lost is None:
                raise BrokenProcessPool(reason)
            for i in lost_twice:
                results[i] = on_lost(items[i], reason)
        return results  # type: ignore[return-value]

    def _recycle_if_due(self) -> None:
        """Fresh workers once the current ones have run max_tasks_per_worker items each (on
        average), or once one has grown by max_worker_growth_mb: between two maps, so no item is
        ever interrupted."""
        limit = self.max_tasks_per_worker
        grown = self._grown_worker()
        with self._lock:
            if self._executor is None:
                return
            if not grown and (limit is None or self._items_run < limit * self.workers):
                return
            old, self._executor = self._executor, None
            self.recycles += 1
            self._started_mb.clear()
        old.shutdown(wait=True)

    def _grown_worker(self) -> bool:
        """Whether some worker's resident memory grew by ``max_worker_growth_mb`` since it was first
        seen (Linux's /proc; elsewhere never)."""
        if self.max_worker_growth_mb is None:
            return False
        grown = False
        for pid in self.worker_pids():
            now = resident_mb(pid)
            if now is None:
                continue
            first = self._started_mb.setdefault(pid, now)
            grown |= now - first > self.max_worker_growth_mb
        return grown

    def _run_round(self, fn: Callable[[T], R], items: list[T], indices: list[int],
                   results: list) -> list[int]:
        """Submit ``items[i]`` for every i in ``indices`` together and store their results; return
        the indices lost to a dead worker or to ``close()`` (the executor is replaced after a death).
        Exceptions raised by ``fn`` itself propagate."""
        try:
            executor = self._get_executor()
        except RuntimeError:  # closed by another thread meanwhile
            return list(indices)
        futures: dict[Future, int] = {}
        try:
            for i in indices:
                futures[executor.submit(fn, items[i])] = i
                self._items_run += 1
        except (BrokenProcessPool, RuntimeError):
            pass  # broken, or shut down by close() from another thread: the rest counts as lost
        not_done = set(futures)
        while not_done:
            _, not_done = wait(not_done, timeout=0.25)
            if not_done and self._shut_down.is_set():
                # close() finished: futures the executor had already handed to its queue may
                # never complete now, so stop waiting for them
                break
        lost = [i for i in indices if i not in futures.values()]
        for future, i in futures.items():
            if not future.done():
                lost.append(i)
                continue
            try:
                exc = future.exception()
            except CancelledError:
                lost.append(i)
                continue
            if exc is None:
                results[i] = future.result()
            elif isinstance(exc, BrokenProcessPool):
                lost.append(i)
            else:
                raise exc
        if lost and not self._closed:
            self._replace_executor(executor)
        return sorted(lost)
