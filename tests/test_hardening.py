"""Regression tests for issue 16's failures: each failed before the fix. No ROS here (see test_node.py).

1. deep JSON nesting crashed the node (RecursionError); 2. a lone surrogate in a name killed the
prediction thread; 3. unbounded cost (tiny bodies, huge gravity); 4. nonsense accepted (1e15 m,
gravity 1e-300, sigma 1e308); 5. CSV tracebacks; 6. unbounded, Python-flavoured messages;
7. the ROS review's points that live outside the node (recording ids, diagnostics, counters, t).
"""

from __future__ import annotations

import dataclasses
import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from ipe_ros.cli import main
from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, SceneError, predict, preset
from ipe_ros.engine import Context
from ipe_ros.engine.sampling.estimate import mean_interval
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.scene.files import scenes_from_tower_csv
from ipe_ros.engine.scene.format import scene_to_dict, scenes_from_json
from ipe_ros.engine.request import Request
from ipe_ros.service import PredictionService, ServiceConfig, StampedScene
from tests.helpers import block, floor_scene

TOWER = json.loads(example_scene_path().read_text())
CSV_HEADER = (",name,object,friction,mass,pos_x,pos_y,pos_z,quat_w,quat_x,quat_y,quat_z,restitution,scale_x,"
              "scale_y,scale_z,blocktype,ratio\n")
CSV_ROW = "0,t,b0,0.5,1,0,0,0.1,1,0,0,0,0,0.2,0.2,0.2,0,1"


def _tower(**changes) -> str:
    scene = json.loads(json.dumps(TOWER))
    for path, value in changes.items():
        node = scene
        keys = path.split(".")
        for key in keys[:-1]:
            node = node[int(key)] if key.isdigit() else node[key]
        node[keys[-1]] = value
    return json.dumps(scene)


def _refused(text: str) -> SceneError:
    with pytest.raises(SceneError) as info:
        scenes_from_json(text)
    return info.value


# -- 1. deep nesting ------------------------------------------------------------------------------------
def test_json_nested_deeper_than_python_recurses_is_refused_by_name(tmp_path, capsys):
    deep = "[" * 100_000 + "]" * 100_000
    assert str(_refused(deep)) == ("json: nested too deeply to read; a scene nests a few levels (objects, shapes, "
                                   "parts), not hundreds")
    path = tmp_path / "deep.json"
    path.write_text(deep)
    assert main(["predict", str(path), "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip().startswith("ipe: error: json: nested too deeply")


# -- 2. names that are not text --------------------------------------------------------------------------
def test_a_lone_surrogate_in_a_name_is_refused():
    assert str(_refused(_tower(name="\ud800"))) == \
        "name: must be valid Unicode text (it holds a lone surrogate), got '\\ud800'"
    assert _refused(_tower(**{"boxes.0.name": "a\x00b"})).field == "boxes[0].name"
    assert "at most 256 characters" in str(_refused(_tower(name="x" * 300)))


class _Recorder:
    def __init__(self):
        self.answers, self.errors, self.done = [], [], threading.Event()

    def publish(self, answer):
        self.answers.append(answer)
        self.done.set()

    def publish_error(self, source, error):
        self.errors.append((source.seq, error))
        self.done.set()


def _stamped(service, scene):
    return StampedScene(scene=scene, stamp_ns=1, frame_id="world", scene_id=scene.name, seq=service.next_seq(),
                        received_monotonic_s=time.monotonic())


def _wait(event: threading.Event) -> None:
    assert event.wait(60.0), "no answer within 60 s"
    event.clear()


def test_the_prediction_thread_survives_an_exception_and_a_logger_that_raises(monkeypatch):
    import ipe_ros.service.predictions as service_module

    calls = {"n": 0}
    real_predict = service_module.predict

    def flaky_predict(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 1:
            raise TypeError("injected failure")
        return real_predict(*args, **kwargs)

    def hostile_logger(_text):
        raise TypeError("the logger refuses this text")

    monkeypatch.setattr(service_module, "predict", flaky_predict)
    out = _Recorder()
    service = PredictionService(ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.01, samples=2))), workers=0,
                                publish=out.publish, publish_error=out.publish_error, log_error=hostile_logger)
    service.start()
    try:
        scene = floor_scene(block("a", 0, 0, 0.1))
        service.submit(_stamped(service, scene))
        _wait(out.done)
        assert out.errors == [(1, "TypeError: injected failure")]
        assert service.stats().recent == ("failed",)
        service.submit(_stamped(service, scene))
        _wait(out.done)
        assert len(out.answers) == 1 and out.answers[0].prediction.samples == 2
        stats = service.stats()
        assert (stats.failed_predictions, stats.predicted, stats.recent) == (1, 1, ("failed", "ok"))
    finally:
        service.close()


# -- 3. and 4. ranges and the budget ----------------------------------------------------------------------
@pytest.mark.parametrize("changes, message", [
    ({"boxes.0.extents_m": [1e-9, 1e-9, 1e-9]},
     "boxes[0] ('block0').extents_m: every extent must be within [0.001, 10] m (smaller bodies need ever finer "
     "steps; check the units), got [1e-09, 1e-09, 1e-09]"),
    ({"gravity_m_s2": [0, 0, -1e8]}, "gravity_m_s2: the magnitude must be within [0.1, 100] m/s^2 (Earth: 9.81), "
                                     "got [0.0, 0.0, -100000000.0]"),
    ({"gravity_m_s2": [0, 0, -1e-300]}, "gravity_m_s2: the magnitude must be within [0.1, 100] m/s^2 (Earth: 9.81), "
                                        "got [0.0, 0.0, -1e-300]"),
    ({"boxes.0.position_m": [1e15, 0, 0.1]}, "boxes[0] ('block0').position_m: position in metres must be within "
                                             "+-10000 m of the scene frame's origin (use a frame near the scene), "
                                             "got [1000000000000000.0, 0.0, 0.1]"),
    ({"boxes.0.mass_kg": 1e9}, "boxes[0] ('block0').mass_kg: the mass must be within [1e-06, 1e+06] kg (check the "
                               "units), got 1e+09 kg"),
    ({"boxes.0.mass_kg": 1e-4}, "boxes: 'block9' is 4.08e+04 times as heavy as 'block0'; mass ratios above 1000:1 are "
                                "beyond what the solver converges on (check the units)"),
    ({"gravity_m_s2": [0, 0, -1e308]}, "gravity_m_s2: the magnitude must be within [0.1, 100] m/s^2 (Earth: 9.81), "
                                       "got [0.0, 0.0, -1e+308]"),
    ({"boxes.0.friction": 1e300}, "boxes[0] ('block0').friction: friction must be <= 10, got 1e+300"),
])
def test_values_outside_the_physical_ranges_are_refused_by_name(changes, message):
    assert str(_refused(_tower(**changes))) == message


def test_model_values_outside_their_ranges_are_refused():
    with pytest.raises(ConfigError, match=r"^sigma_m: must be at most 10 m \(check the units\), got 1e\+308$"):
        ModelConfig(sigma_m=1e308)
    with pytest.raises(ConfigError, match=r"^phi_m_s2: must be at most 100 m/s\^2"):
        ModelConfig(phi_m_s2=(1e6,))


def test_a_scene_whose_one_rollout_cannot_fit_the_budget_is_refused_up_front():
    scene = dataclasses.replace(scenes_from_json(json.dumps(TOWER))[0], horizon_s=60.0)
    with pytest.raises(ConfigError, match=r"^budget_s: one rollout of this scene takes up to 60000 steps x 10 bodies"):
        predict(scene,
                Request(model=ModelConfig(sigma_m=0.04, samples=2), settings=preset("paper"), query=QuerySpec(),
                        budget_s=1.0))


def test_a_prediction_stops_at_its_budget_and_answers_with_what_it_has():
    scene = scenes_from_json(json.dumps(TOWER))[0]
    start = time.monotonic()
    p = predict(scene,
                Request(model=ModelConfig(sigma_m=0.04, samples=200), settings=preset("paper"), query=QuerySpec(),
                        budget_s=1.5))
    took = time.monotonic() - start
    assert took < 1.5 + 1.0
    assert p.stopped_by == "budget" and p.budget_skipped_samples > 0 and p.failed_samples == 0
    assert p.samples + p.budget_skipped_samples == 200 and p.request["budget_s"] == 1.5
    assert p.samples > 0 and 0 <= p.fall_fraction <= 1  # with none, predict says so (the test below)


@pytest.mark.parametrize("asked", ["prediction", "question"])
def test_a_budget_that_no_sample_finished_in_is_an_error_never_an_empty_answer(asked, monkeypatch):
    """Every sample cut off (here: the budget ran out before the first step) used to give an answer
    with k = 0 and every probability null, published like any other."""
    from ipe_ros.engine import actions
    from ipe_ros.engine.sampling import montecarlo

    scene = scenes_from_json(json.dumps(TOWER))[0]
    real_time = time.time
    # the one loop sets every deadline: an hour ago, so every rollout is past its budget
    monkeypatch.setattr(montecarlo, "time", type("Clock", (), {"time": staticmethod(lambda: real_time() - 3600),
                                                                "perf_counter": time.perf_counter}))
    model = ModelConfig(sigma_m=0.04, samples=4)
    with pytest.raises(ConfigError) as info:
        if asked == "prediction":
            predict(scene, Request(model=model, settings=preset("default"), query=QuerySpec(), budget_s=2.0))
        else:
            actions.remove(scene, ["block9"], model, preset("default"), budget_s=2.0)
    cut = 4 if asked == "prediction" else 8
    assert str(info.value) == (f"budget_s: no sample finished within the budget of 2 s ({cut} cut off); raise the "
                               "budget, or ask for fewer samples, objects or contact pairs")


# -- 5. the tower CSV -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("body, message", [
    ("0,t,b0,0.5,1,0,0,0.1\n", "rows.csv:2: fewer values than the 18 columns; complete the row"),
    ('0,"t,b0,0.5,1\n', "rows.csv: not readable as CSV after line 1 (unexpected end of data)"),
    (CSV_ROW + ",7\n", "rows.csv:2: 19 values on a row of a 18-column file; remove the extra values"),
    (CSV_ROW[:-1] + "abc\n", "rows.csv:2.ratio: must be a number, got 'abc'"),
])
def test_malformed_tower_csv_rows_are_refused_by_line(tmp_path, body, message):
    path = tmp_path / "rows.csv"
    path.write_text(CSV_HEADER + body)
    with pytest.raises(SceneError) as info:
        scenes_from_tower_csv(path)
    assert str(info.value) == message


def test_unknown_tower_csv_columns_are_refused(tmp_path):
    path = tmp_path / "cols.csv"
    path.write_text(CSV_HEADER.strip() + ",colour\n" + CSV_ROW + ",red\n")
    with pytest.raises(SceneError, match=r"^cols.csv: unknown column 'colour'; the columns are name, object"):
        scenes_from_tower_csv(path)


# -- 6. bounded messages in JSON's words ------------------------------------------------------------------------
def test_a_huge_value_is_not_echoed_whole():
    error = _refused(_tower(**{"boxes.0.extents_m": [0.1] * 500_000}))
    assert len(str(error)) < 400 and str(error).endswith("characters)")
    assert str(_refused(_tower(**{"boxes.0.name": None}))) == "boxes[0].name: must be a string, got null"


# -- 7. counters, recordings, intervals ---------------------------------------------------------------------------
def test_a_scene_predicted_again_counts_once_and_recordings_get_their_own_ids(tmp_path, monkeypatch):
    import rerun as rr

    ids = []
    real = rr.RecordingStream

    def recording(*args, **kwargs):
        ids.append(kwargs["recording_id"])
        return real(*args, **kwargs)

    monkeypatch.setattr(rr, "RecordingStream", recording)
    out = _Recorder()
    config = ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.01, samples=2)), rerun_save_dir=str(tmp_path),
                           rerun_rollouts_logged=1)
    service = PredictionService(config, workers=0, publish=out.publish, publish_error=out.publish_error)
    service.start()
    try:
        service.submit(_stamped(service, floor_scene(block("a", 0, 0, 0.1))))
        _wait(out.done)
        service.update_config(ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.02, samples=2)),
                                            rerun_save_dir=str(tmp_path), rerun_rollouts_logged=1))
        service.predict_latest(60.0)  # the same scene under the new parameters
        stats = service.stats()
        assert (stats.received, stats.predicted, stats.predictions) == (1, 1, 2)
        assert len(ids) == 2 and ids[0] != ids[1]
    finally:
        service.close()


def test_a_failed_recording_is_counted_and_said_in_the_answer(tmp_path):
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("")
    out = _Recorder()
    config = ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.01, samples=2)),
                           rerun_save_dir=str(blocker / "rrd"))
    service = PredictionService(config, workers=0, publish=out.publish)
    service.start()
    try:
        service.submit(_stamped(service, floor_scene(block("a", 0, 0, 0.1))))
        _wait(out.done)
        answer = out.answers[0]
        assert answer.rrd_path is None and "failed" in answer.rrd_error
        assert answer.to_dict()["rrd_error"] == answer.rrd_error
        stats = service.stats()
        assert stats.rrd_failures == 1 and stats.recent == ("rrd_failed",)
    finally:
        service.close()


def test_the_far_interval_uses_the_t_quantile():
    values = np.array([0.1, 0.3, 0.2, 0.4, 0.25, 0.35, 0.15, 0.3])
    lo, hi = mean_interval(values)
    half = 2.3646242510102993 * values.std(ddof=1) / math.sqrt(8)  # t(0.975, 7)
    assert (hi - lo) / 2 == pytest.approx(half, rel=1e-9)


def test_a_scene_written_by_the_engine_still_loads():
    scene = scenes_from_json(json.dumps(TOWER))[0]
    assert scenes_from_json(json.dumps(scene_to_dict(scene)))[0] == scene


def test_a_marker_of_denormal_size_is_refused_by_name():
    from msg_bridge.markers import markers_to_scene, scene_to_markers

    msg = scene_to_markers(scenes_from_json(json.dumps(TOWER))[0], "world")
    msg.markers[1].scale.x = 1e-320
    with pytest.raises(SceneError, match=r"^objects\[0\] \('block0'\)\.shape: every extent must be within "
                                         r"\[0\.001, 10\] m .* got \[1e-320, 0\.6"):
        markers_to_scene(msg)


def test_the_cli_refuses_an_absurd_sigma_in_one_line(capsys):
    assert main(["predict", str(example_scene_path()), "--sigma", "1e308", "--json", "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip() == "ipe: error: --sigma: must be at most 10 m (check the units), got 1e+308"


def _closed_port() -> int:
    import socket

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]  # nothing listens there once closed


def test_a_dead_viewer_never_holds_up_an_answer_and_is_reported(tmp_path):
    port = _closed_port()
    out = _Recorder()
    config = ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.01, samples=2)), rerun_save_dir=str(tmp_path),
                           rerun_connect_url=f"rerun+http://127.0.0.1:{port}/proxy")
    service = PredictionService(config, workers=0, publish=out.publish)
    service.start()
    try:
        started = time.monotonic()
        service.submit(_stamped(service, floor_scene(block("a", 0, 0, 0.1))))
        _wait(out.done)
        assert time.monotonic() - started < 10.0  # before: no answer within 80 s
        answer = out.answers[0]
        assert answer.rrd_error == (f"streaming to the viewer failed: no viewer at 127.0.0.1:{port} (Connection "
                                    f"refused); the recording is in {tmp_path}/{Path(answer.rrd_path).name}")
        assert Path(answer.rrd_path).stat().st_size > 0  # the file does not depend on the viewer
        assert service.stats().rrd_failures == 1
    finally:
        started = time.monotonic()
        service.close()
        assert time.monotonic() - started < 2.0


def test_a_viewer_that_accepts_and_stays_silent_is_left_to_a_helper_that_ends_itself(tmp_path):
    import socket

    from ipe_ros.viz import rerun_log

    with socket.socket() as silent:  # accepts connections (kernel backlog), never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        path = tmp_path / "x.rrd"
        scene = floor_scene(block("a", 0, 0, 0.1))
        prediction = predict(scene,
                             Request(model=ModelConfig(sigma_m=0.01, samples=1), settings=preset("default"),
                                     query=QuerySpec(queries=frozenset({"fall"})), check=None, budget_s=None),
                             Context(record_every=10, record_samples=1))
        started = time.monotonic()
        rerun_log.write_prediction_rrd(path, scene, prediction, answer=prediction.to_dict(), stamp_ns=0,
                                       rollouts_logged=1, connect_url=f"rerun+http://127.0.0.1:{silent.getsockname()[1]}")
        assert time.monotonic() - started < 3.0 and path.stat().st_size > 0  # before: no return within 80 s
        helper = rerun_log._STREAMERS[-1]
        assert helper.wait(timeout=15.0) == 1  # gave up by itself: flush timed out, os._exit


@pytest.mark.parametrize("shape, message", [
    ({"type": "convex", "vertices_m": [[0.1 * np.cos(a), 0.1 * np.sin(a), z] for a in np.linspace(0, 6.28, 50_000)
                                       for z in (0.0, 0.1)]},
     "objects[0] ('block0').shape.vertices_m: 100000 points exceed the maximum of 1024 for one hull; decimate the mesh"),
    ({"type": "compound", "parts": [{"shape": {"type": "box", "extents_m": [0.01, 0.01, 0.01]},
                                     "position_m": [0.01 * (i % 100), 0.01 * (i // 100), 0.0],
                                     "orientation_xyzw": [0, 0, 0, 1]} for i in range(10_000)]},
     "objects[0] ('block0').shape.parts: 10000 parts exceed the maximum of 256 for one compound; merge parts into hulls"),
])
def test_shapes_whose_geometry_alone_would_outrun_the_budget_are_refused_by_counting(shape, message):
    from ipe_ros.engine import load_scenes

    scene = scene_to_dict(load_scenes(example_scene_path())[0])
    scene["objects"][0]["shape"] = shape
    started = time.perf_counter()
    with pytest.raises(SceneError) as caught:
        scenes_from_json(json.dumps(scene))
    assert str(caught.value) == message
    assert time.perf_counter() - started < 5.0  # counted, never hulled (before: 12-14 s on a 10 s budget)
