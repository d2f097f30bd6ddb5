"""Samples on a Dask cluster: a ``map`` with :meth:`WorkerPool.map`'s contract, on ``distributed.Client``.

The sampler takes its parallelism as an injected ``map``, so a cluster only needs one: tasks (the
engine's ``SampleTask``s, chains, ...) go to the Dask workers in batches, each worker process runs
``fn`` on them with its own pybullet client (worlds are built there, never shipped), and results come
back in order. Seeds travel inside the tasks, so answers are bit-identical to the local pool's.

A task whose worker dies is rescheduled by Dask on another worker (``distributed.scheduler.
allowed-failures`` times, 3 by default); a batch lost beyond that is answered by ``on_lost`` per
item, as the local pool does, so the prediction counts those samples as failed instead of failing.

Dask is imported only here and only when a cluster is used: without ``--scheduler`` (or
``IPE_DASK_SCHEDULER``) nothing changes.
"""

from __future__ import annotations

import contextlib
import importlib
import os
from typing import Any, Callable, Iterable, Iterator, TypeVar

from ..errors import ConfigError
from ..query.spec import plugin_modules

T = TypeVar("T")
R = TypeVar("R")

#: Environment variable naming a scheduler address when no ``--scheduler`` is given.
SCHEDULER_ENV = "IPE_DASK_SCHEDULER"
#: Tasks per Dask task: a sample takes ~25 ms and Dask's per-task overhead is ~1 ms, so small
#: batches keep the overhead small while still spreading a k = 48 prediction over many workers.
DEFAULT_BATCH = 4


def run_batch(fn: Callable[[T], R], batch: list[T], plugins: tuple[str, ...] = ()) -> list[R]:
    """What a Dask worker runs: ``fn`` on each task of a batch, in order, after importing the modules of
    the queries registered at run time (``query.spec.plugin_modules``; a module registers its query
    when imported, once per worker)."""
    for module in plugins:
        importlib.import_module(module)
    return [fn(item) for item in batch]


def scheduler_address(given: str | None) -> str | None:
    """The scheduler to use: ``given``, else $IPE_DASK_SCHEDULER, else None (the local pool)."""
    address = given if given is not None else os.environ.get(SCHEDULER_ENV)
    if address is None or not address.strip():
        return None
    return address.strip()


@contextlib.contextmanager
def local_cluster(workers: int, **config: Any) -> Iterator[Any]:
    """A Dask cluster on this machine, reachable on loopback only; yields its ``distributed.Client``
    (``client.cluster.scheduler_address`` is what ``--scheduler`` takes) and ends every process on exit.

    ``workers`` processes of one thread each (pybullet steps one world per thread), each given one
    task at a time, so that a worker that dies takes only its own task with it (the scheduler queues
    the rest). The scheduler always serves HTTP (health, metrics routes) even without a dashboard:
    on a free loopback port, so that two clusters never collide. ``config``: more Dask settings by
    their dotted names, e.g. ``{"distributed.scheduler.allowed-failures": 1}``.
    """
    import dask
    from distributed import Client, LocalCluster

    settings = {"distributed.scheduler.worker-saturation": 1.0, **config}
    with dask.config.set(settings), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address="127.0.0.1:0") as cluster, \
            Client(cluster, set_as_default=False) as client:
        yield client


class DaskMap:
    """``map(fn, items, on_lost=None)`` on a Dask cluster (a scheduler address, or a Client)."""

    def __init__(self, scheduler, batch_size: int = DEFAULT_BATCH, connect_timeout_s: float = 10.0):
        if not isinstance(batch_size, int) or batch_size < 1:
            raise ConfigError("batch_size", f"must be an integer >= 1, got {batch_size!r}")
        from distributed import Client

        self.batch_size = batch_size
        if isinstance(scheduler, Client):
            self.client, self._own = scheduler, False
        else:
            try:
                self.client, self._own = Client(scheduler, timeout=connect_timeout_s, set_as_default=False), True
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigError("scheduler", f"cannot reach the Dask scheduler at {scheduler!r} ({exc}); start one "
                                               "(`dask scheduler`) or leave --scheduler out to run locally") from None

    @property
    def workers(self) -> int:
        return len(self.worker_pids())

    def map(self, fn: Callable[[T], R], items: Iterable[T],
            on_lost: Callable[[T, str], R] | None = None) -> list[R]:
        from distributed import KilledWorker

        items = list(items)
        batches = [items[i:i + self.batch_size] for i in range(0, len(items), self.batch_size)]
        futures = self.client.map(run_batch, [fn] * len(batches), batches, [plugin_modules()] * len(batches),
                                  pure=False)
        results: list[R] = []
        for future, batch in zip(futures, batches):
            try:
                results += future.result()
            except KilledWorker as exc:
                if on_lost is None:
                    raise
                reason = f"the Dask workers running it died ({exc.__class__.__name__})"
                results += [on_lost(item, reason) for item in batch]
        return results

    # -- what the node's prediction service asks of a pool ------------------------------------------
    replacements = 0  # Dask's nannies replace dead workers; the scheduler counts them, not we

    def worker_pids(self) -> list[str]:
        """The Dask workers' addresses (a local pool's are process ids)."""
        return sorted(self.client.scheduler_info(n_workers=-1).get("workers", {}))

    def warm(self) -> list[str]:
        return self.worker_pids()

    def close(self, grace_s: float | None = None) -> None:
        """Disconnect (the cluster's workers keep running; tasks still queued for us are dropped)."""
        if self._own:
            self.client.close()

    def __enter__(self) -> "DaskMap":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
