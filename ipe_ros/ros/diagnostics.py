"""The service's health as ``diagnostic_msgs/DiagnosticArray`` (the node's business, not the bridge's)."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from msg_bridge.stamps import stamp_ns_to_header

from ..engine.errors import clip
from ..service import ServiceStats


def _diagnostic_value(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, float):
        return f"{value:.4g}"
    return clip(str(value), 600)


def diagnostics_msg(stats: ServiceStats, name: str, stamp_ns: int, hardware_id: str = "",
                    meshes: dict | None = None) -> DiagnosticArray:
    """One DiagnosticStatus for the node, reflecting the recent state (not the whole history):

    - ERROR: shutting down, no worker process alive, or the latest prediction failed (until the
      next one succeeds);
    - WARN: one of the last RECENT_EVENTS inputs or predictions was rejected, partial (failed
      samples, cut by the budget), contradicted by the reference physics without time to escalate,
      or lost its recording; or the prediction in flight has run past the budget;
    - OK otherwise ("predicting" / "idle"). The counters since start come as key/values, and
      ``meshes`` (``DecompositionService.status``): the mesh decomposing, those waiting, the counts.
    """
    recent = stats.recent
    overdue = stats.in_flight_s is not None and stats.budget_s is not None and stats.in_flight_s > stats.budget_s + 5
    troubles = {kind: recent.count(kind) for kind in ("rejected", "failed", "partial", "contradicted", "rrd_failed") if kind in recent}
    if stats.closed:
        level, message = DiagnosticStatus.ERROR, "shutting down"
    elif stats.workers > 0 and stats.workers_alive == 0:
        level, message = DiagnosticStatus.ERROR, f"no worker process alive (of {stats.workers})"
    elif recent and recent[-1] == "failed":
        level, message = DiagnosticStatus.ERROR, f"the latest prediction failed: {stats.last_error or 'unknown'}"
    elif troubles or overdue:
        level = DiagnosticStatus.WARN
        parts = [f"{count} {kind.replace('_', ' ')}" for kind, count in troubles.items()]
        message = (f"in the last {len(recent)} inputs/predictions: {', '.join(parts)}" if parts else "") + \
                  (f"{'; ' if parts else ''}a prediction has run {stats.in_flight_s:.0f} s, past its budget"
                   if overdue else "")
        if stats.last_error:
            message += f"; last error: {stats.last_error}"
    else:
        level, message = DiagnosticStatus.OK, "predicting" if stats.in_flight else "idle"
    values = {
        "workers": stats.workers, "workers_alive": stats.workers_alive,
        "worker_replacements": stats.worker_replacements, "queue_length": stats.waiting,
        "in_flight": stats.in_flight, "in_flight_s": stats.in_flight_s, "budget_s": stats.budget_s,
        "scenes_received": stats.received, "scenes_predicted": stats.predicted,
        "predictions": stats.predictions, "scenes_dropped": stats.dropped, "scenes_rejected": stats.rejected,
        "predictions_failed": stats.failed_predictions, "samples_failed": stats.failed_samples,
        "budget_stops": stats.budget_stops, "rrd_failures": stats.rrd_failures,
        "samples_refined": stats.refined_samples, "predictions_escalated": stats.escalated,
        "predictions_contradicted": stats.contradicted, "predictions_validated": stats.validated, **stats.evidence,
        "last_compute_s": stats.last_compute_s, "last_error": stats.last_error,
    }
    if meshes is not None:
        current = meshes["decomposing"]
        values.update({"mesh_decomposing": None if current is None else f"{current['mesh']} ({current['running_s']} s)",
                       "meshes_waiting": meshes["meshes_waiting"], "inputs_waiting_on_meshes": meshes["inputs_waiting"],
                       "meshes_decomposed": meshes["decomposed"], "meshes_refused": meshes["refused"]})
    status = DiagnosticStatus(level=level, name=name, message=clip(message, 1000), hardware_id=hardware_id,
                              values=[KeyValue(key=k, value=_diagnostic_value(v)) for k, v in values.items()])
    return DiagnosticArray(header=stamp_ns_to_header(stamp_ns, ""), status=[status])
