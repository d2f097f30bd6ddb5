"""The ROS-free prediction service: keep-latest queue, the Trigger semantics, settings updates, shutdown."""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest

from ipe_ros.engine import ModelConfig, load_scenes
from ipe_ros.engine.request import Request
from ipe_ros.service import NoSceneError, PredictionFailed, PredictionService, ServiceConfig, StampedScene
from tests.ros_harness import wait_until

TOWER = load_scenes("ipe_ros/data/example_tower.json")[0]
SETTINGS = ServiceConfig(request=Request(model=ModelConfig(sigma_m=0.04, samples=4)))


def item(seq: int, scene=TOWER) -> StampedScene:
    return StampedScene(scene=scene, stamp_ns=seq, frame_id="world", scene_id=f"{scene.name}", seq=seq,
                        received_monotonic_s=time.monotonic())


@pytest.fixture
def service():
    published = []
    svc = PredictionService(SETTINGS, workers=0, publish=published.append)
    svc.published = published
    svc.start()
    yield svc
    svc.close()


def test_a_newer_scene_replaces_one_still_waiting(service):
    assert service.submit(item(1)) is False
    wait_until(lambda: service.stats().in_flight, 30.0, "the first prediction to start")
    assert service.submit(item(2)) is False   # waits behind the one in flight
    assert service.submit(item(3)) is True    # replaces 2, which was never started
    wait_until(lambda: service.stats().predicted == 2, 60.0, "two predictions")
    assert [a.source.seq for a in service.published] == [1, 3]
    stats = service.stats()
    assert (stats.received, stats.dropped, stats.waiting, stats.in_flight) == (3, 1, 0, False)
    assert service.published[1].latency_s >= service.published[1].compute_s


def test_trigger_semantics(service):
    with pytest.raises(NoSceneError, match=r"^no scene received yet; publish one on ~/scene"):
        service.predict_latest(1.0)
    service.submit(item(1))
    first = service.predict_latest(60.0)
    assert first.source.seq == 1 and first.prediction.samples == 4
    assert service.predict_latest(60.0) is first          # nothing changed: no new simulation
    service.update_config(SETTINGS.replace_request(model=ModelConfig(sigma_m=0.04, samples=2)))
    second = service.predict_latest(60.0)                   # new settings: predicted again
    assert second.prediction.samples == 2 and second.config_version == 1
    service.reject("markers: bad")
    with pytest.raises(PredictionFailed, match=r"^the latest scene was rejected: markers: bad$"):
        service.predict_latest(1.0)
    assert [a.source.seq for a in service.published] == [1, 1]


def test_trigger_timeout_says_the_answer_will_still_come(service):
    slow = SETTINGS.replace_request(model=ModelConfig(sigma_m=0.04, samples=40))
    service.update_config(slow)
    service.submit(item(1))
    with pytest.raises(TimeoutError, match=r"^no answer within 0.01 s; the prediction goes on and will be "
                                           r"published on ~/prediction$"):
        service.predict_latest(0.01)
    wait_until(lambda: service.stats().predicted == 1, 120.0, "the prediction to be published anyway")


def test_a_failing_prediction_is_reported_and_the_service_goes_on(service):
    bump = SETTINGS.replace_request(query=dataclasses.replace(SETTINGS.request.query, queries=frozenset({"bump"})))
    service.update_config(bump)  # the tower stands on a floor: bump cannot be answered
    service.submit(item(1))
    wait_until(lambda: service.stats().failed_predictions == 1, 30.0, "the failure to be counted")
    assert service.stats().last_error.startswith("queries: the bump query needs a table support")
    service.update_config(SETTINGS)
    service.submit(item(2))
    wait_until(lambda: service.stats().predicted == 1, 60.0, "the next prediction")


def test_close_during_a_prediction_ends_promptly_and_wakes_waiters():
    published = []
    svc = PredictionService(SETTINGS.replace_request(model=ModelConfig(sigma_m=0.04, samples=24)),
                            workers=1, publish=published.append)
    svc.start()
    svc.submit(item(1))
    wait_until(lambda: svc.stats().in_flight, 60.0, "the prediction to start")
    errors = []
    waiter = threading.Thread(target=lambda: errors.append(_failure(svc)))
    waiter.start()
    start = time.monotonic()
    svc.close()
    waiter.join(10.0)
    assert time.monotonic() - start < 15.0
    assert errors == ["the node is shutting down"]
    assert published == [] and svc.stats().closed and svc.pool.worker_pids() == []


def _failure(svc: PredictionService) -> str | None:
    try:
        svc.predict_latest(60.0)
    except PredictionFailed as exc:
        return str(exc)
    return None


def test_bad_worker_count_is_named():
    with pytest.raises(ValueError, match=r"^workers: must be an integer >= 0"):
        PredictionService(SETTINGS, workers=-1, publish=print)


def test_the_self_check_is_counted_and_can_be_turned_off():
    """The zoo ramp of tests/test_fidelity.py, under the fast physics that topples its stack
    (``WRONG_HERE``): its answer is escalated to the reference, and the service counts it; with the
    check off the same scene is answered unverified."""
    from ipe_ros.engine.checking.fidelity import SelfCheck
    from ipe_ros.engine.scene.zoo import zoo_scene, zoo_sigma_m
    from tests.test_fidelity import WRONG_HERE

    ramp = zoo_scene("ramp", 2026, 4)
    config = ServiceConfig(request=Request(model=ModelConfig(sigma_m=zoo_sigma_m(ramp), samples=4), settings=WRONG_HERE,
                                           seed=0))
    svc = PredictionService(config, workers=0, publish=lambda answer: None)
    svc.start()
    try:
        svc.submit(item(1, ramp))
        assert svc.predict_latest(120.0).prediction.fidelity == "escalated"
        stats = svc.stats()
        assert (stats.escalated, stats.contradicted, stats.recent) == (1, 0, ("ok",))
        svc.update_config(config.replace_request(check=SelfCheck(enabled=False)))
        assert svc.predict_latest(120.0).prediction.fidelity == "unverified"
        assert svc.stats().escalated == 1
    finally:
        svc.close()


@pytest.mark.slow
def test_a_newer_question_may_replace_older_ones_about_the_same_scene_each_answered_once(service):
    from ipe_ros.engine.actions.question import question_from_dict
    from ipe_ros.service import QuestionService

    replies = []
    questions = QuestionService(service, publish=lambda message, _source: replies.append(message))
    questions.start()
    try:
        scene = item(1)
        other = item(2)  # another scene: untouched by the replacement
        assert questions.submit(question_from_dict({"id": "slow", "question": "support", "samples": 200}), scene) is None
        wait_until(lambda: any(not r["final"] for r in replies), 60.0, "the slow question's first partial answer")
        for request_id, source in (("waiting", scene), ("elsewhere", other)):
            assert questions.submit(question_from_dict({"id": request_id, "question": "remove", "samples": 2}),
                                    source) is None
        newer = question_from_dict({"id": "newer", "question": "remove", "samples": 2, "cancel_older": True})
        assert questions.submit(newer, scene) is None
        finals = lambda: {r["id"]: r for r in replies if r["final"]}  # noqa: E731
        wait_until(lambda: {"slow", "waiting", "elsewhere", "newer"} <= set(finals()), 60.0, "every final reply")
        replaced = "cancelled: question 'newer' about the same scene replaced it (cancel_older)"
        assert finals()["waiting"]["error"] == replaced and finals()["slow"]["error"] == replaced
        assert "answer" in finals()["newer"] and "answer" in finals()["elsewhere"]
        assert sorted(r["id"] for r in replies if r["final"]) == ["elsewhere", "newer", "slow", "waiting"]
        progress = [r["progress"] for r in replies if r["id"] == "slow" and not r["final"]]
        assert progress and progress[0]["samples_requested"] == 200 and progress[0]["samples_drawn"] == 4
    finally:
        questions.close()
