"""Answers and service health as ROS messages: Float64, Vector3Stamped, DiagnosticArray."""

from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Vector3, Vector3Stamped
from std_msgs.msg import Float64

from ipe_ros.engine import Prediction
from ipe_ros.service import ServiceStats

from .stamps import stamp_ns_to_header


def fall_probability_msg(prediction: Prediction) -> Float64 | None:
    """Expected fraction of the dynamic boxes that fall; None when the ``fall`` query was not asked."""
    if prediction.fall_fraction is None:
        return None
    return Float64(data=float(prediction.fall_fraction))


def any_fall_probability_msg(prediction: Prediction) -> Float64 | None:
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


def fall_direction_msg(prediction: Prediction, frame_id: str, stamp_ns: int) -> Vector3Stamped:
    x, y, z = fall_direction_vector(prediction)
    return Vector3Stamped(header=stamp_ns_to_header(stamp_ns, frame_id), vector=Vector3(x=x, y=y, z=z))


def _fmt(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def diagnostics_msg(stats: ServiceStats, name: str, stamp_ns: int, hardware_id: str = "") -> DiagnosticArray:
    """One DiagnosticStatus for the node: ERROR when no worker is alive, WARN when samples failed
    or scenes were rejected, OK otherwise; the counters as key/values."""
    if stats.closed:
        level, message = DiagnosticStatus.ERROR, "shutting down"
    elif stats.workers > 0 and stats.workers_alive == 0:
        level, message = DiagnosticStatus.ERROR, f"no worker process alive (of {stats.workers})"
    elif stats.failed_predictions or stats.failed_samples or stats.rejected:
        level = DiagnosticStatus.WARN
        message = (f"{stats.rejected} scene(s) rejected, {stats.failed_predictions} prediction(s) and "
                   f"{stats.failed_samples} sample(s) failed; last error: {stats.last_error or 'none'}")
    else:
        level, message = DiagnosticStatus.OK, "predicting" if stats.in_flight else "idle"
    values = {
        "workers": stats.workers, "workers_alive": stats.workers_alive,
        "worker_replacements": stats.worker_replacements, "queue_length": stats.waiting,
        "in_flight": stats.in_flight, "scenes_received": stats.received, "scenes_predicted": stats.predicted,
        "scenes_dropped": stats.dropped, "scenes_rejected": stats.rejected,
        "predictions_failed": stats.failed_predictions, "samples_failed": stats.failed_samples,
        "last_compute_s": stats.last_compute_s, "last_error": stats.last_error,
    }
    status = DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                              values=[KeyValue(key=k, value=_fmt(v)) for k, v in values.items()])
    return DiagnosticArray(header=stamp_ns_to_header(stamp_ns, ""), status=[status])
