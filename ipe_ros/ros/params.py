"""The node's ROS parameters: declarations with descriptors and ranges, and their mapping to the engine.

``PARAMETERS`` is the single table the node declares, the README documents and the tests check; its
defaults come from the engine's config. ``config_from_values`` is pure (no rclpy): it turns a
{name: value} mapping into :class:`~ipe_ros.service.ServiceConfig` or raises ``ConfigError`` naming the
parameter. The engine's own types do the checking; only ROS-specific fields are checked here.
"""

from __future__ import annotations

import math
from pathlib import Path
from dataclasses import dataclass
from typing import Any, Mapping

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType

from ..engine import ALL_QUERIES, PRESETS, ConfigError
from ..engine.config import (DEFAULT_BUDGET_S, DEFAULT_PRESET, DEFAULT_QUERIES, DEFAULT_SAMPLES, DEFAULT_SIGMA_M, anytime_batch_size,
                             default_workers)
from ..engine.checking.fidelity import DEFAULT_CHECK
from ..engine.inputs import as_spelled
from ..engine.perceptions import perception_names, perception_source
from ..engine.request import build_request
from ..engine.query.contact import parse_pairs
from ..engine.query.parameters import query_parameters
from ..engine.scene.bodies import DEFAULT_MAX_OBJECTS
from ..service import ServiceConfig

#: Frames conventionally gravity-aligned in ROS (REP 105: map, odom; world is common in simulation).
DEFAULT_GRAVITY_ALIGNED_FRAMES = ("world", "map", "odom")
#: How the scene topics subscribe: "both" takes reliable and best-effort (sensor-style) publishers.
SCENE_RELIABILITY = ("both", "reliable", "best_effort")


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: Any
    type: int
    description: str
    range: tuple[float, float] | None = None
    read_only: bool = False
    constraints: str = ""

    def descriptor(self) -> ParameterDescriptor:
        d = ParameterDescriptor(name=self.name, type=self.type, description=self.description,
                                read_only=self.read_only, additional_constraints=self.constraints)
        if self.range is not None and self.type == ParameterType.PARAMETER_INTEGER:
            d.integer_range = [IntegerRange(from_value=int(self.range[0]), to_value=int(self.range[1]), step=1)]
        elif self.range is not None and self.type == ParameterType.PARAMETER_DOUBLE:
            d.floating_point_range = [FloatingPointRange(from_value=float(self.range[0]),
                                                         to_value=float(self.range[1]), step=0.0)]
        return d


_INT, _DOUBLE = ParameterType.PARAMETER_INTEGER, ParameterType.PARAMETER_DOUBLE
_STRING, _STRINGS = ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_STRING_ARRAY

PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("samples", DEFAULT_SAMPLES, _INT, "Monte Carlo samples k per prediction (paper: 48)", (1, 10000)),
    ParamSpec("sigma", DEFAULT_SIGMA_M, _DOUBLE, "position noise SD, metres (paper: 0.2 block short sides = 0.04 m "
                                      "for 0.2 m blocks; 0 drops the model's own noise, not the noise a scene "
                                      "gives its bodies: ground_truth drops both)", (0.0, 10.0)),
    ParamSpec("phi", 0.0, _DOUBLE, "latent push: horizontal acceleration of the support for 0.2 s, m/s^2 "
                                   "(0: no push)", (0.0, 100.0)),
    ParamSpec("ground_truth", False, ParameterType.PARAMETER_BOOL,
              "the ground-truth model: the scene exactly as given, one deterministic rollout (sigma and phi "
              "read as 0 while on, and no body's own position or yaw noise); questions on ~/ask too"),
    ParamSpec("force_direction_deg", math.nan, _DOUBLE,
              "cued push direction in degrees in the scene frame (0 = +x, counter-clockwise), pushes drawn "
              "within +-45 deg of it; NaN (default) draws the direction uniformly",
              constraints="finite degrees, or NaN for any direction"),
    ParamSpec("mu", 0.0, _DOUBLE, "heavy/light density ratio for bodies in group 'heavy'; 0 keeps the scene's "
                                  "own masses", (0.0, 1000.0)),
    ParamSpec("queries", [q for q in ALL_QUERIES if q in DEFAULT_QUERIES], _STRINGS,
              "queries to answer: any of " + ", ".join(ALL_QUERIES) + " (bump needs a table, contact its "
              "contact_pairs)",
              constraints="non-empty subset of " + ", ".join(ALL_QUERIES)),
    ParamSpec("contact_pairs", "", _STRING,
              "the contact query's pairs as 'A:B,C:support' (will A touch B within the horizon? B may be 'support'); "
              "adds contact to queries; empty: none",
              constraints="empty, or comma-separated A:B object name pairs"),
    ParamSpec("preset", DEFAULT_PRESET, _STRING, "simulation settings: " + ", ".join(
        f"{name} ({s.time_step_s * 1000:g} ms steps, {s.horizon_s:g} s, {s.solver.iterations} solver iterations)"
        for name, s in PRESETS.items()), constraints="one of " + ", ".join(PRESETS)),
    ParamSpec("horizon_s", 0.0, _DOUBLE, "simulated seconds per rollout for scenes that give no horizon_s of their "
                                         "own; 0: the preset's (2 s)", (0.0, 60.0)),
    ParamSpec("until_rest", False, ParameterType.PARAMETER_BOOL,
              "end each rollout once everything is at rest (early termination, also for presets without it); "
              "with horizon_s: until at rest, at most that long"),
    ParamSpec("seed", 0, _INT, "random seed; a prediction is a function of (scene, parameters, seed)", (0, 2**31 - 1)),
    ParamSpec("workers", default_workers(), _INT, "simulation worker processes (0: run samples in the node's "
                                                 "prediction thread); fixed at start", (0, 64), read_only=True),
    ParamSpec("target_ci_width", 0.0, _DOUBLE, "anytime sampling: stop once the 95% interval of the fall "
                                               "fraction is at most this wide (needs the fall query); 0: off",
              (0.0, 1.0)),
    ParamSpec("deadline_s", 0.0, _DOUBLE, "anytime sampling: stop drawing samples before this many seconds; "
                                          "0: off (all k samples)", (0.0, 3600.0)),
    ParamSpec("budget_s", DEFAULT_BUDGET_S, _DOUBLE, "compute budget: the most wall seconds one prediction may "
                                                   "take; samples still running then are cut off (stopped_by: "
                                                   "budget) and scenes whose one rollout cannot fit are rejected",
              (0.1, 3600.0)),
    ParamSpec("self_check", True, ParameterType.PARAMETER_BOOL,
              "check each prediction's fast physics against the converged reference on the same noisy scenes "
              "(refine unhealthy rollouts, verify samples, rerun everything on disagreement; the answer's "
              "fidelity says what happened); false: the fast physics alone, answers 'unverified'"),
    ParamSpec("verify_samples", DEFAULT_CHECK.verify_samples, _INT,
              "samples rerun at the reference settings to verify each prediction", (0, 100)),
    ParamSpec("dask_scheduler", "", _STRING, "run the samples on a Dask cluster at this address (e.g. "
                                         "tcp://10.0.0.1:8786, see docs/cluster.md) instead of `workers` local "
                                         "processes; empty: local; fixed at start", read_only=True),
    ParamSpec("perception", "gaussian", _STRING,
              "where the k noisy scenes come from: gaussian (sigma), depth (the posterior given the newest depth "
              "image on ~/depth/image, its ~/depth/camera_info and the camera pose; sigma unused), or another "
              "registered perception the node can feed (engine.perceptions)",
              constraints="a registered perception the node can feed: gaussian, depth, ..."),
    ParamSpec("depth.max_age_s", 0.5, _DOUBLE, "depth perception: the depth image may be at most this many seconds "
                                               "from the scene's stamp", (0.001, 3600.0)),
    ParamSpec("depth.reliability", "both", _STRING,
              "QoS reliability of the ~/depth/* subscriptions: both (a reliable and a best-effort subscription, "
              "each message used once: a reliable publisher's images arrive whole; best-effort images over ~500 KB "
              "mostly get lost in Fast DDS's fragments), reliable, or best_effort; fixed at start", read_only=True,
              constraints="one of " + ", ".join(SCENE_RELIABILITY)),
    ParamSpec("depth.camera_pose", "", _STRING,
              "depth perception: the camera's optical frame (z forward, y down) in frame_id as "
              "'x,y,z,qx,qy,qz,qw' for a fixed camera; empty (default): from ~/depth/camera_pose",
              constraints="empty, or 7 comma-separated numbers with a unit quaternion"),
    ParamSpec("max_objects", DEFAULT_MAX_OBJECTS, _INT, "scenes with more objects are rejected", (1, 10000)),
    ParamSpec("frame_id", "world", _STRING, "frame of scenes received on ~/scene_json and ~/ask (JSON carries no "
                                            "header); must be one of gravity_aligned_frames",
              constraints="a non-empty frame name"),
    ParamSpec("gravity_aligned_frames", list(DEFAULT_GRAVITY_ALIGNED_FRAMES), _STRINGS,
              "frames whose -z axis is gravity: the physics assumes it, so scenes in any other frame are "
              "refused (transform them first); [''] accepts every frame", constraints="frame names, or ['']"),
    ParamSpec("scene_reliability", "both", _STRING,
              "QoS reliability of the ~/scene and ~/scene_json subscriptions: both (a reliable and a best-effort "
              "subscription, each message used once: accepts every publisher), reliable, or best_effort; "
              "fixed at start", read_only=True, constraints="one of " + ", ".join(SCENE_RELIABILITY)),
    ParamSpec("service_timeout_s", 60.0, _DOUBLE, "how long ~/predict waits for an answer, seconds", (0.1, 3600.0)),
    ParamSpec("rerun.save_dir", "", _STRING, "folder for one .rrd recording per prediction; empty: no rerun logging"),
    ParamSpec("rerun.rollouts_logged", 8, _INT, "sampled rollouts shown in each .rrd", (0, 1000)),
    ParamSpec("rerun.frame_period_s", 0.02, _DOUBLE, "simulated seconds between logged frames of a rollout",
              (0.001, 1.0)),
    ParamSpec("rerun.connect_url", "", _STRING, "also stream recordings to a viewer already running at this "
                                                "gRPC URL (e.g. rerun+http://127.0.0.1:9876/proxy); empty: never "
                                                "contact or spawn a viewer"),
)

_ROS_TYPES = {float: _DOUBLE, int: _INT, bool: ParameterType.PARAMETER_BOOL, str: _STRING}


def query_parameter_specs() -> tuple[ParamSpec, ...]:
    """The registered queries' own parameters (``<query>.<field>``, engine/query/parameters.py),
    declared beside ``PARAMETERS``; a query registered before the node starts is settable too."""
    return tuple(ParamSpec(row.name, row.default, _ROS_TYPES[row.type], f"the {row.query} query: {row.meaning}")
                 for row in query_parameters())


def all_parameters() -> tuple[ParamSpec, ...]:
    """What the node declares: ``PARAMETERS`` and the queries' own."""
    return PARAMETERS + query_parameter_specs()


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
    for name in ("scene_reliability", "depth.reliability"):
        if values[name] not in SCENE_RELIABILITY:
            raise ConfigError(name, f"must be one of {', '.join(SCENE_RELIABILITY)}, got {values[name]!r}")
    direction = float(values["force_direction_deg"])
    if math.isinf(direction):
        raise ConfigError("force_direction_deg", f"must be finite degrees or NaN (any direction), got {direction}")
    if not perception_source(values["perception"]).on_node:
        fed = ", ".join(n for n in perception_names() if perception_source(n).on_node)
        raise ConfigError("perception", f"must be a perception the node can feed ({fed}), got {values['perception']!r}")
    camera_pose(values)  # checked now, used by the node
    text = str(values["contact_pairs"]).strip()
    pairs = parse_pairs(text, "contact_pairs")
    mu, horizon = float(values["mu"]), float(values["horizon_s"])
    width, deadline = float(values["target_ci_width"]), float(values["deadline_s"])
    try:  # one request from the parameters (engine.request), its errors named as the parameters
        request = build_request(
            samples=int(values["samples"]), sigma_m=float(values["sigma"]), phi_m_s2=(float(values["phi"]),),
            ground_truth=bool(values["ground_truth"]),
            force_direction_deg=None if math.isnan(direction) else direction, mu=None if mu == 0 else mu,
            perception=str(values["perception"]), queries=values["queries"], contact=pairs,
            preset_name=values["preset"], horizon_s=horizon if horizon > 0 else None,
            until_rest=bool(values["until_rest"]), seed=int(values["seed"]), ci_width=width or None,
            deadline_s=deadline or None, batch_size=anytime_batch_size(int(values["workers"])),
            budget_s=float(values["budget_s"]), self_check=bool(values["self_check"]),
            verify_samples=int(values["verify_samples"]),
            query_parameters={row.name: values[row.name] for row in query_parameters() if row.name in values})
    except ConfigError as exc:
        raise as_spelled(exc, "ros") from None
    save_dir = str(values["rerun.save_dir"]).strip()
    if save_dir and (".." in Path(save_dir).parts or "\0" in save_dir):
        # any participant on the DDS domain may set parameters: recordings stay where the operator points
        raise ConfigError("rerun.save_dir", f"must not climb out of a folder ('..'), got {save_dir!r}; give the "
                                            "folder itself")
    connect = str(values["rerun.connect_url"]).strip()
    return ServiceConfig(request=request, max_objects=int(values["max_objects"]),
                         rerun_save_dir=save_dir or None, rerun_rollouts_logged=int(values["rerun.rollouts_logged"]),
                         rerun_frame_period_s=float(values["rerun.frame_period_s"]),
                         rerun_connect_url=connect or None, gravity_aligned_frames=frames,
                         depth_max_age_s=float(values["depth.max_age_s"]))


def camera_pose(values: Mapping[str, Any]) -> tuple[tuple, tuple] | None:
    """The fixed camera pose of ``depth.camera_pose`` as (position, xyzw), or None (from the topic)."""
    from ..engine.vision.depth_io import parse_pose

    text = str(values["depth.camera_pose"]).strip()
    if not text:
        return None
    try:
        return parse_pose(text)
    except ConfigError as exc:
        raise ConfigError("depth.camera_pose", exc.problem) from None
