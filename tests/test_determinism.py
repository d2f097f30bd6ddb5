"""One seed per sample: results never depend on worker count, scheduling or preset (for the inputs)."""

import json

import numpy as np
import pytest

from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.scene.examples import example_scene_path

from .helpers import without_timing

MODEL = ModelConfig(sigma_m=0.04, samples=6)
QUERY = QuerySpec(queries=frozenset({"fall", "direction", "far"}))


@pytest.mark.slow
def test_same_seed_same_json_whatever_the_worker_count(pool):
    scene = load_scenes(example_scene_path())[0]
    serial = predict(scene, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=11, budget_s=None))
    two = predict(scene, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=11, budget_s=None),
                  Context(map_fn=pool.map))
    with WorkerPool(1, start_method="spawn") as one_worker:
        one = predict(scene, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=11, budget_s=None),
                      Context(map_fn=one_worker.map))
    texts = {json.dumps(without_timing(p.to_dict()), sort_keys=True) for p in (serial, one, two)}
    assert len(texts) == 1
    other_seed = predict(scene, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=12, budget_s=None),
                         Context(map_fn=pool.map))
    assert without_timing(other_seed.to_dict()) != without_timing(serial.to_dict())


def test_sample_order_does_not_matter():
    # running sample 5 first (a world that saw no other sample) gives what it gave after samples 0..4
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks

    scene = load_scenes(example_scene_path())[0]
    tasks = make_tasks(scene, MODEL, preset("default"), QUERY, seed=5)
    forward = [run_sample(t) for t in tasks]
    backward = [run_sample(t) for t in reversed(tasks)][::-1]
    for a, b in zip(forward, backward):
        assert np.array_equal(a.rollouts[0].final_positions_m, b.rollouts[0].final_positions_m)


def test_noisy_initial_scenes_are_the_same_whatever_the_preset_and_phi():
    scene = load_scenes(example_scene_path())[0]
    model = ModelConfig(sigma_m=0.04, samples=3)
    pushed = ModelConfig(sigma_m=0.04, samples=3, phi_m_s2=(1.0,))
    a = predict(scene, Request(model=model, settings=preset("default"), query=QUERY, seed=2, budget_s=None))
    b = predict(scene, Request(model=model, settings=preset("paper"), query=QUERY, seed=2, budget_s=None))
    c = predict(scene, Request(model=pushed, settings=preset("default"), query=QUERY, seed=2, budget_s=None))
    for x, y, z in zip(a.outcomes, b.outcomes, c.outcomes):
        assert np.array_equal(x.initial_positions_m, y.initial_positions_m)
        assert np.array_equal(x.initial_positions_m, z.initial_positions_m)


def test_predict_many_answers_as_predict_does(pool):
    # several predictions in one map: each keeps its own seeds and outcomes
    from ipe_ros.engine import predict_many
    from ipe_ros.engine.scene.generators import generate_towers

    towers = generate_towers(7, 2)
    requests = [(towers[0], MODEL, 3), (towers[1], MODEL, 4), (towers[0], ModelConfig(), 0),
                (towers[1], ModelConfig(sigma_m=0.04, samples=2, phi_m_s2=(1.0,)), 9)]
    # batch answers are not self-checked (the paper's analyses reproduce fixed settings)
    one_by_one = [predict(scene,
                          Request(model=model, settings=preset("default"), query=QUERY, seed=seed, check=None,
                                  budget_s=None))
                  for scene, model, seed in requests]
    for answers in (predict_many(requests, preset("default"), QUERY),
                    predict_many(requests, preset("default"), QUERY, map_fn=pool.map)):
        assert [json.dumps(without_timing(p.to_dict()), sort_keys=True) for p in answers] == \
            [json.dumps(without_timing(p.to_dict()), sort_keys=True) for p in one_by_one]


def test_predict_many_refuses_a_bad_seed_by_name():
    from ipe_ros.engine import ConfigError, predict_many

    scene = load_scenes(example_scene_path())[0]
    with pytest.raises(ConfigError, match="seed: must be an integer >= 0, got -1"):
        predict_many([(scene, MODEL, -1)], preset("default"), QUERY)


def test_blocks_created_together_simulate_as_blocks_created_one_by_one(monkeypatch):
    # identical consecutive blocks are created by one pybullet call: the world must be the one that
    # creating them one at a time gives, bit for bit, also with blocks turned 90 degrees in between
    from ipe_ros.engine.scene.generators import generate_towers
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.simulation import world

    def one_by_one(p, cid, bodies, positions, masses, orientations, maximal):
        shapes: dict = {}
        return [world._add_body(p, cid, b, pos, float(m), maximal, orn, shapes)
                for b, pos, m, orn in zip(bodies, positions, masses, orientations)]

    towers = generate_towers(3, 3)
    assert any(len({b.orientation_xyzw for b in t.dynamic_objects}) > 1 for t in towers)
    tasks = [t for i, tower in enumerate(towers) for t in make_tasks(tower, MODEL, preset("default"), QUERY, seed=i)]
    together = [run_sample(t) for t in tasks]
    monkeypatch.setattr(world, "_add_dynamic_bodies", one_by_one)
    apart = [run_sample(t) for t in tasks]
    for a, b in zip(together, apart):
        assert a.ok and b.ok
        assert np.array_equal(a.rollouts[0].final_positions_m, b.rollouts[0].final_positions_m)
        assert np.array_equal(a.rollouts[0].final_orientations_xyzw, b.rollouts[0].final_orientations_xyzw)


def test_the_simulation_clients_carry_no_renderer_and_simulate_as_a_client_with_one(monkeypatch):
    # bullet.client() unloads pybullet's software renderer (it meshes every body as it is created,
    # for images these clients never take): that must change nothing a sample simulates
    import pybullet as p

    from ipe_ros.engine.scene.generators import generate_towers
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.simulation import bullet

    cid = bullet.client()
    body = p.createMultiBody(1.0, p.createCollisionShape(p.GEOM_SPHERE, radius=0.1, physicsClientId=cid),
                             physicsClientId=cid)
    with pytest.raises(p.error, match="^Error receiving visual shape info$"):
        p.getVisualShapeData(body, physicsClientId=cid)  # nothing meshed it
    tasks = [t for i, tower in enumerate(generate_towers(5, 2))
             for t in make_tasks(tower, MODEL, preset("default"), QUERY, seed=i)]
    without = [run_sample(t) for t in tasks]
    monkeypatch.setattr(bullet, "RENDERER_PLUGIN", "no such plugin")  # loading it fails: the renderer stays
    monkeypatch.setattr(bullet, "_CLIENTS", {})
    with_renderer = [run_sample(t) for t in tasks]
    cid = bullet.client()
    body = p.createMultiBody(1.0, p.createCollisionShape(p.GEOM_SPHERE, radius=0.1, physicsClientId=cid),
                             physicsClientId=cid)
    assert len(p.getVisualShapeData(body, physicsClientId=cid)) == 1
    p.disconnect(cid)  # this test's own client; the process's goes back in place
    for a, b in zip(without, with_renderer):
        assert a.ok and b.ok
        assert np.array_equal(a.rollouts[0].final_positions_m, b.rollouts[0].final_positions_m)
        assert np.array_equal(a.rollouts[0].final_orientations_xyzw, b.rollouts[0].final_orientations_xyzw)
