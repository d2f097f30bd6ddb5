"""The IPE on a Dask cluster: a LocalCluster on loopback (2 worker processes) gives bit-identical answers
to the local pool, and tasks whose workers die are counted, not fatal."""

from __future__ import annotations

import os

import pytest

distributed = pytest.importorskip("distributed", reason="dask/distributed are pinned in requirements.txt")

from ipe_ros.engine import ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset  # noqa: E402
from ipe_ros.engine import Context, Request
from ipe_ros.engine.compute.cluster import DaskMap, local_cluster, scheduler_address  # noqa: E402

#: a Dask LocalCluster per test
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cluster():
    # one reschedule, not three, so that the lost-worker test ends quickly
    with local_cluster(2, **{"distributed.scheduler.allowed-failures": 1}) as client:
        yield client


def test_a_prediction_on_the_cluster_is_bit_identical_to_the_local_pool(cluster):
    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    model, query = ModelConfig(sigma_m=0.04, samples=12), QuerySpec(queries=frozenset({"fall", "any_fall", "direction"}))
    with WorkerPool(2) as pool:
        local = predict(tower, Request(model=model, settings=preset("default"), query=query, seed=5, budget_s=None),
                        Context(map_fn=pool.map))
    remote = predict(tower, Request(model=model, settings=preset("default"), query=query, seed=5, budget_s=None),
                     Context(map_fn=DaskMap(cluster, batch_size=5).map))
    strip = lambda p: {k: v for k, v in p.to_dict().items() if k != "wall_s"}  # noqa: E731
    assert strip(remote) == strip(local)
    for a, b in zip(local.outcomes, remote.outcomes):
        assert (a.initial_positions_m == b.initial_positions_m).all()
        assert (a.rollouts[0].final_positions_m == b.rollouts[0].final_positions_m).all()


def _dies_on_three(x: int) -> int:
    if x == 3:
        os._exit(1)  # the worker process dies under this task, every time
    return 10 * x


def test_tasks_whose_workers_die_are_answered_by_on_lost(cluster):
    results = DaskMap(cluster, batch_size=1).map(_dies_on_three, range(6), on_lost=lambda x, why: ("lost", x, why))
    assert results[:3] == [0, 10, 20] and results[4:] == [40, 50]
    assert results[3][:2] == ("lost", 3) and "died" in results[3][2]
    with pytest.raises(distributed.KilledWorker):
        DaskMap(cluster, batch_size=1).map(_dies_on_three, [3])


def test_the_scheduler_comes_from_the_option_or_the_environment(monkeypatch):
    monkeypatch.delenv("IPE_DASK_SCHEDULER", raising=False)
    assert scheduler_address(None) is None and scheduler_address("  ") is None
    monkeypatch.setenv("IPE_DASK_SCHEDULER", "tcp://127.0.0.1:8786")
    assert scheduler_address(None) == "tcp://127.0.0.1:8786"
    assert scheduler_address("tcp://10.0.0.2:8786") == "tcp://10.0.0.2:8786"


def test_ipe_predict_on_a_scheduler_answers_as_it_does_locally(cluster):
    import json
    import subprocess
    import sys

    command = [sys.executable, "-m", "ipe_ros.cli", "predict", "ipe_ros/data/example_tower.json", "--samples", "6",
               "--json", "--seed", "3"]
    local = subprocess.run(command + ["--workers", "2"], capture_output=True, text=True, timeout=300)
    remote = subprocess.run(command + ["--scheduler", cluster.scheduler.address], capture_output=True, text=True,
                            timeout=300)
    assert local.returncode == 0 and remote.returncode == 0, remote.stderr
    strip = lambda text: {k: v for k, v in json.loads(text).items() if k != "wall_s"}  # noqa: E731
    assert strip(remote.stdout) == strip(local.stdout)
    unreachable = subprocess.run(command + ["--scheduler", "tcp://127.0.0.1:9"], capture_output=True, text=True,
                                 timeout=300, env={**os.environ, "DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT": "2s"})
    assert unreachable.returncode == 2
    assert unreachable.stderr.startswith("ipe: error: --scheduler: cannot reach the Dask scheduler at "
                                         "'tcp://127.0.0.1:9'")


def test_a_node_offloads_its_samples_to_the_cluster(cluster):
    import json

    from std_msgs.msg import String

    from ipe_ros.engine.scene.format import scene_to_json
    from ipe_ros.ros.node import LATCHED_QOS
    from tests.ros_harness import RosHarness, wait_until

    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    ros = RosHarness()
    try:
        node = ros.start_ipe_node(samples=6, seed=4, dask_scheduler=cluster.scheduler.address)
        answers = ros.collect(String, "/ipe/prediction", LATCHED_QOS)
        ros.publisher(String, "/ipe/scene_json").publish(String(data=scene_to_json(tower)))
        wait_until(lambda: len(answers), 120.0, "an answer computed on the cluster")
        stats = node.service.stats()
        assert stats.workers == 2 and stats.workers_alive == 2  # the Dask workers
    finally:
        ros.close()
    with WorkerPool(2) as pool:
        local = predict(tower,
                        Request(model=ModelConfig(sigma_m=0.04, samples=6), settings=preset("default"),
                                query=QuerySpec(queries=frozenset({"fall", "any_fall", "direction", "far"})), seed=4,
                                budget_s=None),
                        Context(map_fn=pool.map))
    answer = json.loads(answers[0].data)
    assert answer["fall_fraction"] == local.fall_fraction and answer["direction_rad"] == local.direction_rad
