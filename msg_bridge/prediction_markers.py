"""Predictions as ``visualization_msgs/MarkerArray``: each body in its own shape coloured by its fall
probability, the fall direction as an arrow, a label (the scene's markers: ``markers``)."""

from __future__ import annotations

import math

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from ipe_ros.engine import Prediction, Scene
from ipe_ros.viz.palette import group_rgb, risk_rgb

from .markers import body_marker
from .stamps import stamp_ns_to_header


def prediction_to_markers(scene: Scene, prediction: Prediction, frame_id: str, stamp_ns: int) -> MarkerArray:
    """Each dynamic body in its own shape, coloured by its fall probability (green 0 .. red 1), an arrow for the fall
    direction (length grows with decisiveness) and a text label; starts with a DELETEALL so stale
    markers of a previous scene disappear in RViz/Foxglove."""
    header = stamp_ns_to_header(stamp_ns, frame_id)
    markers = [Marker(header=header, ns="", id=0, action=Marker.DELETEALL)]
    probabilities = prediction.object_fall_probability or {}
    dynamic = scene.dynamic_objects
    for j, body in enumerate(dynamic):
        p = probabilities.get(body.name)
        rgb = risk_rgb(p) if p is not None else group_rgb(body.group)
        text = f"{body.name}: P(fall) = {p:.2f}" if p is not None else body.name
        markers.append(body_marker(header, "ipe/objects", j, body, rgb, 0.9, text, exact=False))
    if not dynamic:
        return MarkerArray(markers=markers)
    top = max(b.position_m[2] + max(b.extents_m) / 2 for b in dynamic)
    cx = sum(b.position_m[0] for b in dynamic) / len(dynamic)
    cy = sum(b.position_m[1] for b in dynamic) / len(dynamic)
    scale = max(max(b.extents_m) for b in dynamic)
    if prediction.fall_fraction is not None:
        label = Marker(header=header, ns="ipe/label", id=0, type=Marker.TEXT_VIEW_FACING, action=Marker.ADD,
                       text=f"P(fall) = {prediction.fall_fraction:.2f} (k = {prediction.samples})")
        label.pose.position.x, label.pose.position.y, label.pose.position.z = cx, cy, top + 0.5 * scale
        label.pose.orientation.w = 1.0
        label.scale.z = 0.25 * scale
        label.color = ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0)
        markers.append(label)
    if prediction.direction_rad is not None:
        length = 2.0 * scale * (prediction.direction_decisiveness or 0.0)
        arrow = Marker(header=header, ns="ipe/direction", id=0, type=Marker.ARROW, action=Marker.ADD,
                       text=f"fall direction {math.degrees(prediction.direction_rad):.0f} deg")
        arrow.pose.orientation.w = 1.0
        start = Point(x=cx, y=cy, z=top)
        end = Point(x=cx + length * math.cos(prediction.direction_rad),
                    y=cy + length * math.sin(prediction.direction_rad), z=top)
        arrow.points = [start, end]
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.1 * scale, 0.2 * scale, 0.3 * scale
        arrow.color = ColorRGBA(r=0.95, g=0.1, b=0.1, a=1.0)
        markers.append(arrow)
    return MarkerArray(markers=markers)
