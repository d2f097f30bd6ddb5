"""Resumable runs: results kept on disk by what they are a function of; a run started again computes only
what is missing and answers as an uninterrupted run does."""

from __future__ import annotations

import json
import subprocess
import sys

from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine.store import ResumableMap, result_key
from tests.conftest import REPO

TOWER = load_scenes("ipe_ros/data/example_tower.json")[0]
MODEL, QUERY = ModelConfig(sigma_m=0.04, samples=6), QuerySpec(queries=frozenset({"fall", "direction"}))
#: resumable runs serve the batch analyses, which are not self-checked: the maps here see only the k samples
UNCHECKED = {"check": None}


def test_a_run_started_again_reads_back_what_it_has_and_computes_the_rest(tmp_path):
    fresh = predict(TOWER, MODEL, preset("default"), QUERY, seed=1, **UNCHECKED)
    half = ResumableMap(tmp_path)
    predict(TOWER, ModelConfig(sigma_m=0.04, samples=3), preset("default"), QUERY, seed=1, map_fn=half.map, **UNCHECKED)
    assert (half.hits, half.computed) == (0, 3)  # an "interrupted" run: the first 3 samples of seed 1
    again = ResumableMap(tmp_path)
    resumed = predict(TOWER, MODEL, preset("default"), QUERY, seed=1, map_fn=again.map, **UNCHECKED)
    assert (again.hits, again.computed) == (3, 3)
    strip = lambda p: {k: v for k, v in p.to_dict().items() if k not in ("wall_s", "samples_requested")}  # noqa: E731
    assert strip(resumed) == strip(fresh)
    other = ResumableMap(tmp_path)
    predict(TOWER, MODEL, preset("default"), QUERY, seed=2, map_fn=other.map, **UNCHECKED)  # another seed: nothing to reuse
    assert other.hits == 0


def test_samples_lost_with_their_worker_are_not_kept_and_come_out_in_the_next_run(tmp_path):
    def every_worker_dies(fn, items, on_lost):
        return [on_lost(item, "the worker running it died twice") for item in items]

    lost_run = ResumableMap(tmp_path, inner=every_worker_dies)
    answer = predict(TOWER, MODEL, preset("default"), QUERY, seed=1, map_fn=lost_run.map, **UNCHECKED)
    assert answer.failed_samples == MODEL.samples
    assert answer.failure_reasons == ("WorkerLost: the worker running it died twice",)
    again = ResumableMap(tmp_path)
    resumed = predict(TOWER, MODEL, preset("default"), QUERY, seed=1, map_fn=again.map, **UNCHECKED)
    assert (again.hits, again.computed, resumed.failed_samples) == (0, MODEL.samples, 0)


def test_keys_follow_what_a_result_depends_on_and_not_when_it_ran():
    from ipe_ros.engine.rollout import run_sample
    from ipe_ros.engine.sampler import make_tasks

    [a, b] = make_tasks(TOWER, ModelConfig(sigma_m=0.04, samples=2), preset("default"), QUERY, 0)
    [c, _] = make_tasks(TOWER, ModelConfig(sigma_m=0.05, samples=2), preset("default"), QUERY, 0)
    import dataclasses
    assert result_key(run_sample, a) != result_key(run_sample, b) != result_key(run_sample, c)
    assert result_key(run_sample, a) == result_key(run_sample, dataclasses.replace(a, deadline_unix_s=1e9))


def test_ipe_experiment_resume_reads_everything_back_the_second_time(tmp_path):
    command = [sys.executable, "-m", "ipe_ros.cli", "experiment", "far", "--quick", "--workers", "2", "--resamples",
               "500", "--resume", str(tmp_path / "store")]
    first = subprocess.run(command + ["--out", str(tmp_path / "a")], cwd=REPO, capture_output=True, text=True,
                           timeout=600)
    second = subprocess.run(command + ["--out", str(tmp_path / "b")], cwd=REPO, capture_output=True, text=True,
                            timeout=600)
    assert first.returncode == 0 and second.returncode == 0, second.stderr[-2000:]
    assert " 0 computed" in second.stderr and "0 results read back" in first.stderr
    a, b = (json.loads((tmp_path / d / "far.json").read_text())["results"] for d in ("a", "b"))
    assert a == b
