"""The service's health as ``diagnostic_msgs/DiagnosticArray`` (the node's business, not the bridge's)."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from msg_bridge.stamps import stamp_ns_to_header

from ..service import ServiceStats


def _diagnostic_value(value) -> str:
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
                              values=[KeyValue(key=k, value=_diagnostic_value(v)) for k, v in values.items()])
    return DiagnosticArray(header=stamp_ns_to_header(stamp_ns, ""), status=[status])
