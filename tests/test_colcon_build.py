"""The package builds with ``colcon build`` in a ROS 2 workspace, as ``ros2 run ipe_ros ipe_node`` expects."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

#: builds the package with colcon
pytestmark = pytest.mark.build

SKIP = shutil.ignore_patterns(".git", ".venv", "build", "install", "log", "__pycache__", "*.egg-info", "*.rrd",
                              ".pytest_cache")
SCRIPTS = ("ipe", "ipe_node", "ipe_lifecycle_node", "ipe_ros_demo", "ipe_send_scene")


def test_colcon_build_installs_the_node_script(tmp_path):
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent))
    if colcon is None:
        pytest.skip("colcon is not installed in this environment (requirements.txt pins colcon-core and colcon-ros)")
    shutil.copytree(REPO, tmp_path / "src" / "ipe_ros", ignore=SKIP)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}")
    result = subprocess.run([colcon, "build", "--event-handlers", "console_direct+"], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    assert "Finished <<< ipe_ros" in result.stdout

    prefix = tmp_path / "install" / "ipe_ros"
    for name in SCRIPTS:
        script = prefix / "lib" / "ipe_ros" / name
        assert script.is_file() and os.access(script, os.X_OK), f"{script} missing"
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "ipe_ros").is_file()
    for shared in ("package.xml", "config/ipe.yaml", "launch/ipe.launch.py"):
        assert (prefix / "share" / "ipe_ros" / shared).is_file(), f"share/ipe_ros/{shared} not installed"

    # The installed copy (not this checkout) is what the workspace's scripts import.
    site = next(prefix.glob("lib/python3*/site-packages"))
    probe = subprocess.run([sys.executable, "-c", "import ipe_ros.ros.node, msg_bridge.markers; print(ipe_ros.ros.node.__file__)"],
                           env=dict(env, PYTHONPATH=str(site)), cwd=tmp_path, capture_output=True, text=True,
                           timeout=120)
    assert probe.returncode == 0, probe.stderr
    assert probe.stdout.strip().startswith(str(site))
    help_run = subprocess.run([str(prefix / "lib" / "ipe_ros" / "ipe"), "--help"], env=dict(env, PYTHONPATH=str(site)),
                              capture_output=True, text=True, timeout=120)
    assert help_run.returncode == 0 and "predict" in help_run.stdout
