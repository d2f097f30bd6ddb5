"""``ipe_ros_demo``: the node end to end on a paper tower, in one process, ending by itself.

1. starts ``IpeNode`` (worker processes, rerun recording on) and a small "robot" node beside it;
2. the robot publishes the built-in tower as a ``visualization_msgs/MarkerArray`` on ``/ipe/scene``;
   each answer on ``/ipe/prediction`` is printed as it arrives;
3. it switches the node to the ground-truth model (parameter ``ground_truth``) and asks
   the ``/ipe/predict`` Trigger service for an answer on the same scene;
4. it prints where the ``.rrd`` recordings are (replay: ``rerun FILE.rrd``) and shuts down cleanly.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
import time
from pathlib import Path

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # DDS stays on this machine

import rclpy  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from msg_bridge.markers import scene_to_markers  # noqa: E402

from ..engine import load_scenes  # noqa: E402
from ..engine.config import DEFAULT_SAMPLES, DEFAULT_SIGMA_M, default_workers  # noqa: E402
from ..engine.scene.examples import example_scene_path  # noqa: E402
from .executor import SubmitOnceExecutor  # noqa: E402
from .process_setup import unusable_dds_profile_file  # noqa: E402
from .node import LATCHED_QOS, IpeNode  # noqa: E402


class DemoFailed(RuntimeError):
    pass


def _wait(condition, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise DemoFailed(f"timed out after {timeout_s:g} s waiting for {what}")
        time.sleep(0.01)


def describe(answer: dict) -> str:
    """One readable paragraph for a prediction answer."""
    lines = [f"  scene {answer['scene_id']} #{answer['scene_seq']} in frame {answer['frame_id']!r}, "
             f"stamp {answer['stamp']['sec']}.{answer['stamp']['nanosec']:09d}"]
    if answer.get("fall_fraction") is not None:
        lo, hi = answer["fall_fraction_ci95"]
        kind = "deterministic rollout" if answer["deterministic"] else f"k = {answer['samples']} samples"
        lines.append(f"  expected fraction of blocks that fall: {answer['fall_fraction']:.2f} "
                     f"(95% interval {lo:.2f}..{hi:.2f}, {kind}, {answer['failed_samples']} failed)")
        if answer.get("any_fall_probability") is not None:
            lo, hi = answer["any_fall_probability_ci95"]
            lines.append(f"  probability that anything falls: {answer['any_fall_probability']:.2f} "
                         f"(95% interval {lo:.2f}..{hi:.2f})")
        risky = sorted(answer["object_fall_probability"].items(), key=lambda kv: -kv[1])[:3]
        if risky and risky[0][1] > 0:
            lines.append("  most likely to fall: " + ", ".join(f"{n} ({p:.2f})" for n, p in risky))
    if answer.get("direction_rad") is not None:
        lines.append(f"  fall direction {math.degrees(answer['direction_rad']):.0f} deg in the scene frame, "
                     f"decisiveness {answer['direction_decisiveness']:.2f}; far {answer['far_m']:.2f} m")
    elif answer.get("fall_fraction") is not None:
        lines.append("  nothing falls in any sample: no direction")
    lines.append(f"  computed in {answer['compute_s']:.2f} s (scene to answer {answer['latency_s']:.2f} s)")
    if answer.get("rrd_path"):
        lines.append(f"  recording: {answer['rrd_path']} ({answer['rollouts_logged']} rollouts)")
    return "\n".join(lines)


def run(output_dir: Path, samples: int, workers: int, timeout_s: float) -> list[dict]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    executor = SubmitOnceExecutor(num_threads=4, context=context)
    ipe = robot = None
    spinner = threading.Thread(target=executor.spin, name="executor", daemon=True)
    try:
        ipe = IpeNode(context=context, parameter_overrides=[
            Parameter("samples", value=samples), Parameter("workers", value=workers),
            Parameter("rerun.save_dir", value=str(output_dir)), Parameter("rerun.rollouts_logged", value=8)])
        robot = rclpy.create_node("demo_robot", context=context)
        executor.add_node(ipe)
        executor.add_node(robot)
        spinner.start()

        answers: list[dict] = []

        def on_answer(msg: String) -> None:
            answer = json.loads(msg.data)
            answers.append(answer)
            print(f"\n[/ipe/prediction] answer {len(answers)}:\n{describe(answer)}", flush=True)

        robot.create_subscription(String, "/ipe/prediction", on_answer, LATCHED_QOS)
        scene_pub = robot.create_publisher(MarkerArray, "/ipe/scene", 10)
        _wait(lambda: scene_pub.get_subscription_count() > 0, 30.0, "the node's /ipe/scene subscription")

        tower = load_scenes(example_scene_path())[0]
        print(f"publishing {tower.name} ({len(tower.objects)} blocks, a paper-style tower) as a MarkerArray on "
              f"/ipe/scene; IPE with sigma = {DEFAULT_SIGMA_M:g} m (0.2 block short sides), k = {samples}", flush=True)
        scene_pub.publish(scene_to_markers(tower, "world", robot.get_clock().now().nanoseconds))
        _wait(lambda: len(answers) >= 1, timeout_s, "the IPE prediction")

        print("\nswitching the node to the ground-truth model (ground_truth = true: the scene exactly as given) "
              "and calling /ipe/predict", flush=True)
        results = ipe.set_parameters([Parameter("ground_truth", value=True)])
        if not all(r.successful for r in results):
            raise DemoFailed("setting ground_truth: " + "; ".join(r.reason for r in results))
        client = robot.create_client(Trigger, "/ipe/predict")
        _wait(client.service_is_ready, 30.0, "the /ipe/predict service")
        future = client.call_async(Trigger.Request())
        _wait(future.done, timeout_s, "the /ipe/predict response")
        response = future.result()
        if not response.success:
            raise DemoFailed(f"/ipe/predict failed: {response.message}")
        print(f"\n[/ipe/predict] success: ground truth says fraction fallen = "
              f"{json.loads(response.message)['fall_fraction']:.2f}", flush=True)
        _wait(lambda: len(answers) >= 2, timeout_s, "the ground-truth answer on /ipe/prediction")
        return answers
    finally:
        executor.shutdown(timeout_sec=5.0)
        for node in (ipe, robot):
            if node is not None:
                node.destroy_node()
        rclpy.try_shutdown(context=context)
        if spinner.is_alive():
            spinner.join(10.0)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ipe_ros_demo", description=__doc__.split("\n")[0])
    parser.add_argument("--output-dir", default="ipe_demo_output", help="where the .rrd recordings go")
    parser.add_argument("--samples", type=int, default=DEFAULT_SAMPLES,
                        help=f"Monte Carlo samples k (default {DEFAULT_SAMPLES})")
    parser.add_argument("--workers", type=int, default=default_workers(), help="worker processes (default: CPUs)")
    parser.add_argument("--timeout", type=float, default=300.0, help="give up after this many seconds per step")
    args = parser.parse_args(argv)
    output_dir = Path(args.output_dir).resolve()
    unusable = unusable_dds_profile_file()
    if unusable is not None:  # Fast DDS would wait on it for ever inside rclpy.init
        print(f"ipe_ros_demo: error: {unusable}", file=sys.stderr)
        return 2
    try:
        answers = run(output_dir, args.samples, args.workers, args.timeout)
    except DemoFailed as exc:
        print(f"ipe_ros_demo: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("ipe_ros_demo: interrupted", file=sys.stderr)
        return 130
    recordings = [a["rrd_path"] for a in answers if a.get("rrd_path")]
    print(f"\n{len(answers)} predictions; {len(recordings)} rerun recordings in {output_dir}")
    if recordings:
        print(f"replay what the engine imagined with:  rerun {recordings[0]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
