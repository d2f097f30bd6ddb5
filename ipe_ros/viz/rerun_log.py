"""What the engine imagined, as a rerun recording: the scene, sampled rollouts, outcomes, the answer.

The only module that imports rerun. Functions take an explicit ``RecordingStream`` (no global
recording), and rollouts are sent with ``send_columns`` (one call per object and rollout, all its
frames at once) rather than one ``log`` call per box per frame.

Entity layout (z up, metres):
    world                          view coordinates RIGHT_HAND_Z_UP
    world/scene/support            floor / table top / obstacles (static)
    world/scene/boxes              the scene as received (static)
    world/rollouts/<i>/<object>    sample i's box over simulated time (timeline ``sim_time``);
                                   drawn red when it fell in that rollout, in its group colour otherwise;
                                   <i>-phi<j> when several push magnitudes are simulated per sample
    world/answer/objects           the scene coloured by each object's fall probability
    world/answer/direction         arrow of the predicted fall direction, length = decisiveness
    outcomes/<name>                per-sample outcomes over the ``sample`` timeline
    outcome_bars/<name>            the same per-sample outcomes as one bar chart (static)
    answer                         the aggregated prediction as JSON text; answer/fall_probability
                                   on the ``ros_stamp`` timeline

Each recording carries a blueprint, so the viewer opens on a layout a person reads at a glance:
the answer (objects coloured by fall risk, the direction arrow, the JSON) on the left, the
sampled rollouts side by side in the middle (playing on ``sim_time``), per-sample outcomes as bar
charts on the right. Replay with ``rerun FILE.rrd``.
"""

from __future__ import annotations

import json
import math
import socket
import subprocess
import sys
import urllib.parse
import uuid
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from ..engine.sampling.estimate import Prediction, sample_any_fall, sample_fall_fraction, sample_far_m
from ..engine.query import QUERIES
from .palette import SUPPORT_RGB, group_rgb, risk_rgb, to_rgb8
from ..engine.scene import shapes
from ..engine.scene.bodies import Body, Floor, Scene

FELL_RGB = (0.9, 0.1, 0.1)
APPLICATION_ID = "ipe_ros"


def entity_part(name: str) -> str:
    return rr.escape_entity_path_part(name)


def shape_archetype(body: Body, rgb, *, about_centre_of_mass: bool = False):
    """The body's shape drawn in its own frame (or about its centre of mass, as the engine's
    rollouts place bodies): a box, an ellipsoid, a cylinder, a capsule, a mesh of hull faces, or the
    mesh file an object was read from."""
    shape = body.shape
    offset = -shapes.centre_of_mass_m(shape) if about_centre_of_mass else np.zeros(3)
    color, solid = [to_rgb8(rgb)], rr.components.FillMode.Solid
    if isinstance(shape, shapes.BoxShape):
        return rr.Boxes3D(centers=[offset], half_sizes=[np.asarray(shape.extents_m) / 2], colors=color,
                          labels=[body.name], fill_mode=solid)
    if isinstance(shape, shapes.Sphere):
        return rr.Ellipsoids3D(centers=[offset], half_sizes=[[shape.radius_m] * 3], colors=color, labels=[body.name],
                               fill_mode=solid)
    if isinstance(shape, shapes.Cylinder):
        return rr.Cylinders3D(centers=[offset], lengths=[shape.length_m], radii=[shape.radius_m], colors=color,
                              labels=[body.name], fill_mode=solid)
    if isinstance(shape, shapes.Capsule):  # rerun's capsule starts at its origin and runs along +z
        return rr.Capsules3D(translations=[offset - [0.0, 0.0, shape.length_m / 2]], lengths=[shape.length_m],
                             radii=[shape.radius_m], colors=color, labels=[body.name], fill_mode=solid)
    drawn = None
    if isinstance(shape, shapes.Compound) and shape.source is not None:  # the mesh itself, not its parts
        from ..engine.scene.meshes import source_triangles

        drawn = source_triangles(shape.source)
    vertices, triangles = drawn if drawn is not None else shapes.hull_faces(shape)
    return rr.Mesh3D(vertex_positions=vertices + offset, triangle_indices=triangles, albedo_factor=color[0])


def _log_bodies(rec: rr.RecordingStream, base: str, bodies, colors) -> None:
    """Each body at ``base/<name>``: its shape under a transform to its pose (static)."""
    for body, rgb in zip(bodies, colors):
        path = f"{base}/{entity_part(body.name)}"
        rec.log(path, rr.Transform3D(translation=body.position_m, quaternion=rr.Quaternion(xyzw=body.orientation_xyzw)),
                static=True)
        rec.log(path, shape_archetype(body, rgb), static=True)
        if isinstance(body.shape, shapes.Compound) and body.shape.source is not None:
            # the convex parts the physics uses, beside the mesh drawn: a layer to switch on in the viewer
            vertices, triangles = shapes.hull_faces(body.shape)
            rec.log(f"{path}/convex_parts", rr.Mesh3D(vertex_positions=vertices, triangle_indices=triangles,
                                                      albedo_factor=to_rgb8(rgb)), static=True)


def log_scene(rec: rr.RecordingStream, scene: Scene) -> None:
    """The scene as received: support, obstacles and boxes (static data)."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    support = scene.support
    centers, half_sizes, labels = [], [], []
    extent = max([1.0] + [abs(c) + 1.0 for b in scene.objects for c in b.position_m[:2]])
    if isinstance(support, Floor):
        centers.append((0.0, 0.0, support.height_m - 0.005))
        half_sizes.append((extent, extent, 0.005))
        labels.append("floor")
    else:
        centers.append((*support.center_xy_m, support.top_height_m - support.thickness_m / 2))
        half_sizes.append((support.size_m[0] / 2, support.size_m[1] / 2, support.thickness_m / 2))
        labels.append("table")
        if support.floor_z_m is not None:
            centers.append((0.0, 0.0, support.floor_z_m - 0.005))
            half_sizes.append((extent, extent, 0.005))
            labels.append("floor")
    rec.log("world/scene/support", rr.Boxes3D(centers=centers, half_sizes=half_sizes, labels=labels,
                                              colors=[to_rgb8(SUPPORT_RGB)] * len(centers),
                                              fill_mode=rr.components.FillMode.Solid), static=True)
    fixed = scene.static_objects
    _log_bodies(rec, "world/scene/obstacles", fixed, [SUPPORT_RGB] * len(fixed))
    dynamic = scene.dynamic_objects
    _log_bodies(rec, "world/scene/objects", dynamic, [group_rgb(b.group) for b in dynamic])


def _log_trajectory(rec: rr.RecordingStream, base: str, bodies, trajectory: list, fallen, stamp_ns: int | None) -> None:
    """One rollout's bodies under ``base``/<name>, all frames at once; red where the body fell.
    ``bodies`` follow the trajectory's order (None: a body not to draw)."""
    times = np.array([frame[0] for frame in trajectory])
    positions = np.stack([frame[1] for frame in trajectory])      # (frames, bodies, 3)
    orientations = np.stack([frame[2] for frame in trajectory])   # (frames, bodies, 4)
    indexes = [rr.TimeColumn("sim_time", duration=times)]
    if stamp_ns is not None:
        indexes.append(rr.TimeColumn("ros_stamp", timestamp=np.full(len(times), stamp_ns, dtype="datetime64[ns]")))
    for b, body in enumerate(bodies):
        if body is None:
            continue
        path = f"{base}/{entity_part(body.name)}"
        fell = fallen is not None and bool(fallen[b])
        # trajectories hold centres of mass: the shape is drawn about it, moved by a transform
        rec.log(path, shape_archetype(body, FELL_RGB if fell else group_rgb(body.group),
                                      about_centre_of_mass=True), static=True)
        rec.send_columns(path, indexes=indexes,
                         columns=rr.Transform3D.columns(translation=positions[:, b], quaternion=orientations[:, b]))


def log_rollouts(rec: rr.RecordingStream, scene: Scene, prediction: Prediction, stamp_ns: int,
                 limit: int) -> int:
    """Recorded trajectories of up to ``limit`` samples; returns how many rollouts were logged."""
    boxes = scene.dynamic_objects
    logged = 0
    for outcome in prediction.outcomes:
        if logged >= limit:
            break
        if not outcome.ok or not outcome.rollouts or outcome.rollouts[0].trajectory is None:
            continue
        several = len(outcome.rollouts) > 1
        for j, rollout in enumerate(outcome.rollouts):
            base = f"world/rollouts/{outcome.index}" + (f"-phi{j}" if several else "")
            _log_trajectory(rec, base, boxes, rollout.trajectory, rollout.fallen, stamp_ns)
            _log_contacts(rec, base, rollout)
        logged += 1
    return logged


CONTACT_RGB = (1.0, 0.85, 0.1)


def _log_contacts(rec: rr.RecordingStream, base: str, rollout) -> None:
    """Where and when each asked pair first touched in this rollout: a point that appears then."""
    if rollout.get("contact") is None:
        return
    events = rollout.value("contact")
    for key, t in events["first_s"].items():
        where = events["where_m"].get(key)
        if t is None or where is None:
            continue
        rec.send_columns(f"{base}/contacts/{entity_part(key)}", indexes=[rr.TimeColumn("sim_time", duration=[t])],
                         columns=rr.Points3D.columns(positions=[where], radii=[0.01], colors=[to_rgb8(CONTACT_RGB)],
                                                     labels=[f"{key} touch"]))


def log_outcomes(rec: rr.RecordingStream, prediction: Prediction) -> None:
    """Per-sample outcomes (first push magnitude's values averaged over magnitudes) on ``sample``."""
    ok = [o for o in prediction.outcomes if o.ok and o.rollouts]
    if not ok:
        return
    index = [rr.TimeColumn("sample", sequence=[o.index for o in ok])]
    columns: dict[str, list[float]] = {}
    first = ok[0].rollouts[0]
    if first.fallen is not None:
        columns["fall_fraction"] = [sample_fall_fraction(o) for o in ok]
    if first.get("any_fell") is not None:
        columns["any_fall"] = [sample_any_fall(o) for o in ok]
    if first.get("far_m") is not None:
        columns["far_m"] = [sample_far_m(o) for o in ok]
    if "direction" in prediction.request.get("queries", ()):
        columns["direction_deg"] = [math.degrees(o.rollouts[0].get("direction_rad"))
                                    if o.rollouts[0].get("direction_rad") is not None else math.nan for o in ok]
    if first.get("fell_off") is not None:
        columns["fell_off_count"] = [float(np.mean([r.value("fell_off").sum() for r in o.rollouts])) for o in ok]
    columns.update(_query_columns(prediction, ok))
    for name, values in columns.items():
        rec.send_columns(f"outcomes/{name}", indexes=index, columns=rr.Scalars.columns(scalars=values))
        rec.log(f"outcome_bars/{name}", rr.BarChart(np.asarray(values, dtype=float)), static=True)
    failed = [o.index for o in prediction.outcomes if not o.ok]
    if failed:
        rec.log("outcomes/failed", rr.TextDocument("\n".join(
            f"sample {o.index}: {o.error}" for o in prediction.outcomes if not o.ok)), static=True)


def log_answer(rec: rr.RecordingStream, scene: Scene, prediction: Prediction, answer: dict,
               stamp_ns: int) -> None:
    """The aggregated answer: JSON text, risk-coloured objects, direction arrow, P(fall) over stamps."""
    rec.log("answer", rr.TextDocument("```json\n" + json.dumps(answer, indent=2, sort_keys=True) + "\n```",
                                      media_type=rr.MediaType.MARKDOWN), static=True)
    dynamic = scene.dynamic_objects
    if prediction.object_fall_probability is not None:
        colors = [risk_rgb(prediction.object_fall_probability[b.name]) for b in dynamic]
        _log_bodies(rec, "world/answer/objects", dynamic, colors)
    if prediction.direction_rad is not None and dynamic:
        top = max(dynamic, key=lambda b: b.position_m[2])
        origin = (float(np.mean([b.position_m[0] for b in dynamic])),
                  float(np.mean([b.position_m[1] for b in dynamic])), top.position_m[2] + top.extents_m[2])
        length = prediction.direction_decisiveness or 0.0
        vector = (length * math.cos(prediction.direction_rad), length * math.sin(prediction.direction_rad), 0.0)
        rec.log("world/answer/direction", rr.Arrows3D(origins=[origin], vectors=[vector],
                                                      colors=[to_rgb8(FELL_RGB)], labels=["fall direction"]),
                static=True)
    if prediction.fall_fraction is not None:
        rec.send_columns("answer/fall_probability",
                         indexes=[rr.TimeColumn("ros_stamp", timestamp=np.array([stamp_ns], dtype="datetime64[ns]"))],
                         columns=rr.Scalars.columns(scalars=[prediction.fall_fraction]))


#: Rollout views shown side by side; more logged rollouts stay in the recording, one click away.
ROLLOUT_VIEWS = 8
SUPPORT_CONTENTS = "+ /world/scene/support/**"


def prediction_blueprint(rollout_bases: list[str], outcome_names: list[str]) -> rrb.Blueprint:
    """The answer left (risk-coloured objects, arrow, JSON), rollouts in a grid, outcome bars right."""
    answer = rrb.Vertical(
        rrb.Spatial3DView(name="answer: fall risk and direction", origin="world",
                          contents=[SUPPORT_CONTENTS, "+ /world/answer/**"]),
        rrb.TextDocumentView(name="answer (JSON)", origin="answer"), row_shares=[3, 2])
    rollouts = [rrb.Spatial3DView(name=f"sample {base.rsplit('/', 1)[1]}", origin="world",
                                  contents=[SUPPORT_CONTENTS, f"+ /{base}/**"])
                for base in rollout_bases[:ROLLOUT_VIEWS]]
    columns: list = [answer]
    if rollouts:
        columns.append(rrb.Grid(*rollouts, name="sampled rollouts (red: fell)"))
    else:  # nothing recorded: the scene as received instead
        columns.append(rrb.Spatial3DView(name="scene", origin="world",
                                         contents=[SUPPORT_CONTENTS, "+ /world/scene/objects/**"]))
    if outcome_names:
        columns.append(rrb.Vertical(*[rrb.BarChartView(name=f"{name} per sample", origin=f"outcome_bars/{name}")
                                      for name in outcome_names]))
    shares = [2, 3, 1.5][:len(columns)]
    return rrb.Blueprint(rrb.Horizontal(*columns, column_shares=shares),
                         rrb.TimePanel(timeline="sim_time"), collapse_panels=True)


def question_blueprint(variant_entities: list[str]) -> rrb.Blueprint:
    """One 3-D view per variant (its recorded samples), the answers as text below."""
    views = [rrb.Spatial3DView(name=entity, origin="world", contents=[SUPPORT_CONTENTS, f"+ /world/{entity}/**"])
             for entity in variant_entities]
    return rrb.Blueprint(rrb.Vertical(rrb.Grid(*views, name="variants"),
                                      rrb.TextDocumentView(name="answers", origin="answers"), row_shares=[3, 1]),
                         rrb.TimePanel(timeline="sim_time"), collapse_panels=True)


def _rollout_bases(prediction: Prediction, limit: int) -> list[str]:
    """Entity paths of the rollouts ``log_rollouts`` writes (same rule: recorded, ok, first ``limit``)."""
    bases = []
    for outcome in prediction.outcomes:
        if len(bases) >= limit:
            break
        if outcome.ok and outcome.rollouts and outcome.rollouts[0].trajectory is not None:
            several = len(outcome.rollouts) > 1
            bases.append(f"world/rollouts/{outcome.index}" + ("-phi0" if several else ""))
    return bases


def _outcome_names(prediction: Prediction) -> list[str]:
    ok = [o for o in prediction.outcomes if o.ok and o.rollouts]
    if not ok:
        return []
    first = ok[0].rollouts[0]
    return [name for name, present in (("fall_fraction", first.fallen is not None),
                                        ("any_fall", first.get("any_fell") is not None), ("far_m", first.get("far_m") is not None),
                                        ("fell_off_count", first.get("fell_off") is not None)) if present] \
        + list(_query_columns(prediction, ok[:1]))


def _query_columns(prediction: Prediction, ok: list) -> dict[str, list[float]]:
    """The per-sample values of the asked queries that chart their own (``Query.sample_columns``)."""
    columns: dict[str, list[float]] = {}
    for name in prediction.request.get("queries", ()):
        if name not in QUERIES:
            continue
        for outcome in ok:
            for key, value in QUERIES[name].sample_columns(outcome).items():
                columns.setdefault(entity_part(key), []).append(value)
    return columns


#: How long a live viewer may take to answer (TCP connect, then taking the recording) before it is
#: given up on. The .rrd file never waits on the viewer: it is written first, on its own.
VIEWER_TIMEOUT_S = 1.0
#: Helper processes streaming recordings to a viewer (each ends itself; reaped as new ones start).
_STREAMERS: list[subprocess.Popen] = []


class ViewerUnavailable(RuntimeError):
    """The recording was written to its file, but the live viewer cannot be reached (the message says why)."""


def _viewer_problem(url: str, timeout_s: float) -> str | None:
    """Why the viewer at ``url`` cannot be reached (None: something accepts connections there)."""
    parsed = urllib.parse.urlsplit(url.removeprefix("rerun+"))
    try:
        port = parsed.port or (443 if parsed.scheme == "https" else 80)
    except ValueError:
        return f"{url!r} has no valid port"
    if not parsed.hostname:
        return f"{url!r} names no host"
    try:
        with socket.create_connection((parsed.hostname, port), timeout=timeout_s):
            return None
    except OSError as exc:
        return f"no viewer at {parsed.hostname}:{port} ({exc.strerror or type(exc).__name__})"


def stream_to_viewer(url: str, path: Path, recording_id: str) -> None:
    """Send the written recording at ``path`` to the viewer at ``url`` without waiting for it:
    ViewerUnavailable at once when nothing listens there (within VIEWER_TIMEOUT_S), otherwise a
    helper process (ipe_ros.viz.stream_to_viewer) sends it and ends itself after VIEWER_TIMEOUT_S."""
    _STREAMERS[:] = [p for p in _STREAMERS if p.poll() is None]
    problem = _viewer_problem(url, VIEWER_TIMEOUT_S)
    if problem is not None:
        raise ViewerUnavailable(problem)
    _STREAMERS.append(subprocess.Popen(
        [sys.executable, "-m", "ipe_ros.viz.stream_to_viewer", url, str(path), recording_id, str(VIEWER_TIMEOUT_S)],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, start_new_session=True))


def write_prediction_rrd(path: str | Path, scene: Scene, prediction: Prediction, *, answer: dict,
                         stamp_ns: int, rollouts_logged: int, connect_url: str | None = None) -> int:
    """Write one ``.rrd`` for one prediction (and optionally stream it to a running viewer).

    ``answer`` is the JSON published for this prediction; returns how many rollouts were logged.
    A viewer is only contacted when ``connect_url`` is given; no viewer is ever spawned. The file is
    written first and on its own, then streamed by ``stream_to_viewer`` (ViewerUnavailable after
    the file is written when nothing listens at the URL).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # one id per recording: a scene predicted twice (same name and stamp, new parameters) must not
    # be merged with its earlier recording by the viewer
    recording_id = f"{scene.name}@{stamp_ns}/{uuid.uuid4().hex[:12]}"
    blueprint = prediction_blueprint(_rollout_bases(prediction, rollouts_logged), _outcome_names(prediction))
    logged = 0

    def log_all(rec: rr.RecordingStream) -> None:
        nonlocal logged
        log_scene(rec, scene)
        logged = log_rollouts(rec, scene, prediction, stamp_ns, rollouts_logged)
        log_outcomes(rec, prediction)
        log_answer(rec, scene, prediction, answer, stamp_ns)

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    rec.save(str(path), default_blueprint=blueprint)
    try:
        log_all(rec)
        rec.flush()
    finally:
        rec.disconnect()
    if connect_url:
        stream_to_viewer(connect_url, path, recording_id)
    return logged


def write_question_rrd(path: str | Path, scene: Scene, answers, *, stamp_ns: int = 0) -> int:
    """One ``.rrd`` for a question about actions (``ipe_ros.engine.actions.Answers`` with recorded
    samples): each variant's rollouts under ``world/<variant label>/sample_<i>/<object>`` (e.g.
    ``world/remove/block3/sample_0/block5``), drawn red where the object fell, and every variant's
    answer as JSON under ``answers/<label>``. Returns how many rollouts were logged."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    def entity(label: str) -> str:
        return "/".join(entity_part(part) for part in label.split("/"))

    rec = rr.RecordingStream(APPLICATION_ID, recording_id=f"{scene.name}@{stamp_ns}/{uuid.uuid4().hex[:12]}")
    rec.save(str(path), default_blueprint=question_blueprint([entity(label) for label in answers.recorded]))
    placed = [v.action.body for v in answers.variants if hasattr(v.action, "body")]
    bodies = {b.name: b for b in (*scene.objects, *placed)}
    logged = 0
    try:
        log_scene(rec, scene)
        for variant in answers.variants:
            rec.log(f"answers/{entity(variant.label)}", rr.TextDocument(json.dumps(variant.to_dict(), indent=1),
                                                                media_type="text/markdown"), static=True)
        for label, samples in answers.recorded.items():
            for index, result in samples:
                rollout = result.rollouts[-1]
                _log_trajectory(rec, f"world/{entity(label)}/sample_{index}", [bodies.get(n) for n in result.names],
                                rollout.trajectory, rollout.fallen, None)
                logged += 1
        rec.flush()
    finally:
        rec.disconnect()
    return logged
