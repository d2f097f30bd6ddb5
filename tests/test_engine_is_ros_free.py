"""The engine and the analyses must import and run without rclpy or any ROS message package."""

import json
import subprocess
import sys

CHECK = r"""
import json, sys
from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.cli import example_scene_path
import ipe_ros.analysis.experiments
scene = load_scenes(example_scene_path())[0]
p = predict(scene, ModelConfig(sigma_m=0.04, samples=2), preset("default"), QuerySpec())
ros = sorted(m for m in sys.modules if m.split(".")[0] in {"rclpy", "rosidl_runtime_py", "rpyutils"}
             or m.split(".")[0].endswith("_msgs") or m.split(".")[0].endswith("_srvs")
             or m.split(".")[0] == "msg_bridge")
print(json.dumps({"ros": ros, "samples": p.samples}))
"""


def test_engine_cli_and_analyses_import_no_ros_module():
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, timeout=120, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"ros": [], "samples": 2}
