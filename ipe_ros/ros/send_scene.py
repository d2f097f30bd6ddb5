"""``ipe_send_scene FILE``: publish one scene file to a running ``ipe_node`` and print its answer.

The ``ros2`` command line is not available as pip wheels; this is the small rclpy helper that does
``ros2 topic pub /ipe/scene_json`` + ``ros2 topic echo /ipe/prediction`` for one scene:

    ipe_send_scene my_scene.json                 # the file's only scene
    ipe_send_scene towers.csv --scene tower_00015 --node /ipe --timeout 120

The scene is validated here first (exit status 2 with the field at fault), then published; the
answer is the first one on ``<node>/prediction`` for this scene name stamped after the send.
Exit status 1 when no answer comes in time, 3 when the node answers with an error (the scene refused
by its configuration, or the prediction failed): the error answer is printed all the same.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # DDS stays on this machine

import rclpy  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from msg_bridge.json_text import scene_to_string  # noqa: E402

from ..engine import load_scenes  # noqa: E402
from .node import LATCHED_QOS  # noqa: E402
from .process_setup import unusable_dds_profile_file  # noqa: E402

EXIT_NO_ANSWER, EXIT_BAD_INPUT, EXIT_ERROR_ANSWER = 1, 2, 3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ipe_send_scene", description="Publish a scene to ipe_node and print the answer.")
    parser.add_argument("path", help="a JSON scene file (ipe_ros.scene/2 or /1) or a paper-format tower CSV")
    parser.add_argument("--scene", default=None, help="which scene/tower of the file (needed when it holds several)")
    parser.add_argument("--node", default="/ipe", help="the node's fully qualified name (default /ipe)")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds to wait for the answer")
    args = parser.parse_args(argv)
    try:
        scenes = load_scenes(args.path, towers=[args.scene] if args.scene else None)
    except (OSError, ValueError) as exc:
        print(f"ipe_send_scene: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if len(scenes) != 1:
        names = ", ".join(s.name for s in scenes[:5]) + (" ..." if len(scenes) > 5 else "")
        print(f"ipe_send_scene: error: {args.path} holds {len(scenes)} scenes ({names}); choose one with --scene",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    scene = scenes[0]
    node_name = "/" + args.node.strip("/")
    unusable = unusable_dds_profile_file()
    if unusable is not None:  # Fast DDS would wait on it for ever inside rclpy.init
        print(f"ipe_send_scene: error: {unusable}", file=sys.stderr)
        return EXIT_BAD_INPUT

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=int(os.environ.get("ROS_DOMAIN_ID", "0") or 0))
    node = rclpy.create_node("ipe_send_scene", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    answer: dict | None = None
    try:
        sent_ns = 0

        def on_answer(msg: String) -> None:
            nonlocal answer
            data = json.loads(msg.data)
            stamp_ns = data["stamp"]["sec"] * 1_000_000_000 + data["stamp"]["nanosec"]
            if sent_ns and data.get("scene_id") == scene.name and stamp_ns >= sent_ns:
                answer = data

        node.create_subscription(String, f"{node_name}/prediction", on_answer, LATCHED_QOS)
        pub = node.create_publisher(String, f"{node_name}/scene_json", 10)
        deadline = time.monotonic() + args.timeout
        while pub.get_subscription_count() == 0:
            if time.monotonic() > deadline:
                print(f"ipe_send_scene: nobody subscribes to {node_name}/scene_json within {args.timeout:g} s; "
                      "is ipe_node running with the same ROS_DOMAIN_ID?", file=sys.stderr)
                return EXIT_NO_ANSWER
            executor.spin_once(timeout_sec=0.05)
        sent_ns = node.get_clock().now().nanoseconds
        pub.publish(scene_to_string(scene))
        print(f"sent {scene.name} ({len(scene.objects)} objects) to {node_name}/scene_json; waiting for the answer",
              file=sys.stderr)
        while answer is None:
            if time.monotonic() > deadline:
                print(f"ipe_send_scene: no answer on {node_name}/prediction within {args.timeout:g} s",
                      file=sys.stderr)
                return EXIT_NO_ANSWER
            executor.spin_once(timeout_sec=0.1)
        print(json.dumps(answer, indent=2, sort_keys=True))
        if "error" in answer:
            print(f"ipe_send_scene: the node answered with an error: {answer['error']}", file=sys.stderr)
            return EXIT_ERROR_ANSWER
        return 0
    except KeyboardInterrupt:
        return 130
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


if __name__ == "__main__":
    sys.exit(main())
