"""A perception source from outside the engine that needs evidence (tests/test_perceptions.py): a
detector's list of objects, each with its position's mean and covariance, read from a file
(``--detections FILE``) or from a topic (``~/detections``, std_msgs/String holding the same JSON).
This module is all it takes: ``SOURCE`` registered, ``ipe predict`` and the node offer it with its
option, topic and parameter, and its draws run on the prediction's workers (which import this module to run
``draw_sample``).

The evidence: ``{"frame_id": "world", "detections": [{"object": NAME, "position_m": [x, y],
"covariance_m2": [[xx, xy], [xy, yy]]}, ...]}``. Each of the k scenes moves every detected object
to a draw from its Gaussian (its height as given); objects not detected stay where the scene has them.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ipe_ros.engine import ConfigError
from ipe_ros.engine.evidence import Evidence, EvidenceTopic
from ipe_ros.engine.input_row import Input
from ipe_ros.engine.perceptions import PerceptionSource

STREAM = 0xDE7


@dataclass(frozen=True)
class Detection:
    object: str
    position_m: tuple[float, float]
    covariance_m2: tuple[tuple[float, float], tuple[float, float]]


def parse(text: str, where: str) -> tuple[Detection, ...]:
    """The detections of a JSON text, or a ConfigError naming ``where`` and the field."""
    try:
        data = json.loads(text)
        detections = []
        for i, d in enumerate(data["detections"]):
            cov = np.asarray(d["covariance_m2"], float)
            if cov.shape != (2, 2) or not np.allclose(cov, cov.T) or np.any(np.linalg.eigvalsh(cov) < 0):
                raise ConfigError(f"{where}.detections[{i}].covariance_m2", "must be a symmetric 2 x 2 matrix, "
                                                                           "positive semi-definite")
            detections.append(Detection(str(d["object"]), tuple(map(float, d["position_m"])),
                                        tuple(map(tuple, cov.tolist()))))
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ConfigError(where, f"must be {{\"detections\": [{{\"object\", \"position_m\", \"covariance_m2\"}}]}}: "
                                 f"{exc}") from None
    return tuple(detections)


def read_file(values: dict[str, Any]) -> tuple[Detection, ...]:
    return parse(Path(values["detections"]).read_text(), "--detections")


def received(msg, held, node_values) -> tuple[tuple[Detection, ...], str]:
    """``~/detections``: the detections and their frame (the node's frame_id when the JSON names none).
    Written as a careless plugin might be: a JSON list instead of an object raises AttributeError."""
    frame = json.loads(msg.data).get("frame_id") or str(node_values["frame_id"])
    return parse(msg.data, "detections"), frame


def assemble(held: dict[str, Any]) -> tuple[Detection, ...]:
    return held["~/detections"]


@dataclass(frozen=True)
class Detected:
    """The k scenes drawn, and the scene at the detections' means."""

    scenes: tuple
    refined: Any
    detections: tuple[Detection, ...]

    def with_samples(self, k: int) -> "Detected":
        return dataclasses.replace(self, scenes=self.scenes[:k])

    def to_dict(self) -> dict:
        return {"kind": "detections", "samples": len(self.scenes),
                "objects": {d.object: {"position_m": list(d.position_m),
                                       "covariance_m2": [list(r) for r in d.covariance_m2]} for d in self.detections}}


def _moved(scene, positions: dict[str, tuple[float, float]]):
    unknown = sorted(set(positions) - {b.name for b in scene.objects})
    if unknown:
        raise ConfigError("detections", f"names {unknown[0]!r}, which the scene does not hold")
    return dataclasses.replace(scene, objects=tuple(
        dataclasses.replace(b, position_m=(*positions[b.name], b.position_m[2])) if b.name in positions else b
        for b in scene.objects))


def draw_sample(job) -> Any:
    """One of the k scenes (in a worker): each detected object at a draw from its Gaussian."""
    scene, detections, seed = job
    rng = np.random.default_rng(seed)
    return _moved(scene, {d.object: tuple(rng.multivariate_normal(d.position_m, d.covariance_m2))
                          for d in detections})


def run(scene, model, seed: int, map_fn, evidence, budget_s):
    seeds = np.random.SeedSequence([seed, STREAM]).spawn(model.samples)  # the same draws on any worker count
    jobs = [(scene, evidence, s) for s in seeds]
    scenes = map_fn(draw_sample, jobs) if map_fn is not None else [draw_sample(j) for j in jobs]
    refined = _moved(scene, {d.object: d.position_m for d in evidence})
    return Detected(tuple(scenes), refined, tuple(evidence))


SOURCE = PerceptionSource(
    "detections", "each detected object drawn from its position's Gaussian (a detector's mean and covariance)",
    posterior=True, run=run, describe=lambda v: f"{len(v['objects'])} objects detected",
    options=(Input("detections", "name", None, "path", "a JSON list of objects' positions with their covariances",
                   flag="--detections", in_request=False, unset_means="none", metavar="FILE"),),
    needs=Evidence(what="the detections", describes="one list of detections describes one scene",
                   read=read_file,
                   topics=(EvidenceTopic("~/detections", "std_msgs/msg/String",
                                         "tests.perception_plugin_detections:received", "detection list",
                                         counted_as="detections", view=True),),
                   assemble=assemble, missing="publish one on ~/detections", max_age_parameter="detections.max_age_s",
                   parameters=(Input("detections.max_age_s", "float", 60.0, "s", "the detections may be at most this "
                                     "many seconds from the scene's stamp", parameter="detections.max_age_s",
                                     in_request=False, range=(0.001, 3600.0)),)))
