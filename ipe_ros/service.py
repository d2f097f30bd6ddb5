"""Prediction as a service, without ROS: a keep-latest scene slot, one prediction thread, the pool.

The ROS node (``ipe_ros.ros.node``) only converts messages and hands scenes to :class:`PredictionService`;
everything that takes time happens here, off the executor:

* ``submit`` stores a scene in a one-slot queue. A newer scene replaces one still waiting (the
  replaced one is counted as ``dropped``): a robot wants the answer for the world as it is now,
  not for a backlog.
* One prediction thread takes the waiting scene, runs the Monte Carlo IPE in the worker pool,
  optionally writes a rerun ``.rrd``, and calls ``publish(answer)``. One prediction is in flight
  at a time: the pool already uses every core for the k samples of one scene, so a second
  prediction would only make both slower.
* ``predict_latest`` (the Trigger service) waits for an answer on the newest scene with the current
  config, reusing the last answer when it is already that.
* A worker that dies is replaced by the pool and its samples are run again; samples lost twice
  are counted as failed in the answer (``failed_samples``), never silently dropped.
"""

from __future__ import annotations

import collections
import dataclasses
import importlib
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from .engine import (AdaptiveStop, ConfigError, ModelConfig, Prediction, QuerySpec, Scene, SimSettings, WorkerPool,
                     predict, preset)
from .engine.config import DEFAULT_BUDGET_S, DEFAULT_MODEL, DEFAULT_PRESET, DEFAULT_QUERIES
from .engine.errors import SceneError, clip, shown
from .engine.inputs import as_spelled
from .engine.fidelity import DEFAULT_CHECK, SelfCheck
from .engine.sampler import check_request
from .engine.scene import DEFAULT_MAX_OBJECTS


def _file_safe(text: str, limit: int) -> str:
    """``text`` as a file-name part: letters, digits, - _ . kept, anything else _."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)[:limit]


@dataclass(frozen=True)
class ServiceConfig:
    """Everything a prediction depends on besides the scene; replaced as a whole on updates.

    model, settings, query, seed: the IPE's inputs, the simulation settings, the queries, the seed.
    max_objects: scenes with more objects are refused.
    rerun_save_dir: folder for one ``.rrd`` per prediction, or None for no rerun logging.
    rerun_rollouts_logged: how many sampled rollouts each ``.rrd`` shows.
    rerun_frame_period_s: simulated seconds between recorded frames of a logged rollout.
    rerun_connect_url: also stream to a running viewer at this gRPC URL (never spawns one).
    """

    model: ModelConfig = DEFAULT_MODEL
    settings: SimSettings = preset(DEFAULT_PRESET)
    query: QuerySpec = QuerySpec(queries=DEFAULT_QUERIES)
    seed: int = 0
    max_objects: int = DEFAULT_MAX_OBJECTS
    rerun_save_dir: str | None = None
    rerun_rollouts_logged: int = 8
    rerun_frame_period_s: float = 0.02
    rerun_connect_url: str | None = None
    stop: AdaptiveStop | None = None  # anytime sampling (deadline / interval width), None: all k
    budget_s: float = DEFAULT_BUDGET_S  # wall seconds a prediction may take (see engine.predict)
    gravity_aligned_frames: tuple[str, ...] = ()  # frames whose -z is gravity; () trusts every frame
    check: SelfCheck = DEFAULT_CHECK  # how each prediction checks its fast physics (engine.fidelity)
    #: ``model.perception == "depth"``: a scene is predicted from the newest depth image taken at most
    #: this many seconds before or after its stamp
    depth_max_age_s: float = 0.5


@dataclass(frozen=True)
class StampedScene:
    """A scene as received: its header (stamp in ns since the epoch, frame), an id and a sequence number."""

    scene: Scene
    stamp_ns: int
    frame_id: str
    scene_id: str
    seq: int = 0
    received_monotonic_s: float = 0.0


@dataclass(frozen=True)
class Answer:
    """One published prediction: the scene it answers, the prediction, and what it cost.

    compute_s: wall time of the Monte Carlo run (+ rerun logging), seconds.
    latency_s: from receipt of the scene to the answer, seconds (includes waiting behind another).
    """

    source: StampedScene
    prediction: Prediction
    compute_s: float
    latency_s: float
    config_version: int
    rrd_path: str | None = None
    rollouts_logged: int = 0
    rrd_error: str | None = None  # why the recording could not be written, if it could not

    def to_dict(self) -> dict[str, Any]:
        """The published JSON: ``ipe predict --json``'s fields plus stamp, frame, ids and timing."""
        out = self.prediction.to_dict()
        out.update(stamp=stamp_dict(self.source.stamp_ns), frame_id=self.source.frame_id,
                   scene_id=self.source.scene_id, scene_seq=self.source.seq, compute_s=self.compute_s,
                   latency_s=self.latency_s, rrd_path=self.rrd_path, rollouts_logged=self.rollouts_logged,
                   rrd_error=self.rrd_error)
        return out


def stamp_dict(stamp_ns: int) -> dict[str, int]:
    """A stamp in ns since the epoch as the published JSON writes it: {"sec", "nanosec"}."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def error_answer(source: StampedScene, error: str) -> dict[str, Any]:
    """What ~/prediction carries when a prediction failed: the scene it was for and why."""
    return {"error": error, "scene": source.scene.name, "scene_id": source.scene_id, "scene_seq": source.seq,
            "stamp": stamp_dict(source.stamp_ns), "frame_id": source.frame_id}


def refusal_answer(reason: str, scene_id: str, stamp_ns: int, frame_id: str, input_topic: str) -> dict[str, Any]:
    """What ~/prediction carries for a scene refused on arrival: the same fields as a failed
    prediction's error answer (no sequence number: the scene was never accepted) and the topic it came on."""
    return {"error": reason, "scene": scene_id or None, "scene_id": scene_id, "scene_seq": None,
            "stamp": stamp_dict(max(0, stamp_ns)), "frame_id": frame_id, "refused_on": input_topic}


def _load_rerun_if_recording(config: ServiceConfig) -> None:
    """Import rerun when recording is (switched) on, not on the first answer (the import takes ~0.4 s);
    without recording rerun is never imported."""
    if config.rerun_save_dir is not None or config.rerun_connect_url is not None:
        importlib.import_module(".viz.rerun_log", __package__)


#: How many recent inputs and predictions the health level looks back on.
RECENT_EVENTS = 10


@dataclass(frozen=True)
class ServiceStats:
    """Counters for diagnostics.

    received: scenes accepted; predicted: distinct scenes answered (never more than received);
    predictions: answers made (a scene is predicted again after a parameter change); dropped:
    scenes replaced while waiting (keep-latest); budget_stops: answers cut short by the budget.
    refined_samples: rollouts the self-check reran at the reference because they ended unhealthy;
    escalated / contradicted: answers whose fast physics the reference contradicted, recomputed at
    the reference / left as they were because the budget ran out (engine.fidelity).
    recent: the last RECENT_EVENTS inputs and predictions, oldest first: "ok", "rejected",
    "failed", "partial" (some samples failed or were cut by the budget), "contradicted" or "rrd_failed".
    in_flight_s: how long the prediction in flight has run (None: none in flight).
    """

    received: int
    predicted: int
    predictions: int
    dropped: int
    rejected: int
    failed_predictions: int
    failed_samples: int
    budget_stops: int
    rrd_failures: int
    waiting: int
    in_flight: bool
    in_flight_s: float | None
    workers: int
    workers_alive: int
    worker_replacements: int
    last_compute_s: float | None
    last_error: str | None
    closed: bool
    recent: tuple[str, ...] = ()
    budget_s: float | None = None
    refined_samples: int = 0
    escalated: int = 0
    contradicted: int = 0


class NoSceneError(RuntimeError):
    """The service was asked to predict before any valid scene arrived."""


class PredictionFailed(RuntimeError):
    """A prediction could not be made (the reason says why); the service keeps running."""


@dataclass
class _Waiter:
    seq: int
    version: int
    event: threading.Event = field(default_factory=threading.Event)
    answer: Answer | None = None
    error: str | None = None


class PredictionService:
    """Keep-latest scene queue + one prediction thread + a worker pool. Thread-safe."""

    def __init__(self, config: ServiceConfig, *, workers: int, publish: Callable[[Answer], None],
                 log_error: Callable[[str], None] = lambda _msg: None,
                 log_info: Callable[[str], None] = lambda _msg: None, start_method: str = "forkserver",
                 publish_error: Callable[[StampedScene, str], None] = lambda _source, _error: None,
                 pool=None):
        """``pool``: where samples run instead of ``workers`` local processes (e.g. an
        ``engine.cluster.DaskMap``); anything with WorkerPool's ``map``, ``warm``, ``worker_pids``,
        ``replacements`` and ``close``."""
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
            raise ValueError(f"workers: must be an integer >= 0 (0 runs samples in the prediction thread), got {workers!r}")
        self._config = config
        self._version = 0
        self._publish = publish
        self._publish_error = publish_error
        self._log_error = log_error
        self._log_info = log_info
        self._pool = pool if pool is not None else WorkerPool(workers, start_method=start_method) if workers > 0 else None
        self.workers = len(pool.worker_pids()) if pool is not None else workers
        self._cond = threading.Condition()
        self._depth = None  # (vision.depth.DepthObservation, stamp ns, frame): the newest depth image
        self._pending: StampedScene | None = None
        self._latest: StampedScene | None = None
        self._latest_rejected: str | None = None  # why the newest input was refused, if it was
        self._last_answer: Answer | None = None
        self._in_flight: tuple[int, int] | None = None  # (seq, config version) being computed
        self._in_flight_item: StampedScene | None = None
        self._waiters: list[_Waiter] = []
        self._closing = False
        self._seq = 0
        self._counts = dict(received=0, predicted=0, predictions=0, dropped=0, rejected=0, failed_predictions=0,
                            failed_samples=0, budget_stops=0, rrd_failures=0, refined_samples=0, escalated=0,
                            contradicted=0)
        self._recent: collections.deque[str] = collections.deque(maxlen=RECENT_EVENTS)
        self._last_predicted_seq = 0
        self._in_flight_since: float | None = None
        self._last_compute_s: float | None = None
        self._recordings = 0
        self._last_error: str | None = None
        self._thread = threading.Thread(target=self._run, name="ipe-prediction", daemon=True)
        _load_rerun_if_recording(config)

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def close(self, timeout_s: float = 1.5, reason: str = "the node is shutting down") -> None:
        """Stop taking work, answer the scene waiting and the one in flight with an error naming
        ``reason`` (every accepted scene hears back once), stop the workers (those still busy after
        half a second are terminated), join the thread: done within ~``timeout_s``."""
        with self._cond:
            self._closing = True
            abandoned = [item for item in (self._pending, self._in_flight_item) if item is not None]
            self._pending = None
            for w in self._waiters:
                w.error = reason
                w.event.set()
            self._waiters.clear()
            self._cond.notify_all()
        for item in abandoned:  # the prediction thread publishes nothing once closing (see _serve)
            self._report_failure(item, f"{reason}: the prediction was cancelled")
        if self._pool is not None:
            # cancels samples not yet started; running ones get half a second (their answers are
            # dropped anyway: the waiters were told the node is shutting down), so that with the
            # node's own teardown a signal still ends it within 2 s on a loaded machine
            self._pool.close(grace_s=0.5)
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    @property
    def pool(self) -> WorkerPool | None:
        return self._pool

    # -- inputs (called from executor callbacks: must return at once) ---------------------------
    @property
    def config(self) -> ServiceConfig:
        return self._config

    def update_config(self, config: ServiceConfig) -> None:
        """Applies to the next prediction (the one in flight keeps the config it started with)."""
        _load_rerun_if_recording(config)
        with self._cond:
            self._config = config
            self._version += 1

    def next_seq(self) -> int:
        with self._cond:
            self._seq += 1
            return self._seq

    def check(self, scene: Scene, frame_id: str | None = None, frame_field: str = "frame_id") -> None:
        """Raise SceneError/ConfigError if the current config cannot answer this scene (in this frame).

        The physics takes the frame's -z axis as gravity: a scene in a frame not known to be
        gravity-aligned would be answered wrongly, so it is refused (``frame_field`` names where the
        frame came from)."""
        config = self._config
        frames = config.gravity_aligned_frames
        if frame_id is not None and frames and frame_id not in frames:
            raise SceneError(frame_field, f"{shown(frame_id)} is not a gravity-aligned frame ({', '.join(frames)}); "
                                          "transform the scene into one of them, or add the frame to the "
                                          "gravity_aligned_frames parameter if its -z axis is gravity")
        try:
            check_request(scene, config.query, config.max_objects, model=config.model, settings=config.settings,
                          budget_s=config.budget_s)
        except ConfigError as exc:  # named as the node's parameters spell it
            raise as_spelled(exc, "ros") from None

    def submit(self, item: StampedScene) -> bool:
        """Queue a checked scene; returns True when it replaced one still waiting."""
        with self._cond:
            if self._closing:
                return False
            self._counts["received"] += 1
            replaced = self._pending is not None
            if replaced:
                self._counts["dropped"] += 1
            self._pending = item
            self._latest = item
            self._latest_rejected = None
            self._cond.notify_all()
            return replaced

    def latest_scene(self) -> StampedScene | None:
        """The newest accepted scene (what ``~/ask`` questions are about by default)."""
        with self._cond:
            return self._latest

    def reject(self, reason: str) -> None:
        """Count (and remember) a scene that could not be read or validated."""
        with self._cond:
            self._counts["rejected"] += 1
            self._last_error = reason
            self._latest_rejected = reason
            self._recent.append("rejected")

    def predict_latest(self, timeout_s: float) -> Answer:
        """An answer for the newest scene under the current config (reused when already made).

        Raises NoSceneError, PredictionFailed (with the reason; also when the newest input was
        rejected), or TimeoutError.
        """
        with self._cond:
            if self._closing:
                raise PredictionFailed("the node is shutting down")
            if self._latest_rejected is not None:
                raise PredictionFailed(f"the latest scene was rejected: {self._latest_rejected}")
            latest = self._latest
            if latest is None:
                raise NoSceneError("no scene received yet; publish one on ~/scene (MarkerArray) or ~/scene_json")
            last = self._last_answer
            if last is not None and last.source.seq >= latest.seq and last.config_version >= self._version:
                return last
            waiter = _Waiter(seq=latest.seq, version=self._version)
            self._waiters.append(waiter)
            in_flight_covers = (self._in_flight is not None and self._in_flight[0] >= latest.seq
                                and self._in_flight[1] >= self._version)
            if not in_flight_covers and (self._pending is None or self._pending.seq < latest.seq):
                self._pending = latest  # re-run the newest scene with the new config
            self._cond.notify_all()
        if not waiter.event.wait(timeout_s):
            with self._cond:
                if waiter in self._waiters:
                    self._waiters.remove(waiter)
            raise TimeoutError(f"no answer within {timeout_s:g} s; the prediction goes on and will be "
                               "published on ~/prediction")
        if waiter.error is not None:
            raise PredictionFailed(waiter.error)
        assert waiter.answer is not None  # set together with the event
        return waiter.answer

    def stats(self) -> ServiceStats:
        with self._cond:
            pids = self._pool.worker_pids() if self._pool is not None else []
            since = self._in_flight_since
            return ServiceStats(**self._counts, waiting=int(self._pending is not None),
                                in_flight=self._in_flight is not None,
                                in_flight_s=None if since is None else time.monotonic() - since,
                                recent=tuple(self._recent), budget_s=self._config.budget_s, workers=self.workers,
                                workers_alive=len(pids) if self._pool is not None else 0,
                                worker_replacements=self._pool.replacements if self._pool is not None else 0,
                                last_compute_s=self._last_compute_s, last_error=self._last_error,
                                closed=self._closing)

    # -- the prediction thread ---------------------------------------------------------------------
    def _run(self) -> None:
        if self._pool is not None:
            try:
                self._pool.warm()  # start workers now, not on the first scene
                self._log_info(f"{self.workers} worker process(es) ready: {self._pool.worker_pids()}")
            except RuntimeError:
                return  # closed before it started
            except Exception as exc:  # noqa: BLE001 - the first prediction will retry and report
                self._log_error(f"starting worker processes failed: {exc}")
        while True:
            with self._cond:
                while not self._closing and self._pending is None:
                    self._cond.wait()
                if self._closing:
                    return
                item, self._pending = self._pending, None
                config, version = self._config, self._version
                self._in_flight, self._in_flight_item = (item.seq, version), item
                self._in_flight_since = time.monotonic()
            try:
                self._serve(item, config, version)
            except Exception as exc:  # noqa: BLE001 - the thread must outlive any one prediction
                error = clip(f"internal error: {''.join(traceback.format_exception_only(type(exc), exc)).strip()}", 600)
                with self._cond:
                    self._in_flight = self._in_flight_since = self._in_flight_item = None
                    if self._closing:
                        return  # close() answered it
                    self._counts["failed_predictions"] += 1
                    self._last_error = error
                    self._recent.append("failed")
                    for w in list(self._waiters):  # nobody waits for an answer that will not come
                        if item.seq >= w.seq:
                            self._waiters.remove(w)
                            w.error = error
                            w.event.set()
                self._report_failure(item, error)
            if self._closing:
                return

    def _report_failure(self, item: StampedScene, error: str) -> None:
        for report in (lambda: self._log_error(f"prediction for {item.scene_id} failed: {error}"),
                       lambda: self._publish_error(item, error)):
            try:
                report()
            except Exception:  # noqa: BLE001 - reporting trouble (a logger refusing text) must not stop the thread
                pass

    def _serve(self, item: StampedScene, config: ServiceConfig, version: int) -> None:
        """One prediction: compute, hand to waiters, count, publish."""
        answer, error = self._predict(item, config, version)
        with self._cond:
            self._in_flight = self._in_flight_since = self._in_flight_item = None
            if self._closing:
                return  # close() answered it and its waiters
            done = [w for w in self._waiters if item.seq >= w.seq and version >= w.version]
            for w in done:
                self._waiters.remove(w)
                w.answer, w.error = answer, error
                w.event.set()
            if answer is not None:
                prediction = answer.prediction
                self._last_answer = answer
                self._counts["predictions"] += 1
                if item.seq > self._last_predicted_seq:  # a scene predicted again is not a new scene
                    self._counts["predicted"] += 1
                    self._last_predicted_seq = item.seq
                self._counts["failed_samples"] += prediction.failed_samples
                self._counts["budget_stops"] += prediction.stopped_by == "budget"
                self._counts["rrd_failures"] += answer.rrd_error is not None
                self._counts["refined_samples"] += prediction.refined_samples
                self._counts["escalated"] += prediction.fidelity == "escalated"
                self._counts["contradicted"] += prediction.fidelity == "contradicted"
                self._last_compute_s = answer.compute_s
                if answer.rrd_error is not None:
                    self._last_error = answer.rrd_error
                partial = prediction.failed_samples or prediction.stopped_by == "budget" or not prediction.samples
                self._recent.append("rrd_failed" if answer.rrd_error else
                                    "contradicted" if prediction.fidelity == "contradicted" else
                                    "partial" if partial else "ok")
            else:
                self._counts["failed_predictions"] += 1
                self._last_error = error
                self._recent.append("failed")
        if answer is not None:
            try:
                self._publish(answer)
            except Exception as exc:  # noqa: BLE001 - a publisher error must not stop the thread
                self._report_failure(item, f"publishing the prediction failed: {exc}")
        else:
            self._report_failure(item, error or "unknown error")

    def set_depth(self, observation, stamp_ns: int, frame_id: str) -> None:
        """The newest depth image (``vision.depth.DepthObservation``), when it was taken, and the frame
        its camera pose is in (scenes in another frame cannot use it)."""
        with self._cond:
            self._depth = (observation, int(stamp_ns), frame_id)

    def latest_depth_stamp_ns(self) -> int | None:
        with self._cond:
            return None if self._depth is None else self._depth[1]

    def _perceived(self, item: StampedScene, config: ServiceConfig):
        """The depth posterior's scenes for this scene, from the depth image nearest its stamp."""
        from .engine.vision import depth

        with self._cond:
            latest = self._depth
        if latest is None:
            raise ConfigError("perception", "depth: no depth image received yet; publish ~/depth/image with "
                                            "~/depth/camera_info and the camera pose (~/depth/camera_pose or the "
                                            "depth.camera_pose parameter)")
        observation, stamp_ns, frame_id = latest
        if frame_id != item.frame_id:
            raise ConfigError("perception", f"depth: the camera pose is in {frame_id!r} but the scene in "
                                            f"{item.frame_id!r}; give both in one frame")
        age = abs(stamp_ns - item.stamp_ns) / 1e9
        if age > config.depth_max_age_s:
            raise ConfigError("perception", f"depth: the newest depth image is {age:.3g} s from the scene's stamp, more "
                                            f"than depth.max_age_s = {config.depth_max_age_s:g} s")
        return depth.perceive_depth_for(item.scene, config.model.samples, (observation,), config.seed)

    def _predict(self, item: StampedScene, config: ServiceConfig, version: int) -> tuple[Answer | None, str | None]:
        start = time.perf_counter()
        record_every = 0
        if config.rerun_save_dir and config.rerun_rollouts_logged > 0:
            record_every = max(1, round(config.rerun_frame_period_s / config.settings.time_step_s))
        try:
            perceived = self._perceived(item, config) if config.model.perception == "depth" else None
            prediction = predict(item.scene, config.model, config.settings, config.query, seed=config.seed,
                                 map_fn=self._pool.map if self._pool is not None else None,
                                 record_every=record_every, record_samples=config.rerun_rollouts_logged,
                                 max_objects=config.max_objects, stop=config.stop, budget_s=config.budget_s,
                                 check=config.check, perceived=perceived)
        except ValueError as exc:  # SceneError / ConfigError: the scene no longer fits a new config
            return None, str(exc)
        except Exception as exc:  # noqa: BLE001 - report, keep serving
            return None, "".join(traceback.format_exception_only(type(exc), exc)).strip()
        if self._closing:
            return None, "the node is shutting down"
        answer = Answer(source=item, prediction=prediction, compute_s=time.perf_counter() - start,
                        latency_s=0.0, config_version=version)
        if record_every:
            answer = self._write_rrd(answer, config)
        now = time.monotonic()
        latency = now - item.received_monotonic_s if item.received_monotonic_s else answer.compute_s
        return dataclasses.replace(answer, compute_s=time.perf_counter() - start, latency_s=latency), None

    def _write_rrd(self, answer: Answer, config: ServiceConfig) -> Answer:
        from .viz import rerun_log  # imported on first use: rerun is only needed when logging

        item = answer.source
        safe = _file_safe(item.scene_id, 80)
        with self._cond:
            self._recordings += 1  # one file per prediction, also when a scene is predicted again
            number = self._recordings
        path = Path(config.rerun_save_dir) / f"ipe_{number:06d}_scene{item.seq}_{safe}.rrd"
        answer = dataclasses.replace(answer, rrd_path=str(path.resolve()),
                                     rollouts_logged=min(config.rerun_rollouts_logged, answer.prediction.samples))
        try:
            logged = rerun_log.write_prediction_rrd(path, item.scene, answer.prediction, answer=answer.to_dict(),
                                                    stamp_ns=item.stamp_ns,
                                                    rollouts_logged=config.rerun_rollouts_logged,
                                                    connect_url=config.rerun_connect_url)
        except rerun_log.ViewerUnavailable as exc:  # the file is there; only the live view is missing
            error = clip(f"streaming to the viewer failed: {exc}; the recording is in {path}", 600)
            self._log_error(error)
            return dataclasses.replace(answer, rrd_error=error)
        except Exception as exc:  # noqa: BLE001 - logging trouble must not cost the answer
            error = clip(f"writing {path} failed: {exc}", 600)
            self._log_error(error)
            return dataclasses.replace(answer, rrd_path=None, rollouts_logged=0, rrd_error=error)
        return dataclasses.replace(answer, rollouts_logged=logged)



#: Questions waiting beyond this are refused (the asker hears "busy" at once, not minutes later).
MAX_WAITING_QUESTIONS = 4
#: Samples per variant of a question when the request does not say (see ipe_ros.cli_ask).
DEFAULT_QUESTION_SAMPLES = 16


def _replaced_by(question) -> str:
    return f"cancelled: question {question.request_id!r} about the same scene replaced it (cancel_older)"


def _question_head(question, source: StampedScene) -> dict[str, Any]:
    """The fields every reply to a question carries: its id, kind, and the scene it was about."""
    return {"id": question.request_id, "question": question.kind, "scene_id": source.scene_id,
            "frame_id": source.frame_id, "stamp": stamp_dict(source.stamp_ns)}


class QuestionCancelled(Exception):
    """A newer question about the same scene asked to replace this one (``cancel_older``)."""


def _same_scene(a: StampedScene, b: StampedScene) -> bool:
    return a.scene_id == b.scene_id and a.stamp_ns == b.stamp_ns and a.seq == b.seq


class QuestionService:
    """Questions about actions (``~/ask``): a FIFO of at most MAX_WAITING_QUESTIONS, one thread,
    the prediction service's worker pool and config. Each question gets exactly one final reply
    (answer or error, ``"final": true``) on ``publish`` with the request id echoed (and the scene it
    was about); a decision question answered sequentially also publishes partial replies
    (``"final": false``, what is decided so far) after each batch. A question brings its scene or
    is about the newest accepted one; with ``cancel_older`` it replaces the older questions about
    the same scene (waiting: answered cancelled at once; running: after its current batch)."""

    def __init__(self, predictions: PredictionService, publish: Callable[[dict[str, Any], StampedScene], None],
                 log_error: Callable[[str], None] = lambda _msg: None):
        self._predictions = predictions
        self._publish = publish
        self._log_error = log_error
        self._cond = threading.Condition()
        self._queue: collections.deque = collections.deque()
        self._current: tuple | None = None  # (question, scene) being answered
        self._cancel_current: str | None = None  # why the running question is to end at its next batch
        self._closing = False
        self.answered = 0
        self.refused = 0
        self._recordings = 0
        self._thread = threading.Thread(target=self._run, name="ipe-questions", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self, timeout_s: float = 1.5, reason: str = "the node is shutting down", join: bool = True) -> None:
        """Stop taking questions; every one waiting or in flight is answered with an error naming
        ``reason`` (the question thread publishes nothing once closing). ``join=False``: return at
        once; the thread ends when the pool it waits on closes (see ``join``)."""
        with self._cond:
            self._closing = True
            abandoned = list(self._queue) + ([self._current] if self._current is not None else [])
            self._queue.clear()
            self._cond.notify_all()
        for question, source in abandoned:
            self._deliver({**_question_head(question, source), "final": True,
                           "error": f"{reason}: the question was cancelled"}, source, question)
        if join:
            self.join(timeout_s)

    def join(self, timeout_s: float) -> None:
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def submit(self, question, scene: StampedScene | None) -> str | None:
        """Queue a parsed question (``scene`` None: the newest accepted scene); returns why it was
        refused, or None."""
        if scene is None:
            scene = self._predictions.latest_scene()
            if scene is None:
                return "no scene received yet; publish one on ~/scene or ~/scene_json, or put \"scene\" in the question"
        cancelled = []
        with self._cond:
            if self._closing:
                return "the node is shutting down"
            if getattr(question, "cancel_older", False):
                cancelled = [(q, s) for q, s in self._queue if _same_scene(s, scene)]
                self._queue = collections.deque((q, s) for q, s in self._queue if not _same_scene(s, scene))
                if self._current is not None and _same_scene(self._current[1], scene):
                    self._cancel_current = _replaced_by(question)
            if len(self._queue) >= MAX_WAITING_QUESTIONS:
                return f"busy: {len(self._queue)} questions are waiting; ask again later"
            self._queue.append((question, scene))
            self.refused += len(cancelled)
            self._cond.notify_all()
        for old, source in cancelled:
            self._deliver({**_question_head(old, source), "error": _replaced_by(question), "final": True}, source, old)
        return None

    def _run(self) -> None:

        while True:
            with self._cond:
                while not self._closing and not self._queue:
                    self._cond.wait()
                if self._closing:
                    return
                question, source = self._current = self._queue.popleft()
                self._cancel_current = None
            config = self._predictions.config
            head = _question_head(question, source)
            start = time.perf_counter()

            def progress(partial: dict, head=head, source=source, question=question) -> None:
                with self._cond:
                    if self._closing:
                        raise QuestionCancelled("the node is shutting down")
                    if self._cancel_current is not None:
                        raise QuestionCancelled(self._cancel_current)
                self._deliver({**head, "final": False, "progress": partial,
                               "compute_s": time.perf_counter() - start}, source, question)

            try:
                # questions draw their noise from sigma: depth perception serves predictions only, and
                # the reply says so rather than answering as if it had been used
                model = dataclasses.replace(config.model, samples=DEFAULT_QUESTION_SAMPLES, perception="gaussian")
                pool = self._predictions.pool
                record = {}
                if config.rerun_save_dir and config.rerun_rollouts_logged > 0:
                    record = dict(record_every=max(1, round(config.rerun_frame_period_s / config.settings.time_step_s)),
                                  record_samples=config.rerun_rollouts_logged)
                reply = question.answer(source.scene, model, config.settings, seed=config.seed,
                                        map_fn=pool.map if pool is not None else None, budget_s=config.budget_s,
                                        on_progress=progress, check=config.check, **record)
                message = {**head, "final": True, "answer": reply.data, "compute_s": time.perf_counter() - start}
                if config.model.perception != "gaussian":
                    message["perception"] = (f"gaussian (sigma = {config.model.sigma_m:g} m): questions do not use "
                                             f"{config.model.perception} perception")
                if record and reply.answers is not None:
                    message["rrd_path"] = self._write_rrd(config, question, source, reply.answers)
                answered = True
            except Exception as exc:  # noqa: BLE001 - one question's trouble is its answer, never the thread's end
                error = str(exc) if isinstance(exc, (ValueError, QuestionCancelled)) else "".join(
                    traceback.format_exception_only(type(exc), exc)).strip()
                message = {**head, "final": True, "error": clip(error, 1000)}
                answered = False
            with self._cond:
                self._current = None
                if self._closing:
                    return  # close() answered it
                self.answered += answered
                self.refused += not answered
            self._deliver(message, source, question)

    def _deliver(self, message: dict[str, Any], source: StampedScene, question) -> None:
        try:
            self._publish(message, source)
        except Exception as exc:  # noqa: BLE001
            self._log_error(f"publishing the answer to question {question.request_id!r} failed: {exc}")

    def _write_rrd(self, config: ServiceConfig, question, source: StampedScene, answers) -> str | None:
        from .viz import rerun_log  # only needed when recording

        safe = _file_safe(question.request_id, 60) or "question"
        self._recordings += 1
        path = Path(config.rerun_save_dir) / f"ask_{self._recordings:06d}_{question.kind}_{safe}.rrd"
        try:
            rerun_log.write_question_rrd(path, source.scene, answers, stamp_ns=source.stamp_ns)
        except Exception as exc:  # noqa: BLE001 - a recording's trouble must not cost the answer
            self._log_error(f"writing {path} failed: {exc}")
            return None
        return str(path.resolve())
