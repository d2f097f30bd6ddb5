"""The node's diagnostics: levels and counters from the service's stats (no rclpy needed)."""

from ipe_ros.ros.diagnostics import diagnostics_msg
from ipe_ros.service import ServiceStats


def _stats(**kw) -> ServiceStats:
    base = dict(received=3, predicted=2, dropped=1, rejected=0, failed_predictions=0, failed_samples=0, waiting=0,
                in_flight=False, workers=2, workers_alive=2, worker_replacements=0, last_compute_s=0.5,
                last_error=None, closed=False)
    return ServiceStats(**{**base, **kw})


def test_diagnostics_levels_and_counters():
    ok = diagnostics_msg(_stats(), "ipe", 7).status[0]
    assert (ok.level, ok.message) == (b"\x00", "idle")
    values = {kv.key: kv.value for kv in ok.values}
    assert (values["scenes_received"], values["scenes_dropped"], values["last_compute_s"]) == ("3", "1", "0.5")
    warn = diagnostics_msg(_stats(rejected=2, last_error="markers: x"), "ipe", 7).status[0]
    assert warn.level == b"\x01" and warn.message.endswith("last error: markers: x")
    dead = diagnostics_msg(_stats(workers_alive=0), "ipe", 7).status[0]
    assert (dead.level, dead.message) == (b"\x02", "no worker process alive (of 2)")
