"""Digests of predictions with fixed seeds: a refactoring that must not change answers shows it.

    .venv/bin/python benchmarks/bit_identity.py OUT.json          # write the digests
    .venv/bin/python benchmarks/bit_identity.py OUT.json --against BEFORE.json   # and compare

Each case is one prediction (paper towers from ../shared/data/battaglia2013/stability_all_towers.csv,
or generated towers without it; generated Exp. 5 tables): presets default, fine and paper, the fall,
any_fall, direction/far and bump queries, phi > 0, mu, the ground truth and recorded trajectories;
self-checked and anytime predictions (their reports hashed), several predictions in one map
(``predict_many``), and robot questions (remove, support, place, push, sequential decisions; each
with and without the self-check) on a generated tower. A prediction's digest hashes every sample's initial and final poses, simulated time
and trajectory, and the answer's fields; a question's hashes its JSON answer without wall-clock times
and the trajectories of its recorded samples; and predictions from vision and from depth perception. Equal digests mean bit-identical answers. Exit status 1
when any digest differs.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import sys

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from ipe_ros.analysis.paper_data import shared_data_dir  # noqa: E402
from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, predict_many, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.predict import AdaptiveStop  # noqa: E402
from ipe_ros.engine.checking.fidelity import DEFAULT_CHECK  # noqa: E402
from ipe_ros.engine.scene.generators import generate_tables, generate_towers  # noqa: E402

ANSWER_FIELDS = ("fall_fraction", "fall_fraction_ci95", "object_fall_probability", "any_fall_probability",
                 "direction_rad", "direction_decisiveness", "far_m", "far_m_ci95", "fell_off_fraction_by_group",
                 "bump_ratio", "samples", "failed_samples", "failure_reasons")


def _hash_outcomes(h, outcomes) -> None:
    for o in outcomes:
        h.update(repr((o.index, o.ok, o.error, o.push_direction_rad)).encode())
        if o.ok:
            h.update(o.initial_positions_m.tobytes())
            h.update(o.initial_orientations_xyzw.tobytes())
            for r in o.rollouts:
                h.update(r.final_positions_m.tobytes())
                h.update(r.final_orientations_xyzw.tobytes())
                h.update(repr(r.simulated_s).encode())
                for t, positions, _ in r.trajectory or ():
                    h.update(repr(t).encode())
                    h.update(positions.tobytes())


def digest(prediction) -> str:
    h = hashlib.sha256()
    _hash_outcomes(h, prediction.outcomes)
    answer = {k: getattr(prediction, k) for k in ANSWER_FIELDS}
    h.update(json.dumps(answer, sort_keys=True, default=list).encode())
    return h.hexdigest()[:16]


def cases():
    path = shared_data_dir() / "stability_all_towers.csv"
    towers = load_scenes(path)[:6] if path.exists() else generate_towers(2013, 6)
    tables = generate_tables(3, 1)[:2]
    sigma = ModelConfig(sigma_m=0.04, samples=6)
    for name in ("default", "fine", "paper"):
        for tower in towers[:(6 if name != "paper" else 2)]:
            yield f"{name}/{tower.name}/fall", tower, sigma, name, {"fall"}, 0
    for tower in towers[:4]:
        yield f"default/{tower.name}/gt", tower, ModelConfig(), "default", {"fall", "direction", "far"}, 0
        yield f"default/{tower.name}/any", tower, sigma, "default", {"any_fall"}, 0
        yield (f"default/{tower.name}/phi2", tower, ModelConfig(sigma_m=0.04, phi_m_s2=(2.0,), samples=4), "default",
               {"fall", "direction", "far"}, 0)
        yield f"fine/{tower.name}/mu", tower, ModelConfig(sigma_m=0.04, mu=8.0, samples=4), "fine", {"fall", "direction"}, 0
        yield (f"default/{tower.name}/rec", tower, ModelConfig(sigma_m=0.04, samples=3), "default",
               {"fall", "direction", "far"}, 4)
    for table in tables:
        model = ModelConfig(sigma_m=0.02, phi_m_s2=(1.0, 3.0), samples=4, force_direction_rad=0.5)
        yield f"default/{table.name}/bump", table, model, "default", {"bump"}, 0


#: robot questions as a robot sends them (the node's ~/ask JSON), on a generated tower
QUESTIONS = {
    "remove": {"question": "remove", "samples": 8},
    "remove_safe": {"question": "remove", "safe_below": 0.05, "samples": 8},
    "support": {"question": "support", "samples": 8},
    "place": {"question": "place", "object": {"name": "new", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.1]},
                                              "mass_kg": 1.0, "friction": 0.5, "restitution": 0.0},
              "at": [[0.0, 0.0, 30.0], [0.3, 0.1, 0.0]], "samples": 8, "what_falls": True},
    "remove_sequential": {"question": "remove", "safe_below": 0.3, "samples": 24, "sequential": True},
    "support_sequential": {"question": "support", "samples": 24, "sequential": True},
    "remove_contact": {"question": "remove", "objects": ["block3"], "contact": ["block0:support", "block8:support", "block7:block6"],
                       "samples": 8, "sequential": False},
    "push": {"question": "push", "object": "block2", "velocity_m_s": [0.4, 0.0], "direction_sigma_deg": 5.0,
             "speed_sigma": 0.1, "samples": 8},
}


def _without_times(value):
    """A JSON answer without its wall-clock fields (they differ run to run)."""
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items() if not (k == "wall_s" or k.endswith("wall_s"))}
    if isinstance(value, list):
        return [_without_times(v) for v in value]
    return value


def question_digest(reply: dict, answers) -> str:
    h = hashlib.sha256()
    h.update(json.dumps(_without_times(reply), sort_keys=True, default=list).encode())
    for label, rows in sorted((answers.recorded if answers is not None else {}).items()):
        h.update(label.encode())
        h.update(repr([index for index, _ in rows]).encode())
        _hash_outcomes(h, [outcome for _, outcome in rows])
    return h.hexdigest()[:16]


def question_cases():
    from ipe_ros.engine.actions.question import question_from_dict
    tower = generate_towers(2013, 1)[0]
    model = ModelConfig(sigma_m=0.04, samples=8)
    for name, data in QUESTIONS.items():
        for checked in (False, True):
            question = question_from_dict({**data, "self_check": checked})
            yield f"question/{name}" + ("/checked" if checked else ""), tower, question, model
    # a removal read from the scene as it is (a block 5 m from the tower: out of everything's reach)
    # beside simulated ones
    first = tower.objects[0]
    lone = dataclasses.replace(first, name="lone", position_m=(5.0, 0.0, first.position_m[2]))
    apart = question_from_dict({"question": "remove", "objects": ["lone", "block9", "block0"], "samples": 8})
    yield "question/remove_apart", dataclasses.replace(tower, objects=tower.objects + (lone,)), apart, model


def checked_cases():
    """Predictions that check themselves (verification, coverage, confirmation, escalation) and
    anytime ones (batches until a target interval width), checked too: the report is hashed."""
    path = shared_data_dir() / "stability_all_towers.csv"
    towers = load_scenes(path)[:4] if path.exists() else generate_towers(2013, 4)
    model = ModelConfig(sigma_m=0.04, samples=12)
    for tower in towers:
        yield f"checked/{tower.name}", tower, model, None
        yield (f"anytime/{tower.name}", tower, dataclasses.replace(model, samples=24),
               AdaptiveStop(ci_width=0.45, batch_size=4))


def perception_cases():
    """Predictions from vision and from depth perception (small chains): their posterior scenes and
    the perception's own report (acceptance, ESS, spreads) are hashed with the answer."""
    from ipe_ros.engine.vision import VisionSettings
    from ipe_ros.engine.vision import depth as D
    from ipe_ros.engine.vision.camera import look_at

    tower = generate_towers(2013, 1)[0]
    small = dataclasses.replace(tower, objects=tower.objects[:3])
    vision = VisionSettings(resolution_px=64, chain_samples=300, burn_in=60)
    yield "vision/tower3", small, ModelConfig(perception="vision", vision=vision, samples=4), None
    camera = look_at((1.0, -0.7, 0.6), (0.0, 0.0, 0.1), width_px=160, height_px=120)
    observation = D.DepthObservation(camera, D.render_depth_m(small, camera))
    perceived = D.perceive_depth_for(small, 4, (observation,), seed=7,
                                     settings=D.DepthSettings(kept_states=24))
    yield "depth/tower3", small, ModelConfig(perception="depth", samples=4), perceived


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out")
    parser.add_argument("--against", default=None, help="digests of an earlier run to compare with")
    args = parser.parse_args()
    result = {}
    for key, scene, model, preset_name, queries, record_every in cases():
        # the physics itself: the self-check would rerun unhealthy rollouts at `paper` (engine.checking.fidelity)
        p = predict(scene,
                    Request(model=model, settings=preset(preset_name), query=QuerySpec(queries=frozenset(queries)),
                            seed=7, check=None, budget_s=None),
                    Context(record_every=record_every))
        result[key] = digest(p)
        print(key, result[key], flush=True)
    for key, scene, model, stop in checked_cases():
        p = predict(scene,
                    Request(model=model, settings=preset("default"),
                            query=QuerySpec(queries=frozenset({"fall", "any_fall"})), seed=7, stop=stop,
                            check=DEFAULT_CHECK, budget_s=None))
        h = hashlib.sha256(digest(p).encode())
        h.update(json.dumps([p.self_check, p.stopped_by, p.samples_requested], sort_keys=True, default=list).encode())
        result[key] = h.hexdigest()[:16]
        print(key, result[key], flush=True)
    # several predictions' samples in one map (what ipe experiment runs)
    batch = [(scene, model, i) for i, (key, scene, model, *_) in enumerate(cases()) if key.startswith("default/")][:8]
    for i, p in enumerate(predict_many(batch, preset("default"), QuerySpec(queries=frozenset({"fall", "direction"})))):
        result[f"many/{i}"] = digest(p)
        print(f"many/{i}", result[f"many/{i}"], flush=True)
    for key, scene, model, perceived in perception_cases():
        p = predict(scene,
                    Request(model=model, settings=preset("default"),
                            query=QuerySpec(queries=frozenset({"fall", "any_fall"})), seed=7, check=None,
                            budget_s=None),
                    Context(perceived=perceived))
        h = hashlib.sha256(digest(p).encode())
        h.update(json.dumps(p.request.get("perception"), sort_keys=True, default=list).encode())
        result[key] = h.hexdigest()[:16]
        print(key, result[key], flush=True)
    for key, scene, question, model in question_cases():
        reply = question.answer(scene, model, preset("default"), seed=7, check=DEFAULT_CHECK, record_every=8,
                                record_samples=2)
        result[key] = question_digest(reply.data, reply.answers)
        print(key, result[key], flush=True)
    with open(args.out, "w") as handle:
        json.dump(result, handle, indent=1)
    if args.against is None:
        return 0
    with open(args.against) as handle:
        before = json.load(handle)
    differ = sorted(k for k in before if before[k] != result.get(k))
    print(f"{len(before) - len(differ)} of {len(before)} cases bit-identical" + (f"; differ: {differ}" if differ else ""))
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
