"""The node's ROS parameters: descriptors made from the table of inputs, and their mapping to the engine.

The prediction's inputs are rows of ``engine.inputs.INPUTS`` (the CLI's options are made from the
same rows); the node's own settings (frames, QoS, recordings) are rows of the same kind in
``NODE_SETTINGS``; the perception sources' own (depth's camera) and the queries' own parameters come
from their registries. ``all_parameters`` is what
the node declares, ``config/ipe.yaml`` is written from it (``python -m ipe_ros.ros.params``; a test
keeps the file equal) and docs/node.md documents it. ``config_from_values`` is pure (no rclpy): it
turns a {name: value} mapping into :class:`~ipe_ros.service.ServiceConfig` or raises ``ConfigError``
naming the parameter. The engine's own types do the checking; only ROS-specific fields are checked here.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from dataclasses import dataclass
from typing import Any, Mapping

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ..engine import ConfigError
from ..engine.config import anytime_batch_size
from ..engine.inputs import INPUTS, Input, as_spelled, from_node, node_default
from ..engine.perceptions import perception_names, perception_source
from ..engine.request import build_request
from ..engine.safe_files import is_folder
from ..engine.query.parameters import query_parameters
from ..engine.scene.meshes import MeshAccess
from ..service import ServiceConfig

#: Frames conventionally gravity-aligned in ROS (REP 105: map, odom; world is common in simulation).
DEFAULT_GRAVITY_ALIGNED_FRAMES = ("world", "map", "odom")
#: How the scene topics subscribe: "both" takes reliable and best-effort (sensor-style) publishers.
SCENE_RELIABILITY = ("both", "reliable", "best_effort")


def _reliability() -> tuple[str, ...]:
    return SCENE_RELIABILITY


def _fed_perceptions() -> tuple[str, ...]:
    return tuple(n for n in perception_names() if perception_source(n).on_node)


def _node(name: str, kind, default, unit: str, text: str, **kw) -> Input:
    return Input(name, kind, default, unit, text, parameter=name, in_request=False, **kw)


#: The node's own settings, as rows of the inputs table (no CLI spelling: the CLI has no topics).
NODE_SETTINGS: tuple[Input, ...] = (
    _node("inputs_from", "name", "", "path", "a parameter set (ipe fit's output, engine/input_sets.py) whose model "
          "inputs replace the defaults of those parameters at start; a parameter given as an override wins over the "
          "file; empty: the defaults", fixed_at_start=True),
    _node("dask_scheduler", "name", "", "address", "run the samples on a Dask cluster at this address (e.g. "
          "tcp://10.0.0.1:8786, see docs/cluster.md) instead of `workers` local processes; empty: local",
          fixed_at_start=True),
    _node("frame_id", "name", "world", "frame", "frame of scenes received on ~/scene_json and ~/ask (JSON carries no "
          "header); must be one of gravity_aligned_frames", constraints="a non-empty frame name"),
    _node("gravity_aligned_frames", "names", DEFAULT_GRAVITY_ALIGNED_FRAMES, "frames",
          "frames whose -z axis is gravity: the physics assumes it, so scenes in any other frame are refused "
          "(transform them first); [''] accepts every frame", constraints="frame names, or ['']"),
    _node("scene_reliability", "name", "both", "name",
          "QoS reliability of the ~/scene and ~/scene_json subscriptions: both (a reliable and a best-effort "
          "subscription, each message used once: accepts every publisher), reliable, or best_effort",
          fixed_at_start=True, choices=_reliability),
    _node("service_timeout_s", "float", 60.0, "s", "how long ~/predict waits for an answer, seconds",
          range=(0.1, 3600.0)),
    _node("learned_properties_s", "float", 600.0, "s", "how long properties inferred from an observation on "
          "~/observe (answered on ~/properties) replace an object's own in the scenes that follow, by name; 0: never",
          range=(0.0, 86400.0)),
    _node("mesh_roots", "name", "", "folders", "folders (':'-separated) under which scenes on ~/scene_json, ~/scene "
          "(MESH_RESOURCE markers) and ~/ask may name mesh files (and package:// meshes resolve); empty: scenes may "
          "not name files. Fixed at start-up: no participant on the network may point the node at other files",
          fixed_at_start=True),
    _node("mesh_decomposition_s", "float", 30.0, "s", "the most seconds a mesh not yet decomposed may take to "
          "decompose into convex parts (in a process of its own, off the executor: the sender hears \"decomposing\" at "
          "once and the answer once the parts are ready; when over, the scene is refused, saying so, and that is "
          "remembered); cached meshes cost nothing", range=(0.1, 3600.0)),
    _node("rerun.save_dir", "name", "", "folder", "folder for one .rrd recording per prediction; empty: no rerun "
          "logging. Fixed at start-up: no participant on the network may have the node write elsewhere",
          fixed_at_start=True),
    _node("rerun.rollouts_logged", "int", 8, "count", "sampled rollouts shown in each .rrd", range=(0, 1000)),
    _node("rerun.frame_period_s", "float", 0.02, "s", "simulated seconds between logged frames of a rollout",
          range=(0.001, 1.0)),
    _node("rerun.connect_url", "name", "", "URL", "also stream recordings to a viewer already running at this gRPC "
          "URL (e.g. rerun+http://127.0.0.1:9876/proxy); empty: never contact or spawn a viewer"),
)

#: where the node's parameter means more than the CLI's option
_NODE_NOTES = {
    "perception": "where the k noisy scenes come from: gaussian (sigma), depth (the posterior given the newest "
                  "depth image on ~/depth/image, its ~/depth/camera_info and the camera pose; sigma unused), or "
                  "another registered perception the node can feed (engine.perceptions)",
    "ground_truth": "the ground-truth model: the scene exactly as given, one deterministic rollout (sigma and phi "
                    "read as 0 while on, and no body's own position or yaw noise); questions on ~/ask too",
    "contact": "the contact query's pairs as 'A:B,C:support' (will A touch B within the horizon? B may be "
               "'support'; names holding ':' as a JSON list of pairs); adds contact to queries; empty: none",
}

_ROS_TYPES = {"int": ParameterType.PARAMETER_INTEGER, "float": ParameterType.PARAMETER_DOUBLE,
              "floats": ParameterType.PARAMETER_DOUBLE_ARRAY, "bool": ParameterType.PARAMETER_BOOL,
              "name": ParameterType.PARAMETER_STRING, "names": ParameterType.PARAMETER_STRING_ARRAY,
              "pairs": ParameterType.PARAMETER_STRING}
_KINDS = {float: "float", int: "int", bool: "bool", str: "name"}


@dataclass(frozen=True)
class ParamSpec:
    """One declared parameter, made from a row (``of``)."""

    name: str
    default: Any
    type: int
    description: str
    range: tuple[float, float] | None = None
    read_only: bool = False
    constraints: str = ""
    #: a list parameter that also takes one value (``phi: 2.0`` as well as ``phi: [0.0, 2.0]``)
    dynamic_typing: bool = False

    @classmethod
    def of(cls, row: Input) -> "ParamSpec":
        text = _NODE_NOTES.get(row.field, row.help)
        if row.default is None:
            text += f"; {_shown(row.unset)}: {row.unset_means}"
        constraints = row.constraints
        if not constraints and row.choices is not None:
            choices = _fed_perceptions() if row.field == "perception" else row.choices()
            constraints = ("non-empty subset of " if row.kind == "names" else "one of ") + ", ".join(choices)
        return cls(row.parameter, node_default(row), _ROS_TYPES[row.kind], text,
                   row.range if row.kind in ("int", "float") else None, row.fixed_at_start, constraints,
                   dynamic_typing=row.kind == "floats")

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, type=self.type, description=self.description,
                                read_only=self.read_only, additional_constraints=self.constraints,
                                dynamic_typing=self.dynamic_typing)
        if self.range is not None and self.type == ParameterType.PARAMETER_INTEGER:
            d.integer_range = [IntegerRange(from_value=int(self.range[0]), to_value=int(self.range[1]), step=1)]
        elif self.range is not None and self.type == ParameterType.PARAMETER_DOUBLE:
            d.floating_point_range = [FloatingPointRange(from_value=float(self.range[0]),
                                                         to_value=float(self.range[1]), step=0.0)]
        return d


def _shown(value: Any) -> str:
    return "NaN" if isinstance(value, float) and math.isnan(value) else f"{value:g}" if isinstance(value, float) \
        else str(value)


#: The prediction's inputs the node takes and its own settings.
PARAMETERS: tuple[ParamSpec, ...] = tuple(ParamSpec.of(r) for r in INPUTS + NODE_SETTINGS if r.parameter is not None)


def query_parameter_specs() -> tuple[ParamSpec, ...]:
    """The registered queries' own parameters (``<query>.<field>``, engine/query/parameters.py),
    declared beside ``PARAMETERS``; a query registered before the node starts is settable too."""
    return tuple(ParamSpec.of(Input(row.name, _KINDS[row.type], row.default, "", f"the {row.query} query: "
                                    f"{row.meaning}", parameter=row.name, in_request=False))
                 for row in query_parameters())


def perception_parameter_specs() -> tuple[ParamSpec, ...]:
    """The perception sources' own parameters (``engine.evidence.Evidence.parameters``: depth's
    ``depth.*``), declared beside ``PARAMETERS``; a source registered before the node starts counts."""
    return tuple(ParamSpec.of(row) for name in perception_names() if perception_source(name).needs is not None
                 for row in perception_source(name).needs.parameters)


def all_parameters() -> tuple[ParamSpec, ...]:
    """What the node declares: ``PARAMETERS``, the perception sources' and the queries' own."""
    return PARAMETERS + perception_parameter_specs() + query_parameter_specs()


def declare_all(node) -> dict[str, Any]:
    """Declare every parameter on ``node`` (an rclpy Node) and return their values: ``inputs_from``
    first, whose parameter set's inputs then stand in for those parameters' defaults (an override
    still wins over them)."""
    declared = all_parameters()
    first = next(spec for spec in declared if spec.name == "inputs_from")
    node.declare_parameter(first.name, first.default, first.descriptor())
    defaults = defaults_from(node.get_parameter(first.name).value)
    for spec in declared:
        if spec is not first:
            node.declare_parameter(spec.name, defaults.get(spec.name, spec.default), spec.descriptor())
    return {spec.name: node.get_parameter(spec.name).value for spec in declared}


def defaults_from(inputs_from: str) -> dict[str, Any]:
    """The parameters' defaults a parameter set replaces (``inputs_from``), as node values; a
    ConfigError naming ``inputs_from`` for a file that is not one."""
    if not str(inputs_from).strip():
        return {}
    from ..engine.input_sets import load_input_set

    loaded = load_input_set(str(inputs_from).strip())
    by_field = {row.field: row for row in INPUTS}
    return {by_field[field].parameter: list(value) if isinstance(value, tuple) else value
            for field, value in loaded.items()}


def config_from_values(values: Mapping[str, Any]) -> ServiceConfig:
    """Build the service config from parameter values; ConfigError names the parameter at fault."""
    frame = values["frame_id"]
    if not isinstance(frame, str) or not frame.strip() or frame != frame.strip():
        raise ConfigError("frame_id", f"must be a non-empty frame name without surrounding spaces, got {frame!r}")
    if not list(values["gravity_aligned_frames"]):  # [] would trust every frame by accident
        raise ConfigError("gravity_aligned_frames", "is empty; list the frames whose -z axis is gravity, or [''] "
                                                    "to accept scenes in every frame")
    frames = tuple(f for f in values["gravity_aligned_frames"] if f != "")
    if any(not f.strip() or f != f.strip() for f in frames):
        raise ConfigError("gravity_aligned_frames", f"frame names must be non-empty without surrounding spaces, got "
                                                    f"{list(values['gravity_aligned_frames'])!r}")
    if frames and frame not in frames:
        raise ConfigError("frame_id", f"{frame!r} is not in gravity_aligned_frames {list(frames)!r}; add it there "
                                      "if its -z axis is gravity, or publish scenes in one of those frames")
    if values["scene_reliability"] not in SCENE_RELIABILITY:
        raise ConfigError("scene_reliability", f"must be one of {', '.join(SCENE_RELIABILITY)}, got "
                                               f"{values['scene_reliability']!r}")
    if not perception_source(values["perception"]).on_node:
        fed = ", ".join(_fed_perceptions())
        raise ConfigError("perception", f"must be a perception the node can feed ({fed}), got {values['perception']!r}")
    for name in perception_names():  # each source's own parameters (depth's camera pose: checked now, used later)
        needs = perception_source(name).needs
        if needs is not None and needs.check is not None:
            needs.check(values)
    try:  # one request from the parameters (engine.request), its errors named as the parameters
        given = {row.field: from_node(row, values[row.parameter]) for row in INPUTS
                 if row.in_request and row.parameter is not None}
        request = build_request(**given, batch_size=anytime_batch_size(int(values["workers"])),
                                query_parameters={row.name: values[row.name] for row in query_parameters()
                                                  if row.name in values})
    except ConfigError as exc:
        raise as_spelled(exc, "ros") from None
    save_dir = str(values["rerun.save_dir"]).strip()
    if save_dir and (".." in Path(save_dir).parts or "\0" in save_dir):
        # any participant on the DDS domain may set parameters: recordings stay where the operator points
        raise ConfigError("rerun.save_dir", f"must not climb out of a folder ('..'), got {save_dir!r}; give the "
                                            "folder itself")
    connect = str(values["rerun.connect_url"]).strip()
    roots = tuple(Path(r) for r in str(values["mesh_roots"]).split(":") if r.strip())
    missing = [str(r) for r in roots if not r.is_absolute() or not is_folder(r)]
    if missing:  # a scene arrives over the network: its files are read only where the operator points
        raise ConfigError("mesh_roots", f"{missing[0]!r} is not an absolute path of a folder; give folders as "
                                        "/path/a:/path/b")
    return ServiceConfig(request=request, max_objects=int(values["max_objects"]),
                         rerun_save_dir=save_dir or None, rerun_rollouts_logged=int(values["rerun.rollouts_logged"]),
                         rerun_frame_period_s=float(values["rerun.frame_period_s"]),
                         rerun_connect_url=connect or None, gravity_aligned_frames=frames,
                         evidence_settings=tuple((n, values[n]) for n in evidence_parameters() if n in values),
                         # files only under the roots (none: no files); a mesh not yet decomposed, even a
                         # marker's triangles, is decomposed off the executor, within its time (defer)
                         meshes=MeshAccess(roots=roots, decompose_within_s=float(values["mesh_decomposition_s"]),
                                           defer=True))


def evidence_parameters() -> tuple[str, ...]:
    """The node parameters perception sources read when a scene is predicted (``engine.evidence``)."""
    needs = [perception_source(n).needs for n in perception_names()]
    return tuple(e.max_age_parameter for e in needs if e is not None and e.max_age_parameter)


_YAML_HEAD = """# Parameters of ipe_node with their defaults. Use: ros2 run ipe_ros ipe_node --ros-args --params-file config/ipe.yaml
# (or launch/ipe.launch.py). '/**' matches the node under any name or namespace.
# Every parameter can be changed at run time with `ros2 param set` except those marked read-only.
# Written from the table of inputs by `python -m ipe_ros.ros.params > config/ipe.yaml` (a test keeps it equal).
/**:
  ros__parameters:
"""


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return ".nan" if math.isnan(value) else repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    return f'"{value}"' if isinstance(value, str) else str(value)


def config_yaml() -> str:
    """config/ipe.yaml: every declared parameter with its description, range and default (``workers``,
    whose default is the machine's, commented out)."""
    import textwrap

    lines = [_YAML_HEAD]
    for spec in all_parameters():
        note = spec.description + (f" [{_shown(spec.range[0])} .. {_shown(spec.range[1])}]" if spec.range else "") \
            + (" (read-only)" if spec.read_only else "")
        if spec.name == "workers":
            note += ". Default: one per core, at most 8; uncomment to fix it."
        lines += [f"    # {line}\n" for line in textwrap.wrap(note, 106)]
        if spec.name == "workers":  # the machine's default: an example, commented out
            lines.append("    # workers: 2\n")
        else:
            lines.append(f"    {spec.name}: {_yaml_value(spec.default)}\n")
    return "".join(lines)


if __name__ == "__main__":
    sys.stdout.write(config_yaml())


_TYPE_NAMES = {ParameterType.PARAMETER_INTEGER: "int", ParameterType.PARAMETER_DOUBLE: "double",
               ParameterType.PARAMETER_BOOL: "bool", ParameterType.PARAMETER_STRING: "string",
               ParameterType.PARAMETER_STRING_ARRAY: "string[]", ParameterType.PARAMETER_DOUBLE_ARRAY: "double[]"}


def reference_columns(spec: ParamSpec) -> tuple[str, str, str, str]:
    """docs/node.md's name, type, default and range columns of a parameter, as the node declares it
    (the meaning column is written by hand; a test keeps these four equal)."""
    kind = _TYPE_NAMES[spec.type] + (", read-only" if spec.read_only else "")
    if spec.name == "workers":
        default = "cores (≤ 8)"
    elif isinstance(spec.default, bool):
        default = "true" if spec.default else "false"
    elif isinstance(spec.default, float):
        default = _shown(spec.default) if math.isnan(spec.default) else repr(spec.default)
    elif isinstance(spec.default, (list, tuple)):
        default = "`[" + ", ".join(_shown(v) for v in spec.default) + "]`"
    elif isinstance(spec.default, str):
        default = f"`{spec.default}`" if spec.default else "`''`"
    else:
        default = str(spec.default)
    bounds = "" if spec.range is None else f"{_shown(spec.range[0])}..{_shown(spec.range[1])}"
    return f"`{spec.name}`", kind, default, bounds
