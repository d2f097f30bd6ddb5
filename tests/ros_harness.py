"""In-process ROS 2 test harness: an isolated Context, an executor spun in a thread, deadline waits.

Every test gets its own ``rclpy.Context`` on its own domain id (``ROS_DOMAIN_ID`` from
scripts/test.sh, offset by the pytest-xdist worker number if any), with discovery kept on loopback.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from ipe_ros.ros.executor import SubmitOnceExecutor  # noqa: E402


def domain_id_for_tests() -> int:
    """This test process's DDS domain: ROS_DOMAIN_ID (random per run) + the xdist worker number."""
    base = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    offset = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    return (base + offset) % 233  # valid Fast DDS domain ids: 0..232


def wait_until(condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll ``condition`` until it returns something truthy; fail naming ``what`` at the deadline."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(0.005)


class RosHarness:
    """A context, a client node for the test's own publishers/subscribers, and a spinning executor."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id_for_tests())
        self.executor = SubmitOnceExecutor(num_threads=4, context=self.context)  # as the node's main() spins
        self.client = rclpy.create_node("ipe_test_client", context=self.context)
        self.executor.add_node(self.client)
        self._thread = threading.Thread(target=self.executor.spin, name="executor", daemon=True)
        self._thread.start()
        self._nodes: list = []

    def start_ipe_node(self, **overrides: Any):
        from ipe_ros.ros.node import IpeNode

        overrides.setdefault("workers", 2)
        node = IpeNode(context=self.context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()])
        self._nodes.append(node)
        self.executor.add_node(node)
        return node

    def collect(self, msg_type, topic: str, qos) -> list:
        """Subscribe on the client node; returns the list the messages are appended to."""
        received: list = []
        self.client.create_subscription(msg_type, topic, received.append, qos)
        return received

    def publisher(self, msg_type, topic: str, qos=10, subscribers: int = 1, timeout_s: float = 10.0):
        """A publisher that is already matched with ``subscribers`` subscriptions (discovery done)."""
        pub = self.client.create_publisher(msg_type, topic, qos)
        wait_until(lambda: pub.get_subscription_count() >= subscribers, timeout_s, f"a subscriber on {topic}")
        return pub

    def call(self, srv_type, name: str, request, timeout_s: float = 60.0):
        client = self.client.create_client(srv_type, name)
        wait_until(client.service_is_ready, 10.0, f"service {name}")
        future = client.call_async(request)
        wait_until(future.done, timeout_s, f"a response from {name}")
        return future.result()

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=5.0)
        # the spin thread may still be finishing a callback that touches a node's handles: let it
        # leave before the nodes go (else rclpy's InvalidHandle in that thread)
        self._thread.join(10.0)
        for node in self._nodes:
            node.destroy_node()
        self.client.destroy_node()
        rclpy.try_shutdown(context=self.context)
