"""``ipe_node`` as its own process: SIGINT and SIGTERM end it cleanly, with no stray worker processes."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.ros_harness import domain_id_for_tests, wait_until

#: starts rclpy (a Context of its own, DDS on loopback)
pytestmark = pytest.mark.ros


def _children(pid: int) -> set[int]:
    """Direct children of ``pid``, read from /proc (no psutil needed)."""
    out = set()
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # the command name may contain spaces or parentheses: the ppid follows the last ')'
        fields = stat[stat.rfind(")") + 2:].split()
        if int(fields[1]) == pid:
            out.add(int(entry.name))
    return out


def _descendants(pid: int) -> set[int]:
    found, todo = set(), [pid]
    while todo:
        for child in _children(todo.pop()):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return state[state.rfind(")") + 2] != "Z"  # a zombie has ended


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_ends_the_node_and_its_workers(signum):
    if sys.platform != "linux":
        pytest.skip("reads the process tree from /proc")
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    proc = subprocess.Popen([sys.executable, "-m", "ipe_ros.ros.node", "--ros-args", "-p", "workers:=2",
                             "-p", "samples:=4"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        # the pool's workers (forked by the forkserver, itself a child of the node) are up
        wait_until(lambda: len(_descendants(proc.pid)) >= 3, 60.0, "the node's worker processes")
        family = _descendants(proc.pid)
        proc.send_signal(signum)
        output, _ = proc.communicate(timeout=30.0)
    finally:
        if proc.poll() is None:
            proc.kill()  # only our own child, by its pid
            proc.wait()
    assert proc.returncode == 0, output
    wait_until(lambda: not any(_alive(pid) for pid in family), 20.0,
               f"the node's child processes {sorted(family)} to end")
    assert "ready: k = 4" in output


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_mid_prediction_and_mid_question_ends_the_node_within_2_s_leaving_no_process(signum):
    """A long prediction (paper settings, k = 400) and a long question (a support graph, k = 400) are
    running when the signal comes: the node must wait for neither; workers still busy are terminated."""
    if sys.platform != "linux":
        pytest.skip("reads the process tree from /proc")
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    proc = subprocess.Popen([sys.executable, "-m", "ipe_ros.ros.node", "--ros-args", "-p", "workers:=2",
                             "-p", "samples:=400", "-p", "preset:=paper", "-p", "budget_s:=600.0"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        wait_until(lambda: len(_descendants(proc.pid)) >= 3, 60.0, "the node's worker processes")
        sent = subprocess.run([sys.executable, "-m", "ipe_ros.ros.send_scene", "ipe_ros/data/example_tower.json",
                               "--timeout", "5"], env=env, capture_output=True, text=True, timeout=120)
        assert "sent example_tower" in sent.stderr and sent.returncode != 0, sent.stderr  # ~90 s of work runs
        from std_msgs.msg import String

        from ipe_ros.ros.node import ASK_QOS
        from tests.ros_harness import RosHarness

        asker = RosHarness()
        try:
            asker.publisher(String, "/ipe/ask", ASK_QOS).publish(String(data=json.dumps(
                {"id": "long", "question": "support", "samples": 400})))  # about the scene sent: minutes of work
            time.sleep(1.0)  # a fixed wait is all a test outside the process has: the question starts in ms
        finally:
            asker.close()
        family = _descendants(proc.pid)
        sent_at = time.monotonic()
        proc.send_signal(signum)
        output, _ = proc.communicate(timeout=30.0)
        took = time.monotonic() - sent_at
    finally:
        if proc.poll() is None:
            proc.kill()  # only our own child, by its pid
            proc.wait()
    assert proc.returncode == 0, output
    assert took < 2.0, f"the node took {took:.1f} s to end"
    wait_until(lambda: not any(_alive(pid) for pid in family), 5.0, f"the node's child processes {sorted(family)} to end")
    assert "Traceback" not in output, output


def test_send_scene_helper_gets_the_answer_from_a_running_node(tmp_path):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    node = subprocess.Popen([sys.executable, "-m", "ipe_ros.ros.node", "--ros-args", "-p", "workers:=1",
                             "-p", "samples:=3", "-p", "max_objects:=12"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    from ipe_ros.engine import load_scenes
    from ipe_ros.engine.scene.format import write_scenes
    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    too_big = dataclasses.replace(tower, name="too_big", objects=tower.objects + tuple(
        dataclasses.replace(b, name=f"{b.name}_again", position_m=(b.position_m[0] + 2.0, *b.position_m[1:]))
        for b in tower.objects[:3]))
    write_scenes([too_big], tmp_path / "too_big.json")
    try:
        sent = subprocess.run([sys.executable, "-m", "ipe_ros.ros.send_scene", "ipe_ros/data/example_tower.json",
                               "--timeout", "120"], env=env, capture_output=True, text=True, timeout=180)
        # valid as a file, refused by this node's max_objects: the client hears why at once
        refused = subprocess.run([sys.executable, "-m", "ipe_ros.ros.send_scene", str(tmp_path / "too_big.json"),
                                  "--timeout", "120"], env=env, capture_output=True, text=True, timeout=180)
    finally:
        node.send_signal(signal.SIGINT)
        try:
            node.communicate(timeout=30.0)
        finally:
            if node.poll() is None:
                node.kill()
                node.wait()
    assert sent.returncode == 0, sent.stderr
    answer = json.loads(sent.stdout)
    assert answer["scene_id"] == "example_tower" and answer["samples"] == 3 and answer["frame_id"] == "world"
    assert refused.returncode == 3, refused.stderr
    error = json.loads(refused.stdout)
    assert (error["scene_id"], error["refused_on"]) == ("too_big", "/ipe/scene_json")
    assert error["error"] == "objects: 13 objects exceed the maximum of 12; split the scene or raise max_objects"
    assert refused.stderr.endswith(f"ipe_send_scene: the node answered with an error: {error['error']}\n")


def test_send_scene_refuses_a_bad_file_before_publishing(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "ipe_ros.scene/1"')
    result = subprocess.run([sys.executable, "-m", "ipe_ros.ros.send_scene", str(bad)], capture_output=True, text=True,
                            timeout=120, env=dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST"))
    assert result.returncode == 2
    assert result.stderr.strip() == "ipe_send_scene: error: json: malformed JSON at line 1 column 29: Expecting ',' delimiter"


def test_the_demo_runs_end_to_end_and_writes_recordings(tmp_path):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    result = subprocess.run([sys.executable, "-m", "ipe_ros.ros.demo", "--samples", "4", "--workers", "1",
                             "--output-dir", str(tmp_path)], env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert "[/ipe/predict] success: ground truth says fraction fallen = 0.00" in result.stdout
    assert sorted(p.name for p in tmp_path.glob("*.rrd")) == [
        "ipe_000001_scene1_example_tower.rrd", "ipe_000002_scene1_example_tower.rrd"]


@pytest.mark.parametrize("override, message", [
    ("samples:=0", "ipe_node: error: Invalid parameter value (0) for parameter. Reason: Parameter samples out of "
                   "range. Min: 1, Max: 100000, value: 0: samples"),
    ("queries:=[nope]", "ipe_node: error: queries: unknown query 'nope'; choose from fall, any_fall, direction, far, bump, "
                        "contact, rest, final_pose, tipped"),
])
def test_a_bad_parameter_override_ends_the_node_with_one_line(override, message):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()))
    result = subprocess.run([sys.executable, "-m", "ipe_ros.ros.node", "--ros-args", "-p", override], env=env,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == message


def test_the_node_runs_on_its_own_dds_profiles_unless_the_environment_names_its_own():
    """rmw_fastrtps's default payload memory keeps every buffer at the largest message it carried: the
    node's own profiles free each payload when its message is taken (ipe_ros/ros/fastdds_node.xml)."""
    import xml.etree.ElementTree as ElementTree

    from ipe_ros.ros.process_setup import FASTDDS_PROFILES, use_node_dds_profiles

    environ: dict[str, str] = {}
    assert use_node_dds_profiles(environ)
    assert environ == {"FASTRTPS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILES),
                       "FASTDDS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILES), "RMW_FASTRTPS_USE_QOS_FROM_XML": "1"}
    for own in ({"FASTRTPS_DEFAULT_PROFILES_FILE": "/etc/mine.xml"}, {"RMW_FASTRTPS_USE_QOS_FROM_XML": "0"},
                {"RMW_IMPLEMENTATION": "rmw_cyclonedds_cpp"}):
        environ = dict(own)
        assert not use_node_dds_profiles(environ) and environ == own
    policies = [e.text for e in ElementTree.parse(FASTDDS_PROFILES).iter()
                if e.tag.endswith("historyMemoryPolicy")]
    assert policies == ["DYNAMIC", "DYNAMIC"]  # writers and readers


def test_a_dds_profile_file_fast_dds_would_hang_on_ends_the_node_at_once_naming_it(tmp_path):
    """Issue 76: a Fast DDS profiles file that is a FIFO hung start-up silently inside rclpy.init (Fast
    DDS waits for a writer). Now the node ends at once, exit 2, naming the variable and the fix;
    so for a device, a folder, and a FIFO at the default profile name in the working folder."""
    from ipe_ros.ros.process_setup import unusable_dds_profile_file

    fifo = tmp_path / "profiles.xml"
    os.mkfifo(fifo)
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", ROS_DOMAIN_ID=str(domain_id_for_tests()),
               FASTRTPS_DEFAULT_PROFILES_FILE=str(fifo))
    result = subprocess.run([sys.executable, "-m", "ipe_ros.ros.node"], env=env, capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines()[-1] == (
        f"ipe_node: error: FASTRTPS_DEFAULT_PROFILES_FILE: {fifo} is a FIFO, not a file (Fast DDS would wait on it "
        "for ever at start-up); point it at a profiles XML file, or unset it")
    assert unusable_dds_profile_file({"FASTDDS_ENVIRONMENT_FILE": "/dev/zero"}, tmp_path / "none").startswith(
        "FASTDDS_ENVIRONMENT_FILE: /dev/zero is a device")
    assert "is a folder" in unusable_dds_profile_file({"FASTDDS_DEFAULT_PROFILES_FILE": str(tmp_path)}, tmp_path / "none")
    os.mkfifo(tmp_path / "DEFAULT_FASTRTPS_PROFILES.xml")
    assert unusable_dds_profile_file({}, tmp_path).startswith("DEFAULT_FASTRTPS_PROFILES.xml in the working folder: ")
    (tmp_path / "mine.xml").write_text("<profiles/>")
    assert unusable_dds_profile_file({"FASTRTPS_DEFAULT_PROFILES_FILE": str(tmp_path / "mine.xml"),
                                      "FASTDDS_DEFAULT_PROFILES_FILE": str(tmp_path / "missing.xml")},
                                     tmp_path / "none") is None  # a file, and a missing one (Fast DDS says so)


def test_the_node_keeps_large_buffers_out_of_the_heap_unless_told_otherwise():
    """A fixed mmap threshold (glibc): 1-2 MB messages are returned to the system when freed."""
    from ipe_ros.ros.process_setup import return_large_buffers_to_the_system

    assert return_large_buffers_to_the_system({}) is True  # glibc here
    assert return_large_buffers_to_the_system({"MALLOC_MMAP_THRESHOLD_": "65536"}) is False
