"""Plugins from installed packages (engine/plugins.py): a package's entry points in the groups
ipe_ros.queries and ipe_ros.perceptions are found by ``ipe`` and ``ipe_node`` without editing them.
The package here is a dist-info folder on the path, naming this repository's test plugins
(tests/query_plugin_tilt.py, tests/perception_plugin_detections.py) and one that cannot load."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ipe_ros.engine.perceptions import perception_names, unregister_perception
from ipe_ros.engine.plugins import load_plugins
from ipe_ros.engine.query import QUERIES
from ipe_ros.engine.query.spec import unregister
from ipe_ros.engine.scene.examples import example_scene_path

REPO = Path(__file__).resolve().parents[1]
BROKEN = ("plugin broken (tests.no_such_module:SOURCE, ipe_ros.perceptions) not loaded: ModuleNotFoundError: No "
          "module named 'tests.no_such_module'")


@pytest.fixture
def installed(tmp_path):
    """A distribution declaring the plugins, on the path (as pip would install it)."""
    info = tmp_path / "ipe_test_plugins-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: ipe-test-plugins\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[ipe_ros.perceptions]\ndetections = tests.perception_plugin_detections:SOURCE\n"
        "broken = tests.no_such_module:SOURCE\n\n[ipe_ros.queries]\ntilt = tests.query_plugin_tilt:QUERY\n")
    sys.path.insert(0, str(tmp_path))
    yield tmp_path
    sys.path.remove(str(tmp_path))
    unregister_perception("detections")
    unregister("tilt")


def test_installed_plugins_are_registered_and_a_broken_one_is_named_and_skipped(installed):
    warnings: list[str] = []
    assert load_plugins(warnings.append) == ("ipe_ros.queries:tilt", "ipe_ros.perceptions:detections")
    assert warnings == [BROKEN]
    assert "detections" in perception_names() and "tilt" in QUERIES
    assert load_plugins(warnings.append) == ("ipe_ros.queries:tilt", "ipe_ros.perceptions:detections")  # once is enough


def _env(installed: Path) -> dict:
    from tests.ros_harness import domain_id_for_tests

    return dict(os.environ, PYTHONPATH=f"{installed}{os.pathsep}{REPO}", ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                ROS_DOMAIN_ID=str(domain_id_for_tests()))


def test_ipe_finds_installed_plugins_and_its_workers_run_them(installed):
    detections = installed / "detections.json"
    detections.write_text(json.dumps({"detections": [{"object": "block9", "position_m": [0.0, 0.0],
                                                      "covariance_m2": [[1e-4, 0.0], [0.0, 1e-4]]}]}))
    done = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "predict", str(example_scene_path()), "--perception",
                           "detections", "--detections", str(detections), "--query", "fall,tilt", "--samples", "4",
                           "--workers", "2", "--json", "--no-self-check"], env=_env(installed), capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines()[0] == f"ipe: warning: {BROKEN}"
    record = json.loads(done.stdout.strip().splitlines()[-1])
    assert record["request"]["perception"]["kind"] == "detections" and record["samples"] == 4
    assert record["tilt_probability"] is not None  # the plugin query, answered in the workers


@pytest.mark.ros
def test_ipe_node_finds_installed_plugins(installed):
    proc = subprocess.Popen([sys.executable, "-m", "ipe_ros.ros.node", "--ros-args", "-p", "perception:=detections",
                             "-p", "queries:=[fall, tilt]", "-p", "workers:=0"], env=_env(installed),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    try:
        for line in proc.stdout:  # until it is ready (a perception it did not know would end it with exit 2)
            lines.append(line)
            if "ready: k = " in line:
                break
        proc.send_signal(signal.SIGTERM)
        rest, _ = proc.communicate(timeout=30.0)
    finally:
        if proc.poll() is None:
            proc.kill()  # only our own child, by its pid
            proc.wait()
    output = "".join(lines) + rest
    assert proc.returncode == 0, output
    assert f"ipe_node: warning: {BROKEN}" in output and "ready: k = " in output, output
