"""The prediction service: a keep-latest scene slot, one prediction thread, the worker pool (see the
package docstring)."""

from __future__ import annotations

import collections
import dataclasses
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable

from ..engine import ConfigError, Scene, WorkerPool, predict
from ..engine import Context
from ..engine.errors import SceneError, clip, shown
from ..engine.inputs import as_spelled
from ..engine.perceptions import perception_source
from ..engine.predict import check_request
from .evidence import EvidenceViews
from .recording import load_rerun_if_recording, record_prediction
from .values import RECENT_EVENTS, Answer, NoSceneError, PredictionFailed, ServiceConfig, ServiceStats, StampedScene


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
        ``engine.compute.cluster.DaskMap``); anything with WorkerPool's ``map``, ``warm``, ``worker_pids``,
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
        self.evidence = EvidenceViews()  # perception sources' newest views, and the latest view's posterior
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
                            contradicted=0, validated=0)
        self._recent: collections.deque[str] = collections.deque(maxlen=RECENT_EVENTS)
        self._last_predicted_seq = 0
        self._in_flight_since: float | None = None
        self._last_compute_s: float | None = None
        self._recordings = 0
        self._last_error: str | None = None
        self._thread = threading.Thread(target=self._run, name="ipe-prediction", daemon=True)
        load_rerun_if_recording(config)

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
        load_rerun_if_recording(config)
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
            request = config.request
            check_request(scene, request.query, config.max_objects, model=request.model, settings=request.settings,
                          budget_s=request.budget_s)
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
            return ServiceStats(**self._counts, evidence=self.evidence.counts(), waiting=int(self._pending is not None),
                                in_flight=self._in_flight is not None,
                                in_flight_s=None if since is None else time.monotonic() - since,
                                recent=tuple(self._recent), budget_s=self._config.request.budget_s, workers=self.workers,
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
                self._counts["validated"] += prediction.fidelity == "validated"
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

    def perceived(self, item: StampedScene, config: ServiceConfig, samples: int | None = None):
        """The perception's posterior scenes for this scene from its newest evidence (``service.evidence``),
        or None when the perception needs none. ``samples``: the first so many (a question's k)."""
        source = perception_source(config.request.model.perception)
        if source.needs is None:
            return None
        perceived = self.evidence.perceived(source, item.scene, item.stamp_ns, item.frame_id, config.request.model,
                                            config.request.seed, config.request.budget_s,
                                            dict(config.evidence_settings),
                                            map_fn=self._pool.map if self._pool is not None else None)
        return perceived if samples is None else perceived.with_samples(samples)

    def _predict(self, item: StampedScene, config: ServiceConfig, version: int) -> tuple[Answer | None, str | None]:
        start = time.perf_counter()
        request = config.request
        record_every = 0
        if config.rerun_save_dir and config.rerun_rollouts_logged > 0:
            record_every = max(1, round(config.rerun_frame_period_s / request.settings.time_step_s))
        try:
            perceived = self.perceived(item, config)
            budget_s = request.budget_s  # what the perception's chain left of it
            if budget_s is not None and perceived is not None:
                budget_s = max(budget_s - (time.perf_counter() - start), 1e-3)
            prediction = predict(item.scene, dataclasses.replace(request, budget_s=budget_s),
                                 Context(map_fn=self._pool.map if self._pool is not None else None,
                                         record_every=record_every, record_samples=config.rerun_rollouts_logged,
                                         max_objects=config.max_objects, perceived=perceived))
        except ValueError as exc:  # SceneError / ConfigError: the scene no longer fits a new config
            return None, str(exc)
        except Exception as exc:  # noqa: BLE001 - report, keep serving
            return None, "".join(traceback.format_exception_only(type(exc), exc)).strip()
        if self._closing:
            return None, "the node is shutting down"
        answer = Answer(source=item, prediction=prediction, compute_s=time.perf_counter() - start,
                        latency_s=0.0, config_version=version,
                        perceived_scene=getattr(perceived, "refined", None))
        if record_every:
            with self._cond:
                self._recordings += 1  # one file per prediction, also when a scene is predicted again
                number = self._recordings
            answer = record_prediction(answer, config, number, self._log_error)
        now = time.monotonic()
        latency = now - item.received_monotonic_s if item.received_monotonic_s else answer.compute_s
        return dataclasses.replace(answer, compute_s=time.perf_counter() - start, latency_s=latency), None
