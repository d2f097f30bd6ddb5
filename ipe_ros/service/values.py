"""What the service's parts pass around: its config, a scene as received, a published answer, the
counters diagnostics read, and the errors a caller may catch."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..engine import Prediction, Scene
from ..engine.request import Request
from ..engine.scene.bodies import DEFAULT_MAX_OBJECTS
from ..engine.scene.meshes import MeshAccess



@dataclass(frozen=True)
class ServiceConfig:
    """Everything a prediction depends on besides the scene; replaced as a whole on updates.

    request: the prediction's own inputs (engine.request: model, settings, queries, seed, stopping,
        budget, self-check), built once from the node's parameters as ``ipe predict`` builds it
        from its options.
    max_objects: scenes with more objects are refused.
    rerun_save_dir: folder for one ``.rrd`` per prediction, or None for no rerun logging.
    rerun_rollouts_logged: how many sampled rollouts each ``.rrd`` shows.
    rerun_frame_period_s: simulated seconds between recorded frames of a logged rollout.
    rerun_connect_url: also stream to a running viewer at this gRPC URL (never spawns one).
    """

    request: Request = Request()
    max_objects: int = DEFAULT_MAX_OBJECTS
    rerun_save_dir: str | None = None
    rerun_rollouts_logged: int = 8
    rerun_frame_period_s: float = 0.02
    rerun_connect_url: str | None = None
    gravity_aligned_frames: tuple[str, ...] = ()  # frames whose -z is gravity; () trusts every frame
    #: the node's parameters that perception sources declared (``engine.evidence.Evidence``: how far a
    #: view may be from the scene's stamp), as (name, value)
    evidence_settings: tuple[tuple[str, Any], ...] = ()
    #: where scenes' mesh files may be read from (``mesh_roots``); None: scenes may not name meshes
    meshes: MeshAccess | None = None

    def replace_request(self, **changes) -> "ServiceConfig":
        """This config with the request's fields ``changes`` (model=..., seed=...) replaced."""
        return dataclasses.replace(self, request=dataclasses.replace(self.request, **changes))


@dataclass(frozen=True)
class StampedScene:
    """A scene as received: its header (stamp in ns since the epoch, frame), an id and a sequence number."""

    scene: Scene
    stamp_ns: int
    frame_id: str
    scene_id: str
    seq: int = 0
    received_monotonic_s: float = 0.0
    #: (object, property, value) learned from observed motion and used in place of the scene's own
    learned: tuple[tuple[str, str, float], ...] = ()


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
    #: under depth perception: the scene with every object at its posterior mean pose (for the robot to
    #: use or re-publish; ``prediction.request["perception"]["objects"]`` holds the covariances)
    perceived_scene: Scene | None = None

    def to_dict(self) -> dict[str, Any]:
        """The published JSON: ``ipe predict --json``'s fields plus stamp, frame, ids and timing."""
        out = self.prediction.to_dict()
        out.update(stamp=stamp_dict(self.source.stamp_ns), frame_id=self.source.frame_id,
                   scene_id=self.source.scene_id, scene_seq=self.source.seq, compute_s=self.compute_s,
                   latency_s=self.latency_s, rrd_path=self.rrd_path, rollouts_logged=self.rollouts_logged,
                   rrd_error=self.rrd_error)
        if self.source.learned:
            out["learned_properties"] = [{"object": o, "property": p, "value": v} for o, p, v in self.source.learned]
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


def decomposing_answer(status: dict[str, Any], scene_id: str, stamp_ns: int, frame_id: str,
                       input_topic: str) -> dict[str, Any]:
    """What ~/prediction carries for a scene whose mesh is being decomposed into convex parts
    (``status``: the object, the mesh, how many meshes are ahead, the time allowed): its answer, or
    its refusal, follows once the parts are ready."""
    return {"decomposing": status, "scene": scene_id or None, "scene_id": scene_id, "scene_seq": None,
            "stamp": stamp_dict(max(0, stamp_ns)), "frame_id": frame_id, "received_on": input_topic}


RECENT_EVENTS = 10


@dataclass(frozen=True)
class ServiceStats:
    """Counters for diagnostics.

    received: scenes accepted; predicted: distinct scenes answered (never more than received);
    predictions: answers made (a scene is predicted again after a parameter change); dropped:
    scenes replaced while waiting (keep-latest); budget_stops: answers cut short by the budget.
    refined_samples: rollouts the self-check reran at the reference because they ended unhealthy;
    escalated / contradicted: answers whose fast physics the reference contradicted, recomputed at
    the reference / left as they were because the budget ran out (engine.checking.fidelity);
    validated: answers inside the envelope where the fast physics was validated, not verified.
    recent: the last RECENT_EVENTS inputs and predictions, oldest first: "ok", "rejected",
    "failed", "partial" (some samples failed or were cut by the budget), "contradicted" or "rrd_failed".
    in_flight_s: how long the prediction in flight has run (None: none in flight).
    evidence: the perception sources' input counters (``service.evidence.counter_names``): per
      counted topic its messages held, refused and (a view) the scenes refused as too far from it,
      per source its chains run (a view predicted again reuses its posterior).
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
    validated: int = 0
    evidence: Mapping[str, int] = field(default_factory=dict)


class NoSceneError(RuntimeError):
    """The service was asked to predict before any valid scene arrived."""


class PredictionFailed(RuntimeError):
    """A prediction could not be made (the reason says why); the service keeps running."""

