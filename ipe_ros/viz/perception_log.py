"""Recordings of what perception saw: the vision system's views and chain, a depth camera's measured and
rendered depth with the posterior's cloud (``.rrd`` files, never a viewer)."""

from __future__ import annotations

import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..engine.scene.bodies import Scene
from .palette import group_rgb, to_rgb8
from .rerun_log import APPLICATION_ID, entity_part, log_scene


def write_vision_rrd(path: str | Path, scene: Scene, perceived, settings) -> None:
    """The vision system's view of a scene (``engine.vision``): the observed images (rendered and
    blurred) under ``vision/views``, the posterior sample cloud of every body's position under
    ``world/vision/<object>`` beside the scene, and the chain's acceptance (running mean) and
    log-likelihood over the ``mh_sample`` timeline under ``vision/``."""
    from ..engine.vision import blur
    from ..engine.vision.camera import cameras_for
    from ..engine.vision.render import render_views, scene_mesh

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cameras = cameras_for(scene, settings)
    observed = render_views(scene_mesh(scene), cameras)
    blurred = blur(observed, settings.blur_at_resolution_px)
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="posterior samples of each body's position", origin="world"),
            rrb.Vertical(rrb.Grid(*[rrb.Spatial2DView(name=f"view {i}", origin=f"vision/views/{i}")
                                    for i in range(len(cameras))], name="the evidence (blurred views)"),
                         rrb.TimeSeriesView(name="acceptance and log-likelihood", origin="vision/chain")),
            column_shares=[3, 2]),
        rrb.TimePanel(timeline="mh_sample"), collapse_panels=True)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}@vision/{uuid.uuid4().hex[:12]}")
    rec.save(str(path), default_blueprint=blueprint)
    try:
        log_scene(rec, scene)
        for i, (image, soft) in enumerate(zip(observed, blurred)):
            rec.log(f"vision/views/{i}", rr.Image(np.clip(soft, 0, 255).astype(np.uint8)), static=True)
            rec.log(f"vision/rendered/{i}", rr.Image(np.clip(image, 0, 255).astype(np.uint8)), static=True)
        chain = perceived.chain
        cloud = chain.positions_m[:: max(1, len(chain.positions_m) // 1000)]
        for b, body in enumerate(scene.dynamic_objects):
            rec.log(f"world/vision/{entity_part(body.name)}", rr.Points3D(cloud[:, b], radii=0.004,
                                                                   colors=[to_rgb8(group_rgb(body.group))]), static=True)
        if chain.accepted is not None:
            trace = np.cumsum(chain.accepted) / np.arange(1, len(chain.accepted) + 1)
            index = [rr.TimeColumn("mh_sample", sequence=np.arange(len(trace)))]
            rec.send_columns("vision/chain/acceptance", indexes=index, columns=rr.Scalars.columns(scalars=trace))
        kept = np.arange(perceived.burn_in, perceived.burn_in + len(chain.log_likelihood))
        rec.send_columns("vision/chain/log_likelihood", indexes=[rr.TimeColumn("mh_sample", sequence=kept)],
                         columns=rr.Scalars.columns(scalars=chain.log_likelihood))
        rec.flush()
    finally:
        rec.disconnect()


def write_depth_rrd(path: str | Path, scene: Scene, perceived, observations) -> None:
    """Depth perception's view of a scene (``engine.vision.depth``): each measured depth image under
    ``depth/<i>/measured``, the depth rendered from the posterior mean under ``depth/<i>/rendered``
    and their difference under ``depth/<i>/residual``, the camera's pose and intrinsics in the
    world (``world/cameras/<i>``), and the posterior sample cloud of every object's position under
    ``world/depth/<object>`` beside the scene as published."""
    from ..engine.vision.depth import render_depth_m

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    posterior = perceived.posterior
    mean_positions, mean_yaws, mean_tilts = posterior.mean()
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="posterior samples of each object's position", origin="world"),
            rrb.Grid(*[rrb.Spatial2DView(name=f"camera {i}: {part}", origin=f"depth/{i}/{part}")
                       for i in range(len(observations)) for part in ("measured", "rendered", "residual")],
                     name="depth: measured, rendered at the posterior mean, residual"),
            column_shares=[3, 2]), collapse_panels=True)
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}@depth/{uuid.uuid4().hex[:12]}")
    rec.save(str(path), default_blueprint=blueprint)
    try:
        log_scene(rec, scene)
        for i, observation in enumerate(observations):
            camera = observation.camera
            measured = np.where(np.isfinite(observation.depth_m), observation.depth_m, 0.0).astype(np.float32)
            rendered = render_depth_m(scene, camera, mean_positions, mean_yaws, mean_tilts).astype(np.float32)
            residual = np.where((measured > 0) & np.isfinite(rendered), measured - rendered, 0.0).astype(np.float32)
            rec.log(f"depth/{i}/measured", rr.DepthImage(measured, meter=1.0), static=True)
            rec.log(f"depth/{i}/rendered", rr.DepthImage(np.nan_to_num(rendered, nan=0.0, posinf=0.0), meter=1.0),
                    static=True)
            rec.log(f"depth/{i}/residual", rr.Image(np.clip(128 + residual * 2000, 0, 255).astype(np.uint8)),
                    static=True)
            rec.log(f"world/cameras/{i}", rr.Transform3D(translation=camera.position_m,
                                                         quaternion=rr.Quaternion(xyzw=camera.orientation_xyzw)),
                    static=True)
            # rerun's image space puts pixel corners at integers (its default principal point is
            # resolution / 2); CameraInfo puts pixel centres there
            rec.log(f"world/cameras/{i}", rr.Pinhole(focal_length=[camera.fx, camera.fy],
                                                     principal_point=[camera.cx + 0.5, camera.cy + 0.5],
                                                     width=camera.width_px, height=camera.height_px), static=True)
        cloud = posterior.positions_m[:: max(1, len(posterior.positions_m) // 1000)]
        for b, body in enumerate(scene.dynamic_objects):
            rec.log(f"world/depth/{entity_part(body.name)}", rr.Points3D(cloud[:, b], radii=0.004,
                                                                  colors=[to_rgb8(group_rgb(body.group))]), static=True)
        rec.flush()
    finally:
        rec.disconnect()


def record_vision(values, scene: Scene, perceived, evidence, model) -> str | None:
    """Vision perception's recording (its ``--vision-rrd`` option, engine/vision/sources.py): the
    file written, or None when not asked."""
    if values.get("vision_rrd") is None:
        return None
    write_vision_rrd(values["vision_rrd"], scene, perceived, model.vision)
    return values["vision_rrd"]


def record_depth(values, scene: Scene, perceived, observations, model) -> str | None:
    """Depth perception's recording (its ``--depth-rrd`` option, engine/vision/depth_source.py): the
    file written, or None when not asked."""
    if values.get("depth_rrd") is None:
        return None
    write_depth_rrd(values["depth_rrd"], scene, perceived, observations)
    return values["depth_rrd"]
