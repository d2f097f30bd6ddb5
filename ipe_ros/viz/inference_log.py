"""A recording of an inference (``ipe infer --rrd``): the observed frames over the rollout at the
posterior medians, and each unknown's posterior as a histogram (``.rrd`` files, never a viewer)."""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..engine.inference.infer import Inference, observed_rollout_scene, trajectory_settings
from ..engine.inference.observation import Observation
from ..engine.inference.particle import body_paths, trajectory_sample
from .palette import group_rgb, to_rgb8
from .rerun_log import APPLICATION_ID, entity_part, log_scene

HISTOGRAM_BINS = 24


def write_inference_rrd(path: str | Path, observation: Observation, answer: Inference) -> None:
    """Under ``world/observed/<object>`` the tracked positions and under ``world/rollout/<object>``
    the rollout at the posterior medians (the refined scene), both over the ``sim_time`` timeline,
    their whole paths static beside them; under ``posterior/<unknown>`` a histogram of its draws."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blueprint = rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(name="observed (points) and the rollout at the posterior medians (lines)", origin="world"),
        rrb.Grid(*[rrb.BarChartView(name=e.label, origin=f"posterior/{entity_part(e.label)}") for e in answer.estimates],
                 name="posterior"), column_shares=[3, 2]), rrb.TimePanel(timeline="sim_time"), collapse_panels=True)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"{observation.scene.name}@infer/{uuid.uuid4().hex[:12]}")
    rec.save(str(path), default_blueprint=blueprint)
    try:
        log_scene(rec, observation.scene)
        colours = {b.name: to_rgb8(group_rgb(b.group)) for b in observation.scene.dynamic_objects}
        for body in observation.scene.dynamic_objects:
            times, positions, _ = observation.track(body.name)
            if not len(times):
                continue
            base = f"world/observed/{entity_part(body.name)}"
            rec.log(f"{base}/path", rr.Points3D(positions, radii=0.003, colors=[colours[body.name]]), static=True)
            rec.send_columns(base, indexes=[rr.TimeColumn("sim_time", duration=times)],
                             columns=rr.Points3D.columns(positions=positions).partition([1] * len(times)))
        if answer.refined_scene is not None:
            _log_rollout(rec, observation, answer, colours)
        for j, estimate in enumerate(answer.estimates):
            if answer.draws is None:
                break
            counts, _ = np.histogram(answer.draws[:, j], bins=HISTOGRAM_BINS)
            rec.log(f"posterior/{entity_part(estimate.label)}", rr.BarChart(counts.astype(float)), static=True)
        rec.flush()
    finally:
        rec.disconnect()


def _log_rollout(rec: rr.RecordingStream, observation: Observation, answer: Inference, colours: dict) -> None:
    scene = observed_rollout_scene(observation, answer.refined_scene)
    outcome = trajectory_sample(scene, trajectory_settings(answer.settings.simulation))
    if not outcome.ok:
        rec.log("world/rollout", rr.TextDocument(f"the rollout at the posterior medians failed: {outcome.error}"),
                static=True)
        return
    times, paths = body_paths(scene, outcome.rollouts[0].trajectory)
    for name, (origins, _) in paths.items():
        base = f"world/rollout/{entity_part(name)}"
        rec.log(f"{base}/path", rr.LineStrips3D([origins], colors=[colours[name]]), static=True)
        rec.send_columns(base, indexes=[rr.TimeColumn("sim_time", duration=times)],
                         columns=rr.Points3D.columns(positions=origins, radii=np.full(len(times), 0.006)).partition(
                             [1] * len(times)))
