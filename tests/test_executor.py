"""The node's executor queues a waiting callback once (ipe_ros/ros/executor.py)."""

from __future__ import annotations

import threading

import pytest

from tests.ros_harness import domain_id_for_tests, wait_until

rclpy = pytest.importorskip("rclpy")

from rclpy.callback_groups import ReentrantCallbackGroup  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from ipe_ros.ros.executor import SubmitOnceExecutor  # noqa: E402

#: starts rclpy (a Context of its own, DDS on loopback)
pytestmark = pytest.mark.ros


def submissions_while_both_threads_are_busy(executor_class) -> tuple[int, int, int]:
    """Two message callbacks hold both of a 2-thread executor's threads while a third message's
    callback is ready, and the executor is woken 200 times meanwhile (as every callback that ends
    wakes it: a flood of messages wakes it thousands of times). Returns how many times anything was
    handed to the thread pool meanwhile, how many distinct callbacks that was, and how many times
    the waiting callback ran once the threads were free."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id_for_tests())
    executor = executor_class(num_threads=2, context=context)
    node = rclpy.create_node("executor_probe", context=context)
    executor.add_node(node)
    release, started = threading.Event(), threading.Semaphore(0)
    runs: list[str] = []

    def hold(_msg):
        started.release()
        release.wait(5.0)

    group = ReentrantCallbackGroup()
    for topic in ("hold_a", "hold_b"):
        node.create_subscription(String, topic, hold, 10, callback_group=group)
    node.create_subscription(String, "waiting", lambda msg: runs.append(msg.data), 10, callback_group=group)
    publishers = {topic: node.create_publisher(String, topic, 10) for topic in ("hold_a", "hold_b", "waiting")}
    submitted = []
    real_submit = executor._executor.submit
    executor._executor.submit = lambda fn, *a, **kw: (submitted.append(fn), real_submit(fn, *a, **kw))[1]
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    try:
        wait_until(lambda: all(p.get_subscription_count() for p in publishers.values()), 5.0, "the subscriptions")
        publishers["hold_a"].publish(String(data="a"))
        publishers["hold_b"].publish(String(data="b"))
        for _ in range(2):
            assert started.acquire(timeout=5.0), "a holding callback did not start"
        publishers["waiting"].publish(String(data="w"))
        wait_until(lambda: len(submitted) >= 3, 5.0, "the waiting callback to be queued")
        pause = threading.Event()
        for _ in range(200):  # both threads busy: the waiting callback stays in the pool's queue
            executor.wake()
            pause.wait(0.001)
        count, distinct = len(submitted), len({id(fn) for fn in submitted})
        release.set()
        wait_until(lambda: runs, 5.0, "the waiting callback to run")
        return count, distinct, len(runs)
    finally:
        release.set()
        executor.shutdown(timeout_sec=5.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        spinner.join(5.0)


def test_a_callback_waiting_for_a_free_thread_is_queued_once_and_then_runs():
    count, distinct, runs = submissions_while_both_threads_are_busy(SubmitOnceExecutor)
    assert (count, distinct, runs) == (3, 3, 1)  # the two holders and the waiting callback, each once


def test_the_stock_executor_requeues_it_which_is_why_the_node_does_not_use_it():
    # rclpy 7.1.6 (pinned): if this starts failing, the upstream fix (ros2/rclpy#1547) has arrived
    # and SubmitOnceExecutor can go
    count, distinct, runs = submissions_while_both_threads_are_busy(MultiThreadedExecutor)
    assert (distinct, runs) == (3, 1)
    assert count > 50, count
