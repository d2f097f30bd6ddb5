"""Answers as ROS messages: Float64 and Vector3Stamped."""

from __future__ import annotations

import math

from geometry_msgs.msg import Vector3, Vector3Stamped
from std_msgs.msg import Float64

from ipe_ros.engine import Prediction

from .stamps import stamp_ns_to_header


def fall_fraction_msg(prediction: Prediction) -> Float64 | None:
    """Expected fraction of the dynamic objects that fall; None when the ``fall`` query was not asked."""
    if prediction.fall_fraction is None:
        return None
    return Float64(data=float(prediction.fall_fraction))


def fall_probability_msg(prediction: Prediction) -> Float64 | None:
    """Probability that anything falls; None when the ``any_fall`` query was not asked."""
    if prediction.any_fall_probability is None:
        return None
    return Float64(data=float(prediction.any_fall_probability))


def fall_direction_vector(prediction: Prediction) -> tuple[float, float, float]:
    """Unit vector of the mean fall direction scaled by its decisiveness (0.5 .. 1); zero if nothing falls."""
    if prediction.direction_rad is None:
        return (0.0, 0.0, 0.0)
    scale = prediction.direction_decisiveness or 0.0
    return (scale * math.cos(prediction.direction_rad), scale * math.sin(prediction.direction_rad), 0.0)


def fall_direction_msg(prediction: Prediction, frame_id: str, stamp_ns: int) -> Vector3Stamped | None:
    """The fall direction (a zero vector: nothing fell); None when the ``direction`` query was not
    asked (its ``direction_rollouts`` counts the rollouts it read, 0 included)."""
    if prediction.direction_rollouts is None:
        return None
    x, y, z = fall_direction_vector(prediction)
    return Vector3Stamped(header=stamp_ns_to_header(stamp_ns, frame_id), vector=Vector3(x=x, y=y, z=z))
