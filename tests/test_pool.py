"""The worker pool keeps order, replaces dead workers, and answers every item."""

import os
import time
from concurrent.futures.process import BrokenProcessPool

import pytest

from ipe_ros.engine import WorkerPool


def _square(x: int) -> int:
    return x * x


def square_or_die_once(args):
    """Kills its worker the first time it sees item 3 (a marker file remembers)."""
    value, marker = args
    if value == 3 and not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return value * value


def always_die_on_three(value):
    if value == 3:
        os._exit(1)
    return value * value


def slow_square_or_die_on_three(value):
    if value == 3:
        os._exit(1)
    time.sleep(0.02)
    return value * value


def refuse(value):
    from ipe_ros.engine import ConfigError

    raise ConfigError("budget_s", f"item {value} needs more than the budget leaves it")


def test_an_error_named_in_a_worker_arrives_whole():
    """A ConfigError raised in a worker reaches the caller with its field and message (it used to
    arrive as a TypeError from unpickling: its constructor takes two arguments)."""
    from ipe_ros.engine import ConfigError

    with WorkerPool(1) as pool:
        with pytest.raises(ConfigError, match=r"^budget_s: item 2 needs more than the budget leaves it$") as info:
            pool.map(refuse, [2])
    assert info.value.field == "budget_s"


def test_map_keeps_order_and_recovers_from_a_dead_worker(tmp_path):
    marker = str(tmp_path / "died")
    with WorkerPool(2) as pool:
        before = pool.warm()
        assert len(before) == 2
        results = pool.map(square_or_die_once, [(i, marker) for i in range(8)])
        assert results == [i * i for i in range(8)]
        assert pool.replacements == 1
        after = pool.warm()
        assert len(after) == 2 and set(after) != set(before)  # fresh workers took over


def test_items_lost_twice_are_answered_by_on_lost():
    with WorkerPool(2) as pool:
        results = pool.map(always_die_on_three, range(5), on_lost=lambda item, reason: f"lost {item}: {reason}")
        assert results[3] == "lost 3: a worker process died twice while running this item"
        assert [r for i, r in enumerate(results) if i != 3] == [0, 1, 4, 16]
        with pytest.raises(BrokenProcessPool):
            pool.map(always_die_on_three, [3])


def test_only_the_item_that_kills_its_worker_is_lost():
    # The dying worker takes every item in flight or queued with it (items take 20 ms here, so
    # some always are), twice if the retry ran them together again; each is retried alone, so only
    # the culprit is answered by on_lost.
    with WorkerPool(2) as pool:
        results = pool.map(slow_square_or_die_on_three, range(10), on_lost=lambda item, reason: None)
        assert results == [None if i == 3 else i * i for i in range(10)]


def test_workers_end_when_the_pool_closes():
    pool = WorkerPool(2)
    pids = pool.warm()
    pool.close()
    for pid in pids:
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)


def test_bad_arguments():
    with pytest.raises(ValueError, match="^workers: must be an integer >= 1, got 0"):
        WorkerPool(0)
    with pytest.raises(ValueError, match="^start_method: must be one of forkserver, spawn, got 'fork'"):
        WorkerPool(1, start_method="fork")


@pytest.mark.slow
def test_workers_end_by_themselves_when_their_owner_is_killed(tmp_path):
    """An owner killed with SIGKILL cannot close its pool: the workers notice and exit."""
    import subprocess
    import sys
    import time
    from pathlib import Path

    script = tmp_path / "owner.py"
    script.write_text(
        "import sys, time\n"
        "from ipe_ros.engine import WorkerPool\n"
        "if __name__ == '__main__':\n"
        "    pool = WorkerPool(2)\n"
        "    print(' '.join(map(str, pool.warm())), flush=True)\n"
        "    time.sleep(600)\n")
    owner = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        pids = [int(p) for p in owner.stdout.readline().split()]
        assert len(pids) == 2
    finally:
        owner.kill()  # our own child, by pid
        owner.wait()
    deadline = time.monotonic() + 20
    while any(Path(f"/proc/{pid}").exists() for pid in pids):
        assert time.monotonic() < deadline, f"workers {pids} outlived their owner"
        time.sleep(0.05)


def test_workers_are_renewed_between_maps_after_their_share_of_items():
    """pybullet leaks native memory (its MLCP solver): fresh workers bound it, never mid-map."""
    with WorkerPool(2, max_tasks_per_worker=3) as pool:
        first = pool.warm()
        assert pool.map(_square, range(4)) == [0, 1, 4, 9]
        assert pool.map(_square, range(4)) == [0, 1, 4, 9]  # ran whole: 8 items, beyond 3 per worker
        assert pool.recycles == 0 and pool.worker_pids() == first
        assert pool.map(_square, range(3)) == [0, 1, 4]  # renewed before this map
        assert pool.recycles == 1 and not set(pool.worker_pids()) & set(first)


def test_workers_run_single_threaded_blas_unless_the_user_chose_otherwise():
    """A worker process is one core's worth of work: BLAS thread pools on top oversubscribe the cores."""
    with WorkerPool(1) as pool:
        [in_worker] = pool.map(os.getenv, ["OPENBLAS_NUM_THREADS"])
    assert in_worker == os.environ["OPENBLAS_NUM_THREADS"]  # "1" unless set before the pool started


def _hold_memory(megabytes: int) -> int:
    """Grow this worker by ``megabytes`` for good (as pybullet's leaks do) and return its pid."""
    _HELD.append(bytearray(megabytes * 1_000_000))
    for i in range(0, len(_HELD[-1]), 4096):  # touch every page: resident, not only reserved
        _HELD[-1][i] = 1
    return os.getpid()


_HELD: list = []


def test_a_worker_that_has_grown_too_much_is_renewed_before_the_next_map():
    """pybullet's leaks grow with what a sample does (a mesh's many contacts leak more), so workers
    are renewed by their growth too, not only by their count of items."""
    with WorkerPool(1, max_tasks_per_worker=None, max_worker_growth_mb=50) as pool:
        [first] = pool.warm()
        assert pool.map(_hold_memory, [10]) == [first]
        assert pool.map(_square, [2]) == [4] and pool.recycles == 0  # grown by 10 MB: kept
        assert pool.map(_hold_memory, [80]) == [first]
        assert pool.map(_square, [3]) == [9]  # grown by 90 MB: renewed before this map
        assert pool.recycles == 1 and first not in pool.worker_pids()
    with pytest.raises(ValueError, match=r"max_worker_growth_mb: must be a number > 0 or None, got 0"):
        WorkerPool(1, max_worker_growth_mb=0)
