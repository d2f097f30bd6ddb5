"""Observed motion (``~/observe``): the unknown properties inferred one observation at a time, on the
prediction service's pool and config; what was learned kept by object name for the scenes that follow.
"""

from __future__ import annotations

import collections
import threading
import time
import traceback
from typing import Any, Callable

from ..engine.errors import clip
from ..engine.inference.infer import InferSettings, infer, posterior_priors
from ..engine.inference.observation import Observation
from ..engine.scene.bodies import Scene
from ..engine.scene.properties import with_properties
from .predictions import PredictionService

#: observations waiting beyond this are refused at once ("busy")
MAX_WAITING_OBSERVATIONS = 2


class LearnedProperties:
    """Each object's inferred properties by name, for ``keep_s`` seconds after the observation that
    taught them: a scene that names the object takes the posterior median in place of its own value,
    and the posterior as the property's prior (what is still uncertain is drawn per sample)."""

    def __init__(self, keep_s: float, clock: Callable[[], float] = time.monotonic):
        self.keep_s, self._clock = keep_s, clock
        self._lock = threading.Lock()
        #: (name, property) -> (value, prior or None, when)
        self._known: dict[tuple[str, str], tuple[float, Any, float]] = {}

    def learn(self, medians: dict[tuple[str, str], float], priors: dict | None = None) -> None:
        """``medians``: (object name or "support", property) -> value; ``priors``: the same keys ->
        the posterior as a prior (``scene.properties.posterior_prior``), where it has width."""
        now = self._clock()
        with self._lock:
            for key, value in medians.items():
                self._known[key] = (float(value), (priors or {}).get(key), now)

    def apply(self, scene: Scene) -> tuple[Scene, tuple[tuple[str, str, float], ...]]:
        """The scene with what is still known in place, and (object, property, value) for each used."""
        if self.keep_s <= 0:
            return scene, ()
        now = self._clock()
        owners = {"support"} | {b.name for b in scene.objects if not b.static}
        with self._lock:
            fresh = {key: (value, prior) for key, (value, prior, when) in self._known.items()
                     if key[0] in owners and now - when <= self.keep_s}
        if not fresh:
            return scene, ()
        values = {key: value for key, (value, _) in fresh.items()}
        priors = {key: prior for key, (_, prior) in fresh.items() if prior is not None}
        return with_properties(scene, values, priors), tuple((o, p, v) for (o, p), v in sorted(values.items()))


class ObservationService:
    """A FIFO of at most MAX_WAITING_OBSERVATIONS, one thread; each observation's answer (or error) is
    published once with its id. A consistent answer's medians go to ``learned``."""

    def __init__(self, predictions: PredictionService, publish: Callable[[dict[str, Any]], None], keep_s: float,
                 log_error: Callable[[str], None] = lambda _msg: None):
        self._predictions, self._publish, self._log_error = predictions, publish, log_error
        self.learned = LearnedProperties(keep_s)
        self._cond = threading.Condition()
        self._queue: collections.deque = collections.deque()
        self._closing = False
        self.answered = self.refused = 0
        self._thread = threading.Thread(target=self._run, name="ipe-observations", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def close(self, reason: str = "the node is shutting down", join: bool = True, timeout_s: float = 1.5) -> None:
        with self._cond:
            self._closing = True
            abandoned = list(self._queue)
            self._queue.clear()
            self._cond.notify_all()
        for request_id, _, publish in abandoned:
            self._deliver({"id": request_id, "error": f"{reason}: the observation was not answered"}, publish)
        if join:
            self.join(timeout_s)

    def join(self, timeout_s: float) -> None:
        if self._thread.is_alive():
            self._thread.join(timeout_s)

    def submit(self, request_id: str, observation: Observation,
               publish: Callable[[dict[str, Any]], None] | None = None) -> str | None:
        """Queue an observation, its answer for ``publish`` (None: the service's own, ``~/properties``);
        why it was refused, or None."""
        with self._cond:
            if self._closing:
                return "the node is shutting down"
            if len(self._queue) >= MAX_WAITING_OBSERVATIONS:
                return f"busy: {len(self._queue)} observations are waiting; send it again later"
            self._queue.append((request_id, observation, publish or self._publish))
            self._cond.notify_all()
        return None

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._closing and not self._queue:
                    self._cond.wait()
                if self._closing:
                    return
                request_id, observation, publish = self._queue.popleft()
            request = self._predictions.config.request
            pool = self._predictions.pool
            try:
                settings = InferSettings(simulation=request.settings, seed=request.seed, budget_s=request.budget_s)
                answer = infer(observation, settings, pool.map if pool is not None else None)
                message = {"id": request_id, **answer.to_dict()}
                if answer.consistent:
                    self.learned.learn({(body, e.property): e.median for u, e in
                                        zip(observation.unknowns, answer.estimates)
                                        for body in u.applies_to(observation.scene)},
                                       posterior_priors(observation.unknowns, answer.estimates, observation.scene))
                ok = True
            except Exception as exc:  # noqa: BLE001 - one observation's trouble is its answer, never the thread's end
                error = str(exc) if isinstance(exc, ValueError) else "".join(
                    traceback.format_exception_only(type(exc), exc)).strip()
                message, ok = {"id": request_id, "error": clip(error, 1000)}, False
            with self._cond:
                if self._closing:
                    return
                self.answered += ok
                self.refused += not ok
            self._deliver(message, publish)

    def _deliver(self, message: dict[str, Any], publish: Callable[[dict[str, Any]], None]) -> None:
        try:
            publish(message)
        except Exception as exc:  # noqa: BLE001
            self._log_error(f"publishing the properties for observation {message.get('id')!r} failed: {exc}")
