"""What a ROS user installs besides the code: package.xml's dependencies, config/ipe.yaml, the launch file."""

from __future__ import annotations

import ast
import math
import re
import sys
import types
import xml.etree.ElementTree as ET

import pytest
import yaml

from tests.conftest import REPO
from tests.ros_harness import RosHarness

#: Python modules we import that are not ROS packages, and their rosdep keys (rosdistro rosdep/python.yaml).
#: None: no rosdep key exists; the module is installed from requirements.txt and package.xml says so.
PYTHON_ROSDEP_KEYS = {
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "matplotlib": "python3-matplotlib",
    "pybullet": "python3-pybullet-pip",
    "trimesh": "python3-trimesh",
    "coacd": None,
    "tqdm": "python3-tqdm",
    "PIL": "python3-pil",
    "yaml": "python3-yaml",
    "rerun": None,
    "distributed": None,
    "dask": None,
}
OUR_PACKAGES = {"ipe_ros", "msg_bridge"}


def _imported_top_level_modules() -> dict[str, str]:
    """Every top-level module the installed code imports (package and launch file; not tests or benchmarks)
    -> a file using it."""
    found: dict[str, str] = {}
    for folder in (*sorted(OUR_PACKAGES), "launch"):
        for path in sorted((REPO / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                    [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else []
                for name in names:
                    found.setdefault(name.split(".")[0], str(path.relative_to(REPO)))
    return {m: f for m, f in found.items() if m not in sys.stdlib_module_names and m not in OUR_PACKAGES}


def _declared(kinds=("depend", "exec_depend")) -> set[str]:
    root = ET.parse(REPO / "package.xml").getroot()
    return {e.text.strip() for kind in kinds for e in root.findall(kind)}


def test_package_xml_declares_every_imported_ros_package_and_python_library():
    declared = _declared()
    missing = []
    for module, where in sorted(_imported_top_level_modules().items()):
        if module in PYTHON_ROSDEP_KEYS:
            key = PYTHON_ROSDEP_KEYS[module]
            if key is not None and key not in declared:
                missing.append(f"{key} (for `import {module}` in {where})")
        elif module not in declared:  # a ROS package: its rosdep key is its own name
            missing.append(f"{module} (imported in {where}; if it is not a ROS package, add its rosdep key to "
                           "PYTHON_ROSDEP_KEYS)")
    assert not missing, "package.xml lacks <exec_depend> for: " + "; ".join(missing)
    # and nothing declared that the code does not use
    imported = _imported_top_level_modules()
    needed = {PYTHON_ROSDEP_KEYS[m] if m in PYTHON_ROSDEP_KEYS else m for m in imported}
    assert _declared(("exec_depend",)) <= needed, f"declared but not imported: {_declared(('exec_depend',)) - needed}"
    for pip_only in ("rerun-sdk", "dask/distributed"):
        assert pip_only in (REPO / "package.xml").read_text(), f"package.xml must say how {pip_only} is installed"


def _yaml_parameters() -> dict:
    document = yaml.safe_load((REPO / "config" / "ipe.yaml").read_text())
    return document["/**"]["ros__parameters"]


def test_config_yaml_is_written_from_the_table_of_inputs():
    """config/ipe.yaml is what ``python -m ipe_ros.ros.params`` writes from the declared parameters."""
    from ipe_ros.ros.params import config_yaml

    assert (REPO / "config" / "ipe.yaml").read_text() == config_yaml(), \
        "config/ipe.yaml is stale: python -m ipe_ros.ros.params > config/ipe.yaml"


def test_config_yaml_lists_every_parameter_with_its_default():
    from ipe_ros.ros.params import all_parameters

    declared = all_parameters()  # the built-in queries' own parameters too
    shipped = _yaml_parameters()
    text = (REPO / "config" / "ipe.yaml").read_text()
    for spec in declared:
        if spec.name == "workers":  # machine-dependent default: shown commented out
            assert re.search(r"^\s*# workers: \d+$", text, re.M), "config/ipe.yaml must show workers (commented)"
            continue
        assert spec.name in shipped, f"config/ipe.yaml lacks {spec.name}"
        value, default = shipped[spec.name], spec.default
        same = (math.isnan(value) and math.isnan(default)) if isinstance(default, float) and math.isnan(default) \
            else value == default
        assert same, f"config/ipe.yaml: {spec.name} is {value!r}, the node's default is {default!r}"
    assert set(shipped) <= {spec.name for spec in declared}, set(shipped) - {s.name for s in declared}


@pytest.mark.ros
def test_the_node_reads_a_params_file(tmp_path):
    """--ros-args --params-file, as ``ros2 run`` and the launch file pass it (rcl's own YAML parser)."""
    changed = (REPO / "config" / "ipe.yaml").read_text().replace("    samples: 48", "    samples: 7") \
        .replace('    preset: "default"', '    preset: "fine"').replace("    # workers: 2", "    workers: 1")
    custom = tmp_path / "custom.yaml"
    custom.write_text(changed)
    ros = RosHarness()
    try:
        from ipe_ros.ros.node import IpeNode

        shipped = IpeNode(context=ros.context, cli_args=["--ros-args", "--params-file", str(REPO / "config/ipe.yaml")],
                          node_name="ipe_shipped")
        ros._nodes.append(shipped)
        assert math.isnan(shipped.get_parameter("force_direction_deg").value)
        assert shipped.get_parameter("gravity_aligned_frames").value == ["world", "map", "odom"]
        node = IpeNode(context=ros.context, cli_args=["--ros-args", "--params-file", str(custom)])
        ros._nodes.append(node)
        config = node.service.config
        assert (config.request.model.samples, config.request.settings.name,
                node.get_parameter("workers").value) == (7, "fine", 1)
    finally:
        ros.close()


class _Recorder:
    """Stands in for a launch class: remembers how it was constructed."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def test_launch_file_starts_ipe_node_with_the_shipped_parameters(monkeypatch):
    """launch and launch_ros have no pip wheels here: the file runs against recording stand-ins."""
    fakes = {
        "launch": {"LaunchDescription": _Recorder},
        "launch.actions": {"DeclareLaunchArgument": _Recorder},
        "launch.substitutions": {"LaunchConfiguration": _Recorder},
        "launch_ros": {},
        "launch_ros.actions": {"Node": _Recorder},
        "ament_index_python": {},
        "ament_index_python.packages": {"get_package_share_directory": lambda name: f"/opt/share/{name}"},
    }
    for name, attributes in fakes.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**attributes))
    path = REPO / "launch" / "ipe.launch.py"
    namespace: dict = {"__file__": str(path), "__name__": "ipe_launch"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)
    description = namespace["generate_launch_description"]()
    [actions] = description.args
    arguments = {a.args[0]: a.kwargs["default_value"] for a in actions if "default_value" in a.kwargs}
    assert arguments["params_file"] == "/opt/share/ipe_ros/config/ipe.yaml"
    assert arguments["discovery_range"] == "LOCALHOST"
    [node] = [a for a in actions if "executable" in a.kwargs]
    assert (node.kwargs["package"], node.kwargs["executable"], node.kwargs["name"]) == ("ipe_ros", "ipe_node", "ipe")
    assert [p.args[0] for p in node.kwargs["parameters"]] == ["params_file"]
    setup = (REPO / "setup.py").read_text()
    assert '"config/ipe.yaml"' in setup and '"launch/ipe.launch.py"' in setup and '"ipe_node = ' in setup
