"""Questions about a robot's actions (``~/ask``), answered one at a time beside the predictions, on
their pool and config."""

from __future__ import annotations

import collections
import dataclasses
import threading
import time
import traceback
from typing import Any, Callable

from ..engine.errors import clip
from .predictions import PredictionService
from .recording import record_question
from .values import StampedScene, stamp_dict


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
            request = config.request
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
                # with a perception that needs evidence, every variant's sample i starts from the posterior's
                # scene i: the chain the view's predictions use, thinned to the question's k (no chain of its own)
                model = dataclasses.replace(request.model, samples=DEFAULT_QUESTION_SAMPLES, perception="gaussian")
                k = question.samples if question.samples is not None else DEFAULT_QUESTION_SAMPLES
                perceived = self._predictions.perceived(source, config, samples=k)
                pool = self._predictions.pool
                record = {}
                if config.rerun_save_dir and config.rerun_rollouts_logged > 0:
                    record = dict(record_every=max(1, round(config.rerun_frame_period_s / request.settings.time_step_s)),
                                  record_samples=config.rerun_rollouts_logged)
                reply = question.answer(source.scene, model, request.settings, seed=request.seed,
                                        map_fn=pool.map if pool is not None else None, budget_s=request.budget_s,
                                        on_progress=progress, check=request.check, perceived=perceived, **record)
                message = {**head, "final": True, "answer": reply.data, "compute_s": time.perf_counter() - start}
                if perceived is not None:
                    message["perception"] = perceived.to_dict()
                if record and reply.answers is not None:
                    self._recordings += 1
                    message["rrd_path"] = record_question(config, question, source, reply.answers, self._recordings,
                                                          self._log_error)
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
