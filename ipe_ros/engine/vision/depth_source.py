"""Depth perception as a source (registered in ``engine.perceptions``): the evidence it needs (a depth image with
its camera's calibration and pose), how the command line and the node fill it, and its chain
(``vision.depth``). Everything depth-specific that the doors used to branch on lives here.

Imports of the chain are made when it runs: registering the source costs nothing.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from ..evidence import Evidence, EvidenceTopic
from ..input_row import Input

IMAGE_TOPIC = "~/depth/image"
#: the node's subscriptions' reliabilities (as its scene_reliability's)
RELIABILITY = ("both", "reliable", "best_effort")


def _option(field: str, metavar: str, text: str) -> Input:
    return Input(field, "name", None, "path", f"depth: {text}", flag="--" + field.replace("_", "-"), in_request=False,
                 unset_means="none", metavar=metavar)


def _parameter(name: str, kind, default, unit: str, text: str, **kw) -> Input:
    return Input(name, kind, default, unit, text, parameter=name, in_request=False, **kw)


def _read(values: Mapping[str, Any]) -> tuple:
    from .depth_io import load_observation

    return (load_observation(values["depth"], values["camera_info"], values["camera_pose"]),)


def _assemble(held: Mapping[str, Any]) -> tuple:
    return (held[IMAGE_TOPIC],)


def run_depth(scene, model, seed: int, map_fn, evidence, budget_s: float | None):
    from .depth import perceive_depth_for

    return perceive_depth_for(scene, model.samples, tuple(evidence), seed, budget_s=budget_s, map_fn=map_fn)


def describe_depth(v: dict) -> str:
    return (f"depth chain acceptance {v['acceptance_rate']:.2f}, effective sample size "
            f"{v['effective_sample_size']:.0f}; camera range offset "
            + ", ".join(f"{o['mean_m'] * 1000:+.1f} mm" for o in v["camera_offsets"])
            + "; posterior mean x, y (m) and SD x/y (mm), yaw (deg) per object: "
            + ", ".join(f"{n} {s['position_m'][0]:.4f},{s['position_m'][1]:.4f} "
                        f"{s['x_sd_m'] * 1000:.1f}/{s['y_sd_m'] * 1000:.1f}/"
                        f"{math.degrees(s['yaw_sd_rad']):.1f}" for n, s in v["objects"].items()))


def fixed_camera_pose(values: Mapping[str, Any]) -> tuple[tuple, tuple] | None:
    """The fixed camera pose of the node's ``depth.camera_pose`` as (position, xyzw), or None (from
    the topic)."""
    from ..errors import ConfigError
    from .depth_io import parse_pose

    text = str(values["depth.camera_pose"]).strip()
    if not text:
        return None
    try:
        return parse_pose(text)
    except ConfigError as exc:
        raise ConfigError("depth.camera_pose", exc.problem) from None


def _check_parameters(values: Mapping[str, Any]) -> None:
    from ..errors import ConfigError

    if values["depth.reliability"] not in RELIABILITY:
        raise ConfigError("depth.reliability", f"must be one of {', '.join(RELIABILITY)}, got "
                                               f"{values['depth.reliability']!r}")
    fixed_camera_pose(values)


#: the command line's depth options: the image and its camera, and a recording of the chain
DEPTH_OPTIONS = (_option("depth", "IMAGE", "the depth image, .npy (metres) or 16-bit .png (millimetres; 0: no reading)"),
                 _option("camera_info", "YAML", "the camera's calibration, a ROS camera_info YAML (distortion ignored)"),
                 _option("camera_pose", "X,Y,Z,QX,QY,QZ,QW", "the camera's optical frame (z forward, y down) in "
                                                             "the scene frame"),
                 _option("depth_rrd", "FILE", "write the measured depth, the depth rendered at the posterior mean, "
                                              "their residual and the posterior sample cloud to a rerun recording"))

DEPTH_EVIDENCE = Evidence(
    what="the depth images",
    describes="one depth image describes one scene",
    read=_read,
    # the calibration and the pose first: an image is made an observation with the newest of them
    topics=(EvidenceTopic("~/depth/camera_info", "sensor_msgs/msg/CameraInfo", "msg_bridge.depth:received_camera_info",
                          "camera info"),
            EvidenceTopic("~/depth/camera_pose", "geometry_msgs/msg/PoseStamped",
                          "msg_bridge.depth:received_camera_pose", "camera pose"),
            EvidenceTopic(IMAGE_TOPIC, "sensor_msgs/msg/Image", "msg_bridge.depth:received_depth_image", "depth image",
                          counted_as="depth_images", view=True)),
    assemble=_assemble,
    missing="publish ~/depth/image with ~/depth/camera_info and the camera pose (~/depth/camera_pose or the "
            "depth.camera_pose parameter)",
    frame_named="the camera pose",
    max_age_parameter="depth.max_age_s",
    reliability_parameter="depth.reliability",
    parameters=(
        _parameter("depth.max_age_s", "float", 0.5, "s", "depth perception: the depth image may be at most this many "
                   "seconds from the scene's stamp", range=(0.001, 3600.0)),
        _parameter("depth.reliability", "name", "both", "name",
                   "QoS reliability of the ~/depth/* subscriptions: both (a reliable and a best-effort subscription, "
                   "each message used once: a reliable publisher's images arrive whole; best-effort images over ~500 "
                   "KB mostly get lost in Fast DDS's fragments), reliable, or best_effort", fixed_at_start=True,
                   choices=lambda: RELIABILITY),
        _parameter("depth.camera_pose", "name", "", "x,y,z,qx,qy,qz,qw",
                   "depth perception: the camera's optical frame (z forward, y down) in frame_id as "
                   "'x,y,z,qx,qy,qz,qw' for a fixed camera; empty (default): from ~/depth/camera_pose",
                   constraints="empty, or 7 comma-separated numbers with a unit quaternion")),
    check=_check_parameters,
    budget_share=0.5,  # half a prediction's budget for the chain, the rest for the samples
)
