"""The layers of the package and the imports each may make (ipe_ros/__init__.py draws the map).

Read statically from the source (every import statement, also inside functions), and checked at run
time for the ROS-free layers: importing and running them loads no ROS module.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
ROS_PACKAGES = ("rclpy", "rcl_interfaces", "builtin_interfaces", "rosidl_runtime_py", "rpyutils")

#: layer -> (its files, the internal modules it must never import)
LAYERS = {
    "engine": ("ipe_ros/engine", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.cli", "ipe_ros.analysis", "ipe_ros.viz",
                                  "msg_bridge", "rerun")),
    "viz": ("ipe_ros/viz", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.cli", "ipe_ros.analysis", "msg_bridge")),
    # progress display is the caller's (analysis.reporting): the analyses never import the CLI's bars
    "analysis": ("ipe_ros/analysis", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.cli", "ipe_ros.progress", "msg_bridge")),
    "service": ("ipe_ros/service", ("ipe_ros.ros", "ipe_ros.cli", "ipe_ros.analysis", "msg_bridge")),
    "cli": ("ipe_ros/cli.py", ("ipe_ros.ros", "ipe_ros.service", "msg_bridge")),
    "cli_ask": ("ipe_ros/cli_ask.py", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.analysis", "msg_bridge")),
    "progress": ("ipe_ros/progress.py", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.cli", "ipe_ros.engine",
                                         "ipe_ros.analysis", "ipe_ros.viz", "msg_bridge")),
    "msg_bridge": ("msg_bridge", ("ipe_ros.ros", "ipe_ros.service", "ipe_ros.cli", "ipe_ros.analysis", "rclpy")),
    # the node: the only layer that imports rclpy; it serves the engine, never the CLI or the analyses
    "ros": ("ipe_ros/ros", ("ipe_ros.cli", "ipe_ros.cli_ask", "ipe_ros.analysis", "ipe_ros.progress")),
}
#: layers that talk ROS (message classes; the node also rclpy)
ROS_LAYERS = ("msg_bridge", "ros")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> set[str]:
    """Absolute names of every module a file imports (relative imports resolved)."""
    package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def files_of(layer_path: str) -> list[Path]:
    path = REPO / layer_path
    return [path] if path.is_file() else sorted(path.rglob("*.py"))


def _is_ros(module: str) -> bool:
    top = module.split(".")[0]
    return top in ROS_PACKAGES or top.endswith("_msgs") or top.endswith("_srvs")


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


@pytest.mark.parametrize("layer", sorted(LAYERS))
def test_each_layer_imports_only_what_it_may(layer):
    layer_path, forbidden = LAYERS[layer]
    ros_free = layer not in ROS_LAYERS
    bad = []
    for path in files_of(layer_path):
        for module in sorted(imports_of(path)):
            if any(_within(module, f) for f in forbidden) or (ros_free and _is_ros(module)):
                bad.append(f"{path.relative_to(REPO)} imports {module}")
    assert bad == [], f"layer {layer!r} breaks its import rule"


def test_only_the_ros_layer_imports_rclpy():
    users = sorted(str(path.relative_to(REPO)) for path in [*REPO.joinpath("ipe_ros").rglob("*.py"),
                                                              *REPO.joinpath("msg_bridge").rglob("*.py")]
                   if any(_within(m, "rclpy") for m in imports_of(path)))
    assert users and all(u.startswith("ipe_ros/ros/") for u in users), users


def test_the_rule_reader_sees_relative_and_nested_imports():
    # the checker itself must not be blind: a relative import inside a function is found
    package = REPO / "ipe_ros" / "engine"
    probe = package / "_layer_probe_tmp.py"
    probe.write_text("def f():\n    from ..ros import node\n    import rclpy.node\n")
    try:
        assert {"ipe_ros.ros", "ipe_ros.ros.node", "rclpy.node"} <= imports_of(probe)
    finally:
        probe.unlink()


RUNTIME_CHECK = r"""
import json, sys
from ipe_ros.engine import ModelConfig, QuerySpec, Request, load_scenes, predict, preset
from ipe_ros.engine.scene.examples import example_scene_path
import ipe_ros.analysis.experiments, ipe_ros.cli, ipe_ros.service, ipe_ros.viz.palette
scene = load_scenes(example_scene_path())[0]
p = predict(scene, Request(model=ModelConfig(sigma_m=0.04, samples=2), settings=preset("default"), query=QuerySpec()))
ros = sorted(m for m in sys.modules if m.split(".")[0] in {"rclpy", "rosidl_runtime_py", "rpyutils"}
             or m.split(".")[0].endswith("_msgs") or m.split(".")[0].endswith("_srvs")
             or m.split(".")[0] in {"msg_bridge", "rcl_interfaces", "builtin_interfaces"})
print(json.dumps({"ros": ros, "samples": p.samples}))
"""


def test_engine_cli_service_and_analyses_run_without_loading_ros():
    out = subprocess.run([sys.executable, "-c", RUNTIME_CHECK], capture_output=True, text=True, timeout=120, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"ros": [], "samples": 2}


@pytest.mark.parametrize("module", ["ipe_ros.cli", "ipe_ros.ros.node"])
def test_starting_the_cli_or_the_node_imports_nothing_heavy_it_may_not_need(module):
    """scipy.stats (0.5-1 s), matplotlib, rerun, pybullet and dask load on first use, not at start:
    every CLI call and node start would pay for them."""
    heavy = ("scipy.stats", "matplotlib", "rerun", "pybullet", "dask")
    start = "import ipe_ros.cli as c; c.build_parser()" if module == "ipe_ros.cli" else f"import {module}"
    code = f"import sys; {start}; print(' '.join(m for m in {heavy!r} if m in sys.modules))"
    loaded = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert loaded.returncode == 0, loaded.stderr
    assert loaded.stdout.strip() == ""


# -- one house: no import circles, no private names across modules -----------------------------------------
PACKAGES = ("ipe_ros", "msg_bridge")


def _internal_modules() -> dict[str, Path]:
    return {_module_name(path): path for package in PACKAGES for path in sorted((REPO / package).rglob("*.py"))}


def _known(module: str, known) -> str | None:
    """The longest internal module a dotted import name falls in (None: not ours)."""
    while module and module not in known:
        module = module.rpartition(".")[0]
    return module or None


def imported_modules(path: Path, known) -> set[str]:
    """The internal modules a file imports (function-local and TYPE_CHECKING imports included).
    ``from package import module`` imports the module, not the package's ``__init__`` (which Python
    has begun importing already); ``from package import name`` imports the package."""
    here = _module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    targets = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets.update(_known(alias.name, known) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            names = [f"{base}.{alias.name}" for alias in node.names]
            targets.update(n for n in names if n in known)
            if any(n not in known for n in names):
                targets.add(_known(base, known))
    return {t for t in targets if t and t != here}


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """module -> the internal modules it imports."""
    return {name: imported_modules(path, modules) for name, path in modules.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for start in sorted(graph):
        if start in index:
            continue
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        work = [(start, iter(sorted(graph[start])))]
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph.get(successor, ())))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def private_names_across_modules(path: Path, known) -> list[str]:
    """``from ours import _name`` and ``ours_module._name`` in one file, for modules other than itself."""
    here = _module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    bound: dict[str, str] = {}  # local name -> the internal module it is
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                if full in known:
                    bound[alias.asname or alias.name] = full
                elif _known(base, known) and base != here and alias.name.startswith("_") \
                        and not alias.name.startswith("__"):
                    found.append(f"{here} imports {alias.name} from {base}")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in known and alias.asname:
                    bound[alias.asname] = alias.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in bound \
                and node.attr.startswith("_") and not node.attr.startswith("__") and bound[node.value.id] != here:
            found.append(f"{here} reads {node.attr} of {bound[node.value.id]}")
    return found


def test_no_import_circles_inside_the_package():
    """A circle means two modules can be understood, tested and changed only together; the checker
    reads imports inside functions and under TYPE_CHECKING too (a circle hidden there is one still)."""
    assert circles(import_graph(_internal_modules())) == []


def test_no_private_name_is_used_outside_its_module():
    """A name that begins with ``_`` is its module's own: another module that needs it needs it public."""
    modules = _internal_modules()
    found = [line for path in modules.values() for line in private_names_across_modules(path, modules)]
    assert found == []


def test_no_name_mangled_private_of_another_class_is_touched():
    """``_Class__name`` is a class's most private name (rclpy's lifecycle state change, say): code
    that overrides or calls it works only with one version's private layout."""
    mangled = re.compile(r"\b_[A-Za-z]\w*?__\w+")
    found = [f"{path.relative_to(REPO)}:{number}" for path in _internal_modules().values()
             for number, line in enumerate(path.read_text().splitlines(), 1) if mangled.search(line)]
    assert found == []


def test_the_circle_and_private_name_checkers_are_not_blind(tmp_path):
    pkg = tmp_path / "ipe_ros"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import thing\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .c import other\n")
    (pkg / "c.py").write_text("def f():\n    from . import a\n    return a._hidden\n")
    (pkg / "d.py").write_text("from .a import _secret\n")
    global REPO
    saved, REPO = REPO, tmp_path
    try:
        modules = {_module_name(p): p for p in sorted(pkg.rglob("*.py"))}
        assert circles(import_graph(modules)) == [["ipe_ros.a", "ipe_ros.b", "ipe_ros.c"]]
        found = sorted(line for p in modules.values() for line in private_names_across_modules(p, modules))
        assert found == ["ipe_ros.c reads _hidden of ipe_ros.a", "ipe_ros.d imports _secret from ipe_ros.a"]
    finally:
        REPO = saved


ROOM_LIST = re.compile(r"^\d+\. (\w+): (.*)$")


def engine_rooms() -> dict[str, int]:
    """docs/architecture.md's rooms of the engine, bottom first: a room's name (a package of
    ipe_ros/engine, or at the foundation its modules) -> its level."""
    text = (REPO / "docs" / "architecture.md").read_text()
    block = text[text.index("<!-- rooms: tests/test_layers.py reads this list -->"):].split("\n\n")[0]
    levels: dict[str, int] = {}
    for level, line in enumerate(m for m in map(ROOM_LIST.match, block.splitlines()[1:]) if m):
        room, rest = line.group(1), line.group(2)
        names = [n.strip() for n in rest.split("(")[0].split(",")] if room in ("foundation", "front") else [room]
        levels.update({n.strip("`"): level for n in names})
    return levels


def _room_of(module: str) -> str | None:
    parts = module.split(".")
    if parts[:2] != ["ipe_ros", "engine"]:
        return None
    return "__init__" if len(parts) == 2 else parts[2]


def room_imports(path: Path) -> set[str]:
    """The engine modules a file imports, as rooms see them: ``from .. import simulation`` imports
    the simulation package, not the engine's ``__init__``."""
    found = set()
    for name in imports_of(path):
        found.add(name)
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.level and not node.module:
            package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rpartition(".")[0]
            base = ".".join(package.split(".")[:len(package.split(".")) - (node.level - 1)])
            if all((REPO / Path(*f"{base}.{a.name}".split("."))).is_dir()
                   or (REPO / Path(*f"{base}.{a.name}".split("."))).with_suffix(".py").is_file() for a in node.names):
                found.discard(base)  # every name imported is a module of that package
    return found


def upward_room_imports(levels: dict[str, int], root: Path = REPO / "ipe_ros" / "engine") -> list[str]:
    found = []
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        room = "__init__" if parts == ("__init__",) else parts[0]
        if room not in levels:
            found.append(f"{path.relative_to(REPO)}: room {room!r} is not in docs/architecture.md's list")
            continue
        for module in sorted(room_imports(path)):
            other = _room_of(module)
            if other is not None and other != room and levels.get(other, -1) > levels[room]:
                found.append(f"{path.relative_to(REPO)} ({room}) imports {module} ({other}, above it)")
    return found


def test_the_engines_rooms_import_only_rooms_below_them():
    levels = engine_rooms()
    assert levels["errors"] == 0 and levels["scene"] == 1 and levels["__init__"] == max(levels.values())
    assert upward_room_imports(levels) == []


def test_the_rooms_check_sees_an_upward_import():
    levels = engine_rooms()
    planted = {**levels, "scene": levels["predict"] + 1}  # scene moved above the rooms that read scenes
    found = upward_room_imports(planted)
    assert any(line.startswith("ipe_ros/engine/predict.py (predict) imports ipe_ros.engine.scene") for line in found), \
        found[:5]


#: Functions allowed past FUNCTION_MAX_LINES: tables of arguments, read as tables
LONG_TABLES = {"ipe_ros/cli.py:build_parser"}
MODULE_MAX_LINES, FUNCTION_MAX_LINES = 450, 80


def oversized(paths) -> list[str]:
    found = []
    for path in paths:
        text = path.read_text()
        where = str(path.relative_to(REPO))
        if text.count("\n") > MODULE_MAX_LINES:
            found.append(f"{where}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text, where)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > FUNCTION_MAX_LINES and f"{where}:{node.name}" not in LONG_TABLES:
                    found.append(f"{where}:{node.name}: {length} lines")
    return found


def test_modules_and_functions_stay_readable_sizes():
    """Size as a guarded habit: a module over 450 lines or a function over 80 is split (argument
    tables listed by name in LONG_TABLES)."""
    paths = [p for d in ("ipe_ros", "msg_bridge") for p in (REPO / d).rglob("*.py")]
    assert oversized(paths) == []


def test_the_size_check_sees_an_oversized_module_and_function(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    big = tmp_path / "big.py"
    big.write_text("def long():\n" + "    x = 1\n" * 90 + "\n" * 400)
    assert oversized([big]) == ["big.py: 491 lines", "big.py:long: 91 lines"]


def test_predict_and_ask_take_a_request_and_a_context():
    """The Request is the currency (issue 71): a prediction and a robot question are asked with one
    request (what is asked) and one context (where it runs, what it records, what it draws from)."""
    import inspect

    from ipe_ros.engine import predict
    from ipe_ros.engine.actions import ask

    assert list(inspect.signature(predict).parameters) == ["scene", "request", "context"]
    assert list(inspect.signature(ask).parameters) == ["scene", "actions", "request", "context"]
