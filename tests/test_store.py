"""Resumable runs: results kept on disk by what they are a function of; a run started again computes only
what is missing and answers as an uninterrupted run does."""

from __future__ import annotations

import base64
import json
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest

from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.compute.store import STORE_VERSION, ResumableMap, result_key
from tests.conftest import REPO

TOWER = load_scenes("ipe_ros/data/example_tower.json")[0]
MODEL, QUERY = ModelConfig(sigma_m=0.04, samples=6), QuerySpec(queries=frozenset({"fall", "direction"}))
# resumable runs serve the batch analyses, which are not self-checked (check=None): the maps here
# see only the k samples


def test_a_run_started_again_reads_back_what_it_has_and_computes_the_rest(tmp_path):
    fresh = predict(TOWER,
                    Request(model=MODEL, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None))
    half = ResumableMap(tmp_path)
    predict(TOWER,
            Request(model=ModelConfig(sigma_m=0.04, samples=3), settings=preset("default"), query=QUERY, seed=1,
                    check=None, budget_s=None),
            Context(map_fn=half.map))
    assert (half.hits, half.computed) == (0, 3)  # an "interrupted" run: the first 3 samples of seed 1
    again = ResumableMap(tmp_path)
    resumed = predict(TOWER,
                      Request(model=MODEL, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None),
                      Context(map_fn=again.map))
    assert (again.hits, again.computed) == (3, 3)
    strip = lambda p: {k: v for k, v in p.to_dict().items() if k not in ("wall_s", "samples_requested")}  # noqa: E731
    assert strip(resumed) == strip(fresh)
    other = ResumableMap(tmp_path)
    predict(TOWER, Request(model=MODEL, settings=preset("default"), query=QUERY, seed=2, check=None, budget_s=None),
            Context(map_fn=other.map))  # another seed: nothing to reuse
    assert other.hits == 0


def test_samples_lost_with_their_worker_are_not_kept_and_come_out_in_the_next_run(tmp_path):
    def every_worker_dies(fn, items, on_lost):
        return [on_lost(item, "the worker running it died twice") for item in items]

    lost_run = ResumableMap(tmp_path, inner=every_worker_dies)
    answer = predict(TOWER,
                     Request(model=MODEL, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None),
                     Context(map_fn=lost_run.map))
    assert answer.failed_samples == MODEL.samples
    assert answer.failure_reasons == ("WorkerLost: the worker running it died twice",)
    again = ResumableMap(tmp_path)
    resumed = predict(TOWER,
                      Request(model=MODEL, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None),
                      Context(map_fn=again.map))
    assert (again.hits, again.computed, resumed.failed_samples) == (0, MODEL.samples, 0)


def test_keys_follow_what_a_result_depends_on_and_not_when_it_ran():
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks

    [a, b] = make_tasks(TOWER, ModelConfig(sigma_m=0.04, samples=2), preset("default"), QUERY, 0)
    [c, _] = make_tasks(TOWER, ModelConfig(sigma_m=0.05, samples=2), preset("default"), QUERY, 0)
    import dataclasses
    assert result_key(run_sample, a) != result_key(run_sample, b) != result_key(run_sample, c)
    assert result_key(run_sample, a) == result_key(run_sample, dataclasses.replace(a, deadline_unix_s=1e9))


def test_a_task_field_keyed_when_set_keeps_older_runs_keys_until_it_is_set():
    """``SampleTask.refine`` came after runs were stored: unset, it is not in the key."""
    import dataclasses

    from ipe_ros.engine.checking.fidelity import reference_settings
    from ipe_ros.engine.compute.store import _canonical
    from ipe_ros.engine.sampling.rollout import Refine, run_sample
    from ipe_ros.engine.predict import make_tasks

    [a] = make_tasks(TOWER, ModelConfig(sigma_m=0.04, samples=1), preset("default"), QUERY, 0)
    assert "refine" not in [name for name, _ in _canonical(a)[1]]
    refined = dataclasses.replace(a, refine=Refine(reference_settings(), 0.05, 0.01))
    assert "refine" in [name for name, _ in _canonical(refined)[1]]
    assert result_key(run_sample, a) != result_key(run_sample, refined)


@pytest.mark.slow
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


# --- entries are data: a crafted, damaged or foreign entry is reported in one line and recomputed ---

def _one_sample_run(folder, **kwargs):
    store = ResumableMap(folder, **kwargs)
    answer = predict(TOWER,
                     Request(model=ModelConfig(sigma_m=0.04, samples=1), settings=preset("default"), query=QUERY,
                             seed=1, check=None, budget_s=None),
                     Context(map_fn=store.map))
    return store, answer


def _only_entry(folder):
    [entry] = [p for p in folder.rglob("*.json")]
    return entry


class _RunsAShellCommand:
    """What a crafted pickle does when loaded: here it would create ``marker``."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _damage_cases(tmp_path):
    valid = json.loads(_only_entry(tmp_path / "store").read_text())
    other_type = dict(valid, result={"dataclass": "Popen", "fields": {"args": "touch x"}})
    wrong_field = json.loads(json.dumps(valid))
    wrong_field["result"]["fields"]["index"] = "zero"
    bad_array = json.loads(json.dumps(valid))
    bad_array["result"]["fields"]["initial_positions_m"]["shape"] = [99, 3]
    short_fallen = json.loads(json.dumps(valid))  # well-formed, but one body's outcome missing
    values = short_fallen["result"]["fields"]["rollouts"]["tuple"][0]["fields"]["values"]["dict"]
    fallen = next(value for name, value in values if name == "fallen")
    fallen.update(shape=[fallen["shape"][0] - 1], data=base64.b64encode(b"\0" * (fallen["shape"][0] - 1)).decode())
    object_array = json.loads(json.dumps(valid))
    object_array["result"]["fields"]["initial_positions_m"]["array"] = "object"
    return {
        "pickle": (pickle.dumps(_RunsAShellCommand(tmp_path / "marker")), "not a JSON document"),
        "empty": (b"", "not a JSON document"),
        "truncated": (json.dumps(valid).encode()[:200], "not a JSON document"),
        "list": (b"[1, 2, 3]", "not an ipe_ros.result entry"),
        "old version": (json.dumps(dict(valid, version=STORE_VERSION - 1)).encode(),
                        f"version {STORE_VERSION - 1}, this engine writes {STORE_VERSION}"),
        "another key": (json.dumps(dict(valid, key="0" * 64)).encode(), "stored under another result's name"),
        "another type": (json.dumps(other_type).encode(), "result: 'Popen' is not a result type"),
        "a field of the wrong type": (json.dumps(wrong_field).encode(),
                                      "result.index: a str where a <class 'int'> belongs"),
        "an array that does not fill its shape": (json.dumps(bad_array).encode(), "do not fill a float64 array"),
        "an object array": (json.dumps(object_array).encode(), "arrays of 'object' are not allowed"),
        "a value for fewer bodies": (json.dumps(short_fallen).encode(),
                                     "result.rollouts[0].values.fallen: shape (9,), the sample has 10 bodies so (10,)"),
        "deep nesting": (b"[" * 100_000 + b"]" * 100_000, "nested deeper than any result"),
    }


def test_a_crafted_or_damaged_entry_is_reported_in_one_line_and_recomputed_never_run(tmp_path):
    _, fresh = _one_sample_run(tmp_path / "store")
    for case, (content, reason) in _damage_cases(tmp_path).items():
        entry = _only_entry(tmp_path / "store")
        entry.write_bytes(content)
        lines = []
        store, answer = _one_sample_run(tmp_path / "store", report=lines.append)
        assert (store.hits, store.computed, store.rejected) == (0, 1, 1), case
        assert len(lines) == 1 and lines[0].startswith(f"ipe: ignoring store entry {entry} and computing it again: ")
        assert reason in lines[0], (case, lines[0])
        assert answer.to_dict()["object_fall_probability"] == fresh.to_dict()["object_fall_probability"], case
        again, _ = _one_sample_run(tmp_path / "store", report=lines.append)  # the recomputed entry was written back
        assert (again.hits, again.rejected) == (1, 0), case
    assert not (tmp_path / "marker").exists()


def test_a_well_formed_entry_of_another_scene_is_refused_naming_both_counts(tmp_path):
    """Poisoned but well-formed: every array consistent, for a scene of 9 bodies stored under the
    10-body tower's name; it was aggregated as the tower's (numpy's All-NaN slice, naming nothing)."""
    import dataclasses

    _, fresh = _one_sample_run(tmp_path / "store")
    entry = _only_entry(tmp_path / "store")
    shorter = dataclasses.replace(TOWER, objects=TOWER.objects[:-1])
    other = ResumableMap(tmp_path / "other")
    predict(shorter,
            Request(model=ModelConfig(sigma_m=0.04, samples=1), settings=preset("default"), query=QUERY, seed=1,
                    check=None, budget_s=None),
            Context(map_fn=other.map))
    poisoned = json.loads(_only_entry(tmp_path / "other").read_text())
    poisoned["key"] = json.loads(entry.read_text())["key"]
    entry.write_text(json.dumps(poisoned))
    lines = []
    store, answer = _one_sample_run(tmp_path / "store", report=lines.append)
    assert (store.hits, store.computed, store.rejected) == (0, 1, 1)
    assert lines == [f"ipe: ignoring store entry {entry} and computing it again: result: 9 bodies, but the scene it "
                     f"is read for ({TOWER.name}) has 10"]
    assert answer.to_dict()["object_fall_probability"] == fresh.to_dict()["object_fall_probability"]


def test_links_and_oversized_entries_are_refused_unread(tmp_path, monkeypatch):
    _one_sample_run(tmp_path / "store")
    entry = _only_entry(tmp_path / "store")
    target = tmp_path / "elsewhere.json"
    target.write_bytes(entry.read_bytes())  # even a valid entry is not read through a link
    entry.unlink()
    entry.symlink_to(target)
    lines = []
    store, _ = _one_sample_run(tmp_path / "store", report=lines.append)
    assert store.rejected == 1 and lines[0].endswith("not a regular file (a link or a folder)")
    assert not entry.is_symlink()  # replaced by the recomputed entry; the link's target untouched
    import ipe_ros.engine.compute.store as store_module
    monkeypatch.setattr(store_module, "MAX_ENTRY_BYTES", 100)
    store, _ = _one_sample_run(tmp_path / "store", report=lines.append)
    assert store.rejected == 1 and lines[-1].endswith("bytes, more than the 100 an entry may have")


def test_every_stored_result_type_reads_back_equal():
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.scene.format import scene_to_dict
    from ipe_ros.engine.compute.store import decode_entry, encode_entry
    from ipe_ros.engine.vision.likelihood import VisionSettings
    from ipe_ros.engine.vision.perception import perceive

    [task] = make_tasks(TOWER, ModelConfig(sigma_m=0.04, samples=1), preset("default"),
                        QuerySpec(queries=frozenset({"fall", "direction", "far"})), 0)
    outcome = run_sample(task)
    back = decode_entry(encode_entry(outcome, "k"), "k")
    assert type(back) is type(outcome) and back.index == outcome.index and back.ok is outcome.ok
    np.testing.assert_array_equal(back.initial_positions_m, outcome.initial_positions_m)
    for a, b in zip(back.rollouts, outcome.rollouts, strict=True):
        assert (a.get("direction_rad"), a.get("far_m"), a.simulated_s, a.get("any_fell")) == (
            b.get("direction_rad"), b.get("far_m"), b.simulated_s, b.get("any_fell"))
        np.testing.assert_array_equal(a.final_orientations_xyzw, b.final_orientations_xyzw)
        np.testing.assert_array_equal(a.fallen, b.fallen)
        assert a.fallen.dtype == b.fallen.dtype
    seen = perceive(TOWER, 2, VisionSettings(resolution_px=32, chain_samples=40, burn_in=10),
                    np.random.default_rng(0), check_ess=False)
    back = decode_entry(encode_entry(seen, "k"), "k")
    assert [scene_to_dict(s) for s in back.scenes] == [scene_to_dict(s) for s in seen.scenes]
    assert (back.acceptance_rate, back.effective_sample_size) == (seen.acceptance_rate, seen.effective_sample_size)
    np.testing.assert_array_equal(back.chain.positions_m, seen.chain.positions_m)
    np.testing.assert_array_equal(back.chain.accepted, seen.chain.accepted)


def test_the_store_writes_only_inside_itself_whatever_links_are_planted_in_it(tmp_path):
    """A link planted where an entry or a whole shard folder belongs is never written through: the
    entry's link is replaced by the entry, a shard that is a link is left alone and reported, and a
    file outside the store stays as it was (ipe experiment --resume ran as root once overwrote one)."""
    _, fresh = _one_sample_run(tmp_path / "store")
    entry = _only_entry(tmp_path / "store")
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    entry.unlink()
    entry.symlink_to(victim)
    lines = []
    _one_sample_run(tmp_path / "store", report=lines.append)
    assert victim.read_text() == "precious"
    assert entry.is_file() and not entry.is_symlink()
    assert [p.name for p in entry.parent.iterdir()] == [entry.name]  # no temporary file left behind
    # the whole shard folder a link to a folder outside the store
    outside = tmp_path / "outside"
    outside.mkdir()
    shard = entry.parent
    for p in shard.iterdir():
        p.unlink()
    shard.rmdir()
    shard.symlink_to(outside, target_is_directory=True)
    lines = []
    store, answer = _one_sample_run(tmp_path / "store", report=lines.append)
    assert list(outside.iterdir()) == []
    assert (store.hits, store.computed, store.rejected) == (0, 1, 1)
    refusal = f"its folder {shard} is not a folder of the store (a link or a file)"
    assert lines == [f"ipe: ignoring store entry {entry} and computing it again: {refusal}",
                     f"ipe: not storing {entry}: {refusal}; remove it to store results there again"]
    assert answer.to_dict()["object_fall_probability"] == fresh.to_dict()["object_fall_probability"]


def test_a_link_planted_at_the_temporary_file_s_name_is_never_written_through(tmp_path, monkeypatch):
    import ipe_ros.engine.safe_files as safe_files

    _one_sample_run(tmp_path / "store")
    entry = _only_entry(tmp_path / "store")
    entry.unlink()
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    monkeypatch.setattr(safe_files.secrets, "token_hex", lambda _n: "guessed")
    planted = entry.parent / f"{entry.name}.{os.getpid()}.guessed.part"
    planted.symlink_to(victim)
    lines = []
    store, _ = _one_sample_run(tmp_path / "store", report=lines.append)
    assert victim.read_text() == "precious" and planted.is_symlink() and not entry.exists()
    assert store.computed == 1 and len(lines) == 1
    assert lines[0].startswith(f"ipe: not storing {entry}: its temporary file {planted.name} exists already")
