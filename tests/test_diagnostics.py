"""The node's diagnostics: levels from the recent state, counters since start (no rclpy needed)."""

from ipe_ros.ros.diagnostics import diagnostics_msg
from ipe_ros.service import RECENT_EVENTS, ServiceStats

OK, WARN, ERROR = b"\x00", b"\x01", b"\x02"


def _stats(**kw) -> ServiceStats:
    base = dict(received=3, predicted=2, predictions=2, dropped=1, rejected=0, failed_predictions=0, failed_samples=0,
                budget_stops=0, rrd_failures=0, waiting=0, in_flight=False, in_flight_s=None, workers=2,
                workers_alive=2, worker_replacements=0, last_compute_s=0.5, last_error=None, closed=False,
                recent=("ok", "ok"), budget_s=60.0)
    return ServiceStats(**{**base, **kw})


def _status(**kw):
    return diagnostics_msg(_stats(**kw), "/robot/ipe: IPE prediction service", 7, "/robot/ipe").status[0]


def test_diagnostics_levels_and_counters():
    ok = _status()
    assert (ok.level, ok.message, ok.name) == (OK, "idle", "/robot/ipe: IPE prediction service")
    values = {kv.key: kv.value for kv in ok.values}
    assert (values["scenes_received"], values["scenes_dropped"], values["last_compute_s"]) == ("3", "1", "0.5")
    assert (values["predictions"], values["budget_stops"], values["rrd_failures"]) == ("2", "0", "0")
    warn = _status(rejected=2, last_error="markers: x", recent=("ok", "rejected", "rejected", "ok"))
    assert warn.level == WARN
    assert warn.message == "in the last 4 inputs/predictions: 2 rejected; last error: markers: x"
    dead = _status(workers_alive=0)
    assert (dead.level, dead.message) == (ERROR, "no worker process alive (of 2)")


def test_a_rejection_warns_only_while_it_is_recent():
    """A single bad scene long ago must not leave the node at WARN forever."""
    assert _status(rejected=1, recent=("rejected",) + ("ok",) * (RECENT_EVENTS - 1)).level == WARN
    assert _status(rejected=1, recent=("ok",) * RECENT_EVENTS).level == OK


def test_a_failed_latest_prediction_is_an_error_until_the_next_one_succeeds():
    failed = _status(failed_predictions=1, last_error="TypeError: x", recent=("ok", "failed"))
    assert (failed.level, failed.message) == (ERROR, "the latest prediction failed: TypeError: x")
    assert _status(failed_predictions=1, recent=("failed", "ok")).level == WARN


def test_budget_stops_recording_failures_and_an_overdue_prediction_warn():
    assert _status(recent=("partial",)).level == WARN
    assert _status(recent=("rrd_failed",), rrd_failures=1).level == WARN
    overdue = _status(in_flight=True, in_flight_s=300.0)
    assert overdue.level == WARN and "past its budget" in overdue.message
    assert _status(in_flight=True, in_flight_s=3.0).message == "predicting"


def test_self_check_counters_and_a_contradicted_answer_warns():
    status = _status(refined_samples=5, escalated=2, contradicted=1, recent=("ok", "contradicted"))
    values = {kv.key: kv.value for kv in status.values}
    assert (values["samples_refined"], values["predictions_escalated"], values["predictions_contradicted"]) == \
        ("5", "2", "1")
    assert status.level == WARN and status.message == "in the last 2 inputs/predictions: 1 contradicted"
    assert _status(escalated=3, recent=("ok",)).level == OK  # escalated answers are the reference's: no trouble
