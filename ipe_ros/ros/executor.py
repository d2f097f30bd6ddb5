"""The node's executor: rclpy's MultiThreadedExecutor, with each callback in its thread pool once.

rclpy 7.1.6 (the pinned Jazzy wheel, the only one the registry has) hands a callback that is
waiting in its thread pool's queue to the pool again every time the executor wakes: a queued
callback is "ready, not executing" (ros2/rclpy#1452; changed on rolling by ros2/rclpy#1547, not in
this wheel). Every callback that ends wakes it, so under a burst of messages the queue fills with
duplicates, the list of pending futures it scans on every turn grows with them, and the spinning
thread holds the GIL that the threads running the callbacks need. Measured here: under
tests/test_node.py's flood of 5000 questions the question thread answered one question every few
seconds and replies stopped for minutes, in 14 of 31 runs with node and asker in one process and
9 of 9 with the asker in a context of its own; with this executor 8 of 8 passed.

This executor submits a callback only when it is not already in the pool; while one waits there,
the spinning thread sleeps briefly instead of spinning. A coroutine callback that suspends leaves
the pool and is submitted again when it is next ready, as before.
"""

from __future__ import annotations

import threading
import time
from typing import Callable

from rclpy.executors import (ConditionReachedException, ExternalShutdownException, MultiThreadedExecutor,
                             ShutdownException, TimeoutException)

#: How long the spinning thread sleeps when the only ready work is already queued in the pool: it
#: lets the pool's threads take the GIL; short enough to add no measurable latency.
QUEUED_WAIT_S = 0.0005


class SubmitOnceExecutor(MultiThreadedExecutor):
    """``MultiThreadedExecutor`` that never queues a callback twice (see the module docstring)."""

    def __init__(self, num_threads: int | None = None, *, context=None) -> None:
        super().__init__(num_threads, context=context)
        self._in_pool: set = set()  # handlers submitted whose pool run has not returned
        self._in_pool_lock = threading.Lock()

    def _spin_once_impl(self, timeout_sec=None, wait_condition: Callable[[], bool] = lambda: False) -> None:
        try:
            handler, _entity, _node = self.wait_for_ready_callbacks(timeout_sec, None, wait_condition)
        except (ExternalShutdownException, ShutdownException, TimeoutException, ConditionReachedException):
            return
        with self._in_pool_lock:
            queued = handler in self._in_pool
            if not queued:
                self._in_pool.add(handler)
        if queued:
            time.sleep(QUEUED_WAIT_S)
            return
        run = self._executor.submit(handler)
        run.add_done_callback(lambda _run, done=handler: self._left_pool(done))
        self._futures.append(handler)
        for future in self._futures[:]:
            if future.done():
                self._futures.remove(future)
                future.result()  # raise any exceptions, as MultiThreadedExecutor does

    def _left_pool(self, handler) -> None:
        with self._in_pool_lock:
            self._in_pool.discard(handler)
