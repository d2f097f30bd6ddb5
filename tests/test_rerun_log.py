"""Rerun recordings of predictions (engine level, no ROS): what is recorded, and that it changes nothing."""

from __future__ import annotations

import numpy as np
from rerun.chunk import RrdReader

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.viz.rerun_log import write_prediction_rrd, write_question_rrd
from tests.helpers import block, floor_scene, without_timing

MODEL = ModelConfig(sigma_m=0.04, samples=4)
QUERY = QuerySpec(queries=frozenset({"fall", "direction", "far"}))
SCENE = floor_scene(block("base block", 0, 0, 0.1), block("top/overhang", 0.08, 0, 0.3))


def test_only_the_logged_samples_record_and_recording_changes_no_outcome():
    plain = predict(SCENE, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=5, budget_s=None))
    recorded = predict(SCENE, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=5, budget_s=None),
                       Context(record_every=50, record_samples=2))
    assert without_timing(plain.to_dict()) == without_timing(recorded.to_dict())
    trajectories = [o.rollouts[0].trajectory for o in recorded.outcomes]
    assert [t is not None for t in trajectories] == [True, True, False, False]
    # a frame every 50 steps of the simulated time (early termination may end a rollout early), plus t = 0
    steps = round(recorded.outcomes[0].rollouts[0].simulated_s / preset("default").time_step_s)
    assert len(trajectories[0]) == 1 + steps // 50 and trajectories[0][0][0] == 0.0
    np.testing.assert_array_equal(trajectories[0][0][1], recorded.outcomes[0].initial_positions_m)


def test_recording_holds_scene_rollouts_outcomes_and_answer(tmp_path):
    prediction = predict(SCENE, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=5, budget_s=None),
                         Context(record_every=100, record_samples=4))
    path = tmp_path / "p.rrd"
    logged = write_prediction_rrd(path, SCENE, prediction, answer={"fall_fraction": prediction.fall_fraction},
                                  stamp_ns=1_700_000_000_000_000_000, rollouts_logged=3)
    assert logged == 3
    chunks = RrdReader(path).stream().to_chunks()
    by_entity: dict[str, list] = {}
    for chunk in chunks:
        by_entity.setdefault(chunk.entity_path, []).append(chunk)
    # names with spaces and slashes are escaped into one entity path part each
    assert "/world/rollouts/0/base\\ block" in by_entity and "/world/rollouts/2/top\\/overhang" in by_entity
    assert not any(e.startswith("/world/rollouts/3") for e in by_entity)
    frames = sum(c.num_rows for c in by_entity["/world/rollouts/0/base\\ block"] if not c.is_static)
    steps = round(prediction.outcomes[0].rollouts[0].simulated_s / preset("default").time_step_s)
    assert frames == 1 + steps // 100
    assert sum(c.num_rows for c in by_entity["/outcomes/fall_fraction"]) == 4
    assert {"/world", "/world/scene/support", "/world/scene/objects/base\\ block", "/world/answer/objects/base\\ block",
            "/answer",
            "/answer/fall_probability"} <= set(by_entity)


def test_will_anything_fall_is_recorded_per_sample(tmp_path):
    query = QuerySpec(queries=frozenset({"any_fall"}))
    prediction = predict(SCENE, Request(model=MODEL, settings=preset("default"), query=query, seed=5, budget_s=None),
                         Context(record_every=100, record_samples=2))
    path = tmp_path / "any.rrd"
    write_prediction_rrd(path, SCENE, prediction, answer=prediction.to_dict(),
                         stamp_ns=1_700_000_000_000_000_000, rollouts_logged=2)
    entities = {chunk.entity_path for chunk in RrdReader(path).stream().to_chunks()}
    assert "/outcomes/any_fall" in entities and "/outcomes/fall_fraction" not in entities


def test_recordings_draw_every_body_in_its_own_shape(tmp_path):
    from ipe_ros.engine.scene.catalogue import capped_tower

    scene = capped_tower()
    prediction = predict(scene,
                         Request(model=ModelConfig(sigma_m=0.02, samples=2), settings=preset("default"), query=QUERY,
                                 seed=1, budget_s=None),
                         Context(record_every=20, record_samples=1))
    path = tmp_path / "capped.rrd"
    write_prediction_rrd(path, scene, prediction, answer=prediction.to_dict(), stamp_ns=1, rollouts_logged=1)
    columns: dict[str, set] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        names = set(chunk.to_record_batch().schema.names)
        columns.setdefault(chunk.entity_path, set()).update(names)

    def has(entity: str, archetype: str) -> bool:
        return any(archetype in name for name in columns.get(entity, ()))

    for base in ("/world/scene/objects", "/world/rollouts/0"):
        assert has(f"{base}/box0", "Boxes3D") and has(f"{base}/ball", "Ellipsoids3D")
        assert has(f"{base}/cone", "Mesh3D")  # a convex hull: its faces
        assert has(f"{base}/cone", "Transform3D")  # moved by a transform, drawn in its own frame


def test_a_question_recording_names_each_variants_rollouts_by_the_question(tmp_path):
    from ipe_ros.engine import ModelConfig, preset
    from ipe_ros.engine import actions as A
    from tests.test_actions import FAR

    answers = A.remove(FAR, ["bottom", "lone"], ModelConfig(sigma_m=0.005, samples=3), preset("default"),
                       record_every=4, record_samples=2)
    path = tmp_path / "question.rrd"
    assert write_question_rrd(path, FAR, answers) == 4  # as is and remove/bottom, 2 samples each
    paths = {chunk.entity_path for chunk in RrdReader(path).stream().to_chunks()}
    assert {"/world/remove/bottom/sample_0/top", "/world/as_is/sample_1/bottom", "/answers/remove/lone"} <= paths


def _blueprint_views(path) -> dict[str, dict]:
    """The views a recording's blueprint opens on: display name -> class, origin and contents."""
    reader = RrdReader(path)
    [store] = reader.blueprints()
    columns: dict[str, dict] = {}
    for chunk in reader.stream(store=store).to_chunks():
        batch = chunk.to_record_batch()
        view = chunk.entity_path.removesuffix("/ViewContents")
        if not view.startswith("/view/"):
            continue
        entry = columns.setdefault(view, {})
        for name in batch.schema.names:
            if ":" in name:
                value = batch.column(name).to_pylist()[-1]
                entry[name.split(":")[1]] = value[0] if isinstance(value, list) and len(value) == 1 else value
    return {v["display_name"]: v for v in columns.values()}


def test_recordings_open_on_a_blueprint_with_the_answer_the_rollouts_and_the_outcomes(tmp_path):
    prediction = predict(SCENE, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=5, budget_s=None),
                         Context(record_every=100, record_samples=4))
    path = tmp_path / "p.rrd"
    write_prediction_rrd(path, SCENE, prediction, answer=prediction.to_dict(), stamp_ns=1, rollouts_logged=3)
    views = _blueprint_views(path)
    assert set(views) == {"answer: fall risk and direction", "answer (JSON)", "sample 0", "sample 1", "sample 2",
                          "fall_fraction per sample", "far_m per sample"}
    assert views["answer: fall risk and direction"]["class_identifier"] == "3D"
    assert views["answer: fall risk and direction"]["query"] == ["+ /world/scene/support/**", "+ /world/answer/**"]
    assert views["sample 2"]["query"] == ["+ /world/scene/support/**", "+ /world/rollouts/2/**"]
    assert views["fall_fraction per sample"]["space_origin"] == "outcome_bars/fall_fraction"
    # each bar view has its data: one bar per sample
    bars = [c for c in RrdReader(path).stream().to_chunks() if c.entity_path == "/outcome_bars/fall_fraction"]
    assert bars and bars[0].is_static


def test_question_recordings_show_one_view_per_variant(tmp_path):
    from ipe_ros.engine import actions as A
    from tests.test_actions import FAR

    answers = A.remove(FAR, ["bottom", "lone"], ModelConfig(sigma_m=0.005, samples=3), preset("default"),
                       record_every=4, record_samples=1)
    path = tmp_path / "q.rrd"
    write_question_rrd(path, FAR, answers)
    views = _blueprint_views(path)
    assert set(views) == {"answers", "as_is", "remove/bottom"}  # the lone block's removal is not simulated: no view
    assert views["remove/bottom"]["query"] == ["+ /world/scene/support/**", "+ /world/remove/bottom/**"]


def test_rerun_is_imported_when_recording_is_switched_on_not_on_the_first_answer(tmp_path):
    import subprocess
    import sys

    from tests.conftest import REPO

    script = f"""
import sys
from ipe_ros.service import PredictionService, ServiceConfig
service = PredictionService(ServiceConfig(), workers=0, publish=print)
assert "rerun" not in sys.modules, "imported without recording"
service.update_config(ServiceConfig(rerun_save_dir={str(tmp_path)!r}))
assert "rerun" in sys.modules, "not imported when recording was switched on"
print("ok")
"""
    run = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr[-2000:]
