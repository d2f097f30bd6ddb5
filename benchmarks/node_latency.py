"""End-to-end latency of the ROS 2 node vs the engine alone, measured in one run.

    .venv/bin/python benchmarks/node_latency.py [--repeats 5] [--samples 8,48] [--workers 2]

For each k: the engine API alone (``predict`` with a warm pool), then the node: a MarkerArray tower
published on /ipe/scene, answer received on /ipe/prediction (the scene changes a little each time so
no answer is reused). Reports medians and the node's overhead (conversion, queueing, DDS, JSON), and
the cost of writing a rerun recording. Prints a Markdown table. DDS stays on loopback.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import tempfile
import threading
import time

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy  # noqa: E402
from ipe_ros.ros.executor import SubmitOnceExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from ipe_ros.engine.scene.examples import example_scene_path  # noqa: E402
from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.ros.node import LATCHED_QOS, IpeNode  # noqa: E402
from msg_bridge.markers import scene_to_markers  # noqa: E402


def _wait(condition, timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {what} within {timeout_s:g} s")
        time.sleep(0.001)


def shifted(scene, i: int):
    """The scene moved by i micrometres in x: a new scene each time (no cached answer), same physics."""
    boxes = tuple(dataclasses.replace(b, position_m=(b.position_m[0] + 1e-6 * i, *b.position_m[1:]))
                  for b in scene.objects)
    return dataclasses.replace(scene, objects=boxes)


def engine_times(scene, k: int, workers: int, repeats: int) -> list[float]:
    model, query = ModelConfig(sigma_m=0.04, samples=k), QuerySpec(queries=frozenset({"fall", "direction", "far"}))
    with WorkerPool(workers) as pool:
        pool.warm()
        times = []
        for i in range(repeats):
            start = time.perf_counter()
            predict(shifted(scene, i),
                    Request(model=model, settings=preset("default"), query=query, seed=0, budget_s=None),
                    Context(map_fn=pool.map))
            times.append(time.perf_counter() - start)
    return times


def node_times(scene, k: int, workers: int, repeats: int, rerun_dir: str | None) -> tuple[list[float], list[float]]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    executor = SubmitOnceExecutor(num_threads=4, context=context)
    overrides = [Parameter("samples", value=k), Parameter("workers", value=workers)]
    if rerun_dir:
        overrides.append(Parameter("rerun.save_dir", value=rerun_dir))
    node = IpeNode(context=context, parameter_overrides=overrides)
    client = rclpy.create_node("bench_client", context=context)
    executor.add_node(node)
    executor.add_node(client)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    answers: list[tuple[float, dict]] = []
    client.create_subscription(String, "/ipe/prediction",
                               lambda m: answers.append((time.perf_counter(), json.loads(m.data))), LATCHED_QOS)
    pub = client.create_publisher(MarkerArray, "/ipe/scene", 10)
    try:
        _wait(lambda: pub.get_subscription_count() > 0, 30, "subscriber")
        _wait(lambda: node.service.stats().workers_alive == workers, 60, "warm workers")
        round_trips, computes = [], []
        for i in range(repeats):
            before = len(answers)
            sent = time.perf_counter()
            pub.publish(scene_to_markers(shifted(scene, i), "world"))
            _wait(lambda: len(answers) > before, 300, "answer")
            round_trips.append(answers[-1][0] - sent)
            computes.append(answers[-1][1]["compute_s"])
        return round_trips, computes
    finally:
        executor.shutdown(timeout_sec=5)
        node.destroy_node()
        client.destroy_node()
        rclpy.try_shutdown(context=context)
        spinner.join(10)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--samples", default="8,48")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    scene = load_scenes(example_scene_path())[0]
    print(f"example tower (10 blocks), sigma = 0.04 m, preset default, {args.workers} workers, "
          f"median of {args.repeats}\n")
    print("| k | engine API s | node: publish to answer s | node overhead s | with rerun .rrd s | rerun cost s |")
    print("|---|---|---|---|---|---|")
    for k in (int(v) for v in args.samples.split(",")):
        engine = statistics.median(engine_times(scene, k, args.workers, args.repeats))
        node, _ = node_times(scene, k, args.workers, args.repeats, None)
        with tempfile.TemporaryDirectory() as tmp:
            logged, _ = node_times(scene, k, args.workers, args.repeats, tmp)
        node_m, logged_m = statistics.median(node), statistics.median(logged)
        print(f"| {k} | {engine:.3f} | {node_m:.3f} | {node_m - engine:+.3f} | {logged_m:.3f} | "
              f"{logged_m - node_m:+.3f} |", flush=True)


if __name__ == "__main__":
    main()
