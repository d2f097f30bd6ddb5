"""The benchmark scripts still run: a tiny accuracy-versus-time sweep end to end.

No timing is asserted (timings belong in the benchmark's own output); this checks that the
reference is the first row, the swept settings are the ones named, and the outputs are written.
"""

import json
import math
import os
import subprocess
import sys
from pathlib import Path
import pytest

#: runs every benchmark script small: minutes, not part of the fast subset
pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
ENV = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")


def test_accuracy_vs_time_writes_table_json_and_plot_with_paper_as_reference(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "accuracy_vs_time.py"), "--towers", "2", "--samples", "2",
         "--workers", "1", "--phi", "0", "--query", "fall", "--no-k-sweep",
         "--only", "default,default-1/120s-uncapped", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "accuracy_vs_time.json").read_text())
    assert data["towers"] == 2 and data["samples"] == 2 and data["queries"] == ["fall"]
    rows = {row["config"]: row for row in data["rows"]}
    assert [row["config"] for row in data["rows"]][0] == "paper"
    assert set(rows) >= {"paper", "default", "default-1/120s-uncapped"}
    paper = rows["paper"]
    assert paper["speedup_vs_paper"] == 1.0 and paper["mean_abs_dff"] == 0.0 and paper["per_sample_agreement"] == 1.0
    for row in rows.values():
        assert row["failed_samples"] == 0
        assert math.isfinite(row["wall_s_per_prediction"]) and row["wall_s_per_prediction"] > 0
    # the uncapped candidate really runs 1/120 s steps on these 0.2 m blocks
    assert rows["default-1/120s-uncapped"]["settings"]["time_step_s"] == 1 / 120
    assert rows["default-1/120s-uncapped"]["settings"]["max_step_fraction_of_time_scale"] == 0.1
    assert "| paper |" in (tmp_path / "accuracy_vs_time.md").read_text()
    assert (tmp_path / "accuracy_vs_time.png").stat().st_size > 1000


def _time_budget(tmp_path, preset_name):
    out = tmp_path / preset_name
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "time_budget.py"), "--towers", "2", "--samples", "2",
         "--preset", preset_name, "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((out / "time_budget.json").read_text())
    assert "| **total** |" in (out / "time_budget.md").read_text()
    return report["result"], {row["part"]: row for row in report["result"]["parts"]}


def test_time_budget_files_every_step_under_the_phase_it_ran_in(tmp_path):
    # default on 0.2 m blocks: 1/180 s steps, the first 0.1 s (18 ticks) in two substeps each
    result, parts = _time_budget(tmp_path, "default")
    assert result["samples_run"] == 4
    assert parts["settle steps"]["steps_per_sample"] == 36
    assert parts["fine steps"]["steps_per_sample"] > 0
    # the parts are the whole: what the timers missed lands in the last row, never below zero
    assert math.isclose(sum(row["ms_per_sample"] for row in parts.values()), result["ms_per_sample"], rel_tol=1e-9)
    assert all(row["ms_per_sample"] >= 0 for row in parts.values())
    assert sum(row["samples"] for row in result["by_outcome"]) == 4
    # paper: 1 ms steps for the whole 2 s, no settling, no collapse steps
    result, parts = _time_budget(tmp_path, "paper")
    assert parts["fine steps"]["steps_per_sample"] == 2000
    assert parts["settle steps"]["steps_per_sample"] == 0 and parts["collapse steps"]["steps_per_sample"] == 0


def test_catalogue_benchmark_writes_every_preset_against_paper(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "catalogue.py"), "--scenes", "2", "--samples", "1",
         "--workers", "1", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "catalogue.json").read_text())
    rows = {row["preset"]: row for row in data["rows"]}
    assert [row["preset"] for row in data["rows"]] == ["paper", "accurate", "fine", "default"]
    assert rows["paper"]["speedup_vs_paper"] == 1.0 and rows["paper"]["per_sample_agreement"] == 1.0
    for row in rows.values():
        assert row["failed_samples"] == 0 and 0 <= row["max_end_penetration_fraction"] < 1
    assert "| default |" in (tmp_path / "catalogue.md").read_text()


def test_zoo_benchmark_compares_every_family_with_paper_and_the_yardstick(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "zoo.py"), "--per-family", "1", "--samples", "2",
         "--families", "launch,bouncy", "--workers", "1", "--out", str(tmp_path)], capture_output=True, text=True,
        timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "zoo.json").read_text())
    assert list(data["families"]) == ["launch", "bouncy"]
    for family, rows in data["families"].items():
        assert list(rows) == ["paper", "paper-half-step", "default", "default-unchecked"]
        paper = rows["paper"]
        assert paper["speedup_vs_paper"] == 1.0 and paper["mean_abs_dp_object"] == 0.0
        assert paper["fidelity"] == {"reference": 1} and rows["default-unchecked"]["fidelity"] == {"unverified": 1}
        assert set(data["verdicts"][family]) == {"mean_ok", "worst_ok", "penetration_ok", "energy_ok"}
    text = (tmp_path / "zoo.md").read_text()
    assert "| launch | default |" in text and "Overall speed-up" in text


def test_soak_benchmark_runs_the_node_under_mixed_input_and_reports(tmp_path):
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    result = subprocess.run([sys.executable, "benchmarks/soak.py", "--minutes", "0.4", "--settle-s", "5",
                             "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=300, cwd=REPO)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    report = json.loads((tmp_path / "soak.json").read_text())
    assert report["node_alive_until_the_end"] and report["processes_left"] == [] and report["exit_code"] == 0
    assert report["answers"]["ok"] >= 1 and report["sigint_exit_s"] < 2.0
    assert int(report["diagnostics_at_end"]["scenes_rejected"]) >= 1 or report["sent"]["bad"] == 0
    questions = report["questions"]  # every question exactly one reply, floods and hostile ones included
    assert (questions["without_reply"], questions["replied_twice"]) == (0, 0)
    assert questions["unreadable"]["sent"] == questions["unreadable"]["replies"]


def test_vision_benchmark_writes_renders_and_mh_steps_per_second(tmp_path):
    result = subprocess.run([sys.executable, str(REPO / "benchmarks" / "vision.py"), "--towers", "1", "--steps", "20",
                             "--resolutions", "48", "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    [row] = json.loads((tmp_path / "vision.json").read_text())["rows"]
    assert row["resolution_px"] == 48 and row["renders_per_s"] > 0 and row["pybullet_renders_per_s"] > 0
    assert 0.5 < row["silhouette_iou_mean"] <= 1.0 and row["mh_steps_per_s"] > 0
    assert "| 48 |" in (tmp_path / "vision.md").read_text()


def test_full_size_runner_times_a_resumable_run_on_a_local_cluster(tmp_path):
    # the runner of the paper's full-size analyses, at --quick size: a second run reads every sample back
    command = [sys.executable, str(REPO / "benchmarks" / "full_size.py"), "bump", "--workers", "1",
               "--resume", str(tmp_path / "runs"), "--out", str(tmp_path / "out"), "--", "--quick"]
    for _ in range(2):
        result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300, env=ENV)
        assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads((tmp_path / "out" / "bump_full_size.json").read_text())
    first, second = summary["runs"]
    assert first["finished"] and second["finished"]
    assert first["samples_computed"] > 0 and first["samples_read_back"] == 0
    assert second["samples_computed"] == 0 and second["samples_read_back"] == first["samples_computed"]
    assert "<LocalCluster on 127.0.0.1>" in first["command"] and "--quick" in first["command"]
    assert (tmp_path / "out" / "bump.md").exists()


def test_depth_benchmark_reports_coverage_and_the_towers_cost(tmp_path):
    result = subprocess.run([sys.executable, str(REPO / "benchmarks" / "depth.py"), "--scenes", "2", "--tower-k", "4",
                             "--tower-repeats", "1", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "depth.json").read_text())
    assert report["calibration"]["scenes"] == 2 and 0 <= report["calibration"]["coverage"] <= 1
    assert report["tower"]["objects"] == 10 and report["tower"]["k"] == 4 and report["tower"]["total_s"] > 0
    assert report["tower"]["total_unchecked_s"] > report["tower"]["chain_s"] > 0
    assert "goal 90-98%" in (tmp_path / "depth.md").read_text()


def test_independent_depth_benchmark_reports_coverage_for_objects_in_view_and_hidden(tmp_path):
    result = subprocess.run([sys.executable, str(REPO / "benchmarks" / "depth_independent.py"), "--scenes", "2",
                             "--set", "kept_states=16", "--without", "bias", "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "depth_independent.json").read_text())
    assert report["summary"]["scenes"] == 2 and 0 <= report["summary"]["all"]["coverage"] <= 1
    assert all(0 <= o["visible"] <= 1 and len(o["covered"]) == 4 for o in report["objects"])
    assert "--set kept_states=16 --without bias" in (tmp_path / "depth_independent.md").read_text()


def test_queries_benchmark_compares_the_contact_watch_and_its_early_end(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "queries.py"), "--per-family", "1", "--samples", "2",
         "--out", str(tmp_path)], capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = json.loads((tmp_path / "queries.json").read_text())
    assert [r["family"] for r in rows] == ["launch", "dominoes", "ramp", "drop"]
    # the contact question asked alone answers as the run to rest does (it only ends sooner)
    assert all(r["same_contact_answer"] == "1/1" for r in rows)
    assert all(0 < r["simulated_alone_vs_rest"] <= 1 for r in rows)
    assert "| dominoes |" in (tmp_path / "queries.md").read_text()


def test_check_policy_replays_every_policy_on_the_same_samples(tmp_path):
    def replay(out):
        result = subprocess.run(
            [sys.executable, str(REPO / "benchmarks" / "check_policy.py"), "--towers", "1", "--zoo", "0", "--samples",
             "2", "--cache", str(tmp_path / "samples.pkl"), "--out", str(out)], capture_output=True, text=True,
            timeout=600, env=ENV)
        assert result.returncode == 0, result.stderr[-3000:]
        return json.loads((out / "check_policy.json").read_text())

    rows = replay(tmp_path / "first")
    # the second run reads the samples the first simulated: the same verdicts and counts
    assert [{k: v for k, v in r.items() if k != "speedup_vs_reference"} for r in replay(tmp_path / "again")] == \
        [{k: v for k, v in r.items() if k != "speedup_vs_reference"} for r in rows]
    by_policy = {r["policy"]: r for r in rows}
    assert set(by_policy) >= {"current", "no confirmation", "unchecked"}
    assert by_policy["unchecked"]["reference_samples_per_prediction"] == 0
    assert by_policy["current"]["reference_samples_per_prediction"] >= 1  # the verified sample at least
    # replayed on draws of the same samples: each draw a prediction of its own
    drawn = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "check_policy.py"), "--towers", "1", "--zoo", "0", "--samples", "2",
         "--cache", str(tmp_path / "samples.pkl"), "--draws", "3", "--draw-samples", "1", "--out", str(tmp_path / "d")],
        capture_output=True, text=True, timeout=600, env=ENV)
    assert drawn.returncode == 0, drawn.stderr[-3000:]
    rows = json.loads((tmp_path / "d" / "check_policy.json").read_text())
    assert {r["scenes"] for r in rows} == {3} and all(r["missed"] <= r["needed"] for r in rows)
    # every escalation gives its reasons (each that held, so at least as many as escalations)
    assert all(sum(t["escalated"] for t in r["escalated_because"].values()) >= r["escalated"] for r in rows)
    # a policy's name may hold a comma of its own; an unknown one is refused by name
    picked = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "check_policy.py"), "--towers", "1", "--zoo", "0", "--samples", "2",
         "--cache", str(tmp_path / "samples.pkl"), "--policies", "current,net, verify (before)", "--out",
         str(tmp_path / "p")], capture_output=True, text=True, timeout=600, env=ENV)
    assert picked.returncode == 0, picked.stderr[-3000:]
    assert [r["policy"] for r in json.loads((tmp_path / "p" / "check_policy.json").read_text())] == \
        ["current", "net, verify (before)"]
    unknown = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "check_policy.py"), "--policies", "current,lenient"],
        capture_output=True, text=True, timeout=600, env=ENV)
    assert unknown.returncode == 2 and "unknown policy 'lenient'; choose from 'current'" in unknown.stderr
    ghost = subprocess.run([sys.executable, str(REPO / "benchmarks" / "check_policy.py"), "--families", "plates,ghost"],
                           capture_output=True, text=True, timeout=600, env=ENV)
    assert ghost.returncode == 2 and "unknown family 'ghost'; choose from launch" in ghost.stderr


def test_collapse_trial_benchmark_compares_each_rule_on_columns_the_zoo_and_towers(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "collapse_trial.py"), "--samples", "2", "--per-family", "1",
         "--towers", "2", "--columns", "10:8", "--families", "drop", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "collapse_trial.json").read_text())
    (column,) = report["columns"]
    assert column["scene"] == "column_10_without_c8" and column["both"] == 0.0  # the column stands, as in paper
    assert [r["family"] for r in report["zoo"]] == ["drop"] and report["zoo"][0]["both"]["speedup"] > 0
    assert report["towers"].get("towers", 2) == 2
    assert "| column_10_without_c8 |" in (tmp_path / "collapse_trial.md").read_text()


def test_actions_benchmark_compares_sequential_fixed_k_and_checked_answers(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "actions.py"), "--repeats", "1", "--heights", "5", "--shelves", "1",
         "--robot-sigma", "0", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "actions.json").read_text())
    questions = [row["question"] for row in data["questions"]]
    assert len(questions) == 4 and questions[0].startswith("support graph") and "column of 5" in questions[-1]
    for row in data["questions"]:
        # every decision the fixed-k interval made, the sequential run made the same
        assert row["same_decision"] == row["fixed_decided"], row
        # the check's floor: one reference rollout at least per variant compared, priced dearer than a fast one
        assert row["reference_rollouts"] >= row["compared_variants"] and row["floor_s"] >= row["sequential_s"], row
        if row["compared_variants"]:
            assert row["reference_over_fast_per_rollout"] > 1 and row["floor_s"] > row["sequential_s"], row
    assert any(row["compared_variants"] for row in data["questions"])
    assert [r["towers"] for r in data["unrelated_towers"]] == [1]
    text = (tmp_path / "actions.md").read_text()
    assert "| question | stands |" in text and "| question | fast rollouts |" in text


def test_check_cost_sorts_the_checked_predictions_map_calls_into_its_parts(tmp_path):
    result = subprocess.run([sys.executable, "benchmarks/check_cost.py", "--towers", "1", "--samples", "4",
                             "--out", str(tmp_path)], cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "check_cost.json").read_text())
    (tower,) = report["towers"]
    # k = 4: no look-ahead split; the first map holds the 4 fast samples and the verified one
    assert tower["maps"][0][:2] == [5, 1]
    assert tower["reference_reruns"] == sum(references for _, references, _ in tower["maps"]) >= 1
    assert math.isclose(sum(tower["parts_s"].values()), sum(wall for _, _, wall in tower["maps"]))
    assert report["summary"]["verdicts"] == {tower["verdict"]: 1}
    assert "| fast + verification |" in (tmp_path / "check_cost.md").read_text()


def test_check_cost_on_the_zoo_gives_its_parts_per_family(tmp_path):
    result = subprocess.run([sys.executable, "benchmarks/check_cost.py", "--zoo", "1", "--families", "drop,bouncy",
                             "--samples", "4", "--out", str(tmp_path)], cwd=REPO, env=ENV, capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads((tmp_path / "check_cost.json").read_text())
    assert [row["family"] for row in report["towers"]] == ["drop", "bouncy"]
    assert set(report["summary"]["per_family"]) == {"drop", "bouncy"}
    text = (tmp_path / "check_cost.md").read_text()
    assert "--zoo 1 --families drop,bouncy --samples 4" in text and "| drop |" in text and "| bouncy |" in text


def test_thin_plates_export_gives_a_third_engine_every_samples_start_and_pybullets_answers(tmp_path):
    out = tmp_path / "plates.json"
    result = subprocess.run([sys.executable, "benchmarks/thin_plates/export.py", str(out), "0", "--samples", "2"],
                            cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    (row,) = json.loads(out.read_text())
    assert row["scene"] == "zoo_plates_2026_000" and len(row["samples"]) == 2
    assert set(row["pybullet_fallen"]) == {"paper", "paper, plain rigid bodies", "default", "default, multibodies"}
    for fallen in row["pybullet_fallen"].values():
        assert [len(f) for f in fallen] == [len(row["names"])] * 2
    body = row["samples"][0]["bodies"][0]
    assert body["name"] == row["names"][0] and body["mass"] > 0 and len(body["quat_xyzw"]) == 4
    # the start state is the sample's noisy, separated scene, not the scene as written
    from ipe_ros.engine.scene.zoo import scene_zoo

    written = scene_zoo(2026, 6, ("plates",))[0].dynamic_objects[0].position_m
    assert max(abs(a - b) for a, b in zip(body["com"], written)) > 1e-4


def test_reference_tier_benchmark_compares_each_tier_with_the_reference_and_the_bar(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "reference_tier.py"), "--towers", "1", "--per-family", "0",
         "--samples", "2", "--out", str(tmp_path)], capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    [row] = json.loads((tmp_path / "reference_tier.json").read_text())["rows"]
    assert row["paper+rest"] == {"agreement": 1.0, "mean_dp": 0.0, "max_dp": 0.0, "failed": 0}
    assert {"paper-half", "accurate+rest", "paper-30it+rest", "fine"} <= set(row["seconds_per_sample"])
    assert "| towers | 1 |" in (tmp_path / "reference_tier.md").read_text()


def test_friction_routes_measures_every_route_and_the_one_corner_prediction(tmp_path):
    result = subprocess.run([sys.executable, "benchmarks/friction_routes.py", "--out", str(tmp_path)],
                            cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    answer = json.loads((tmp_path / "friction_routes.json").read_text())
    assert [(r["route"], r["step"]) for r in answer["rows"]] == [
        (route, step) for route in ("as built", "cone off", "anchors", "plain floor", "box floor")
        for step in ("paper", "default")]
    # unturned, the route the engine builds stays within the 2% of Coulomb's distance
    assert all(abs(r["slide"]["0"]["travel_ratio"] - 1) <= 0.02 for r in answer["rows"] if r["route"] == "as built")
    # the prediction is mechanics of the box alone: 1 unturned, the same for 30 and 120 deg (a quarter turn apart)
    prediction = answer["one_corner_prediction"]
    assert prediction["0"] == pytest.approx(1.0) and prediction["30"] == pytest.approx(prediction["120"])
    assert "| as built | paper |" in (tmp_path / "friction_routes.md").read_text()


def test_impacts_compares_the_direct_solver_for_impacts_only_with_it_for_whole_rollouts(tmp_path):
    result = subprocess.run([sys.executable, "benchmarks/impacts.py", "--per-family", "1", "--samples", "2",
                             "--presets", "default", "--families", "bouncy,drop", "--out", str(tmp_path)],
                            cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rows = json.loads((tmp_path / "impacts.json").read_text())["rows"]
    assert rows and {r["family"] for r in rows} <= {"bouncy", "drop"}
    for row in rows:
        assert 0.0 < row["direct_share"] < 1.0  # impacts on the direct solver, the rest not
        assert 0.0 <= row["mean_abs_dP"] <= row["max_abs_dP"] <= 1.0


def test_the_witness_export_writes_every_shape_and_start_the_other_engine_needs(tmp_path):
    out = tmp_path / "witness.json"
    result = subprocess.run([sys.executable, "benchmarks/witness/export.py", str(out), "--per-family", "1",
                             "--samples", "2", "--families", "rings,drop", "--preset", "default"],
                            cwd=REPO, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    rows = json.loads(out.read_text())["rows"]
    mechanics = [r for r in rows if r["kind"] == "mechanics"]
    assert len(mechanics) >= 10 and all(r["closed_form"] for r in mechanics)
    rings = next(r for r in rows if r["kind"] == "rings")
    parts = [part["type"] for body in rings["scene"]["dynamic"] + rings["scene"]["static"] for part in body["parts"]]
    assert len(parts) > 2 and set(parts) <= {"box", "sphere", "cylinder", "capsule", "hull"}  # a compound's parts
    for row in rows:
        assert row["samples"] and len(row["samples"][0]["initial_m"]) == len(row["scene"]["dynamic"])
        assert all(b["mass_kg"] > 0 and min(b["inertia_kg_m2"]) > 0 for b in row["scene"]["dynamic"])


def test_the_witness_compares_runs_of_the_same_starts_sample_for_sample(tmp_path):
    # two pybullet runs (the second with its solver changed) and a MuJoCo result, side by side
    first, second = tmp_path / "paper.json", tmp_path / "paper200.json"
    for out, extra in ((first, []), (second, ["--solver-iterations", "200", "--warm-start", "0.5"])):
        result = subprocess.run([sys.executable, "benchmarks/witness/export.py", str(out), "--per-family", "1",
                                 "--samples", "2", "--families", "drop", "--no-mechanics", *extra],
                                cwd=REPO, capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
    rows = json.loads(second.read_text())["rows"]
    assert rows[0]["preset"] == "paper-iterations=200-warm_start_factor=0.5"
    label = rows[0]["label"]
    mujoco = tmp_path / "mujoco.json"
    mujoco.write_text(json.dumps({"p_fall": {label: {"mujoco": [1.0] * len(rows[0]["scene"]["dynamic"])}}}))
    md = tmp_path / "compare.md"
    result = subprocess.run([sys.executable, "benchmarks/witness/compare.py", "--pybullet", f"a={first}",
                             "--pybullet", f"b={second}", "--mujoco", f"m={mujoco}", "--md", str(md)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    table = md.read_text()
    assert f"| {label} |" in table and "| a | b | m |" in table and "Mean |dP(falls)|" in table
    result = subprocess.run([sys.executable, "benchmarks/witness/compare.py", "--pybullet", str(first)],
                            cwd=REPO, capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "NAME=FILE" in result.stderr


def test_inference_benchmark_scores_each_case_and_writes_its_json(tmp_path):
    result = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "inference.py"), "--cases", "2", "--workers", "0", "--families",
         "slide", "--out", str(tmp_path), "--every", "3", "--window", "0.6", "--also", "box.mass_kg=0.1,2"],
        capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "inference.json").read_text())
    rows = data["results"]["slide"]["rows"]
    assert [r["seed"] for r in rows] == [0, 1] and all(set(r["covered"]) == {"box.friction"} for r in rows)
    assert data["results"]["slide"]["summary"]["cases"] == 2 and data["settings"]["grid"] is None
    # 30 Hz thinned to 10 Hz over 0.6 s: 6 frames; the mass added as a second (unscored) unknown
    assert all((r["frames"], r["unknowns"]) == (6, 2) for r in rows)


def test_observations_for_another_engine_carry_the_truth_and_read_back_into_the_inference_benchmark(tmp_path):
    """benchmarks/witness/observations.py writes what MuJoCo needs to make the frames; inference.py
    --observed infers such files (here frames pybullet made, put where MuJoCo's would go)."""
    from ipe_ros.engine.inference.known import CASES

    cases = tmp_path / "cases.json"
    result = subprocess.run([sys.executable, "benchmarks/witness/observations.py", str(cases), "--cases", "1",
                             "--families", "slide,head-on"], capture_output=True, text=True, timeout=300, env=ENV,
                            cwd=REPO)
    assert result.returncode == 0, result.stderr[-3000:]
    rows = json.loads(cases.read_text())["rows"]
    assert [(r["family"], r["seed"]) for r in rows] == [("slide", 0), ("head-on", 0)]
    slide = rows[0]
    assert slide["truth"] == CASES["slide"](0).truth and slide["scene"]["dynamic"][0]["name"] == "box"
    assert all(f["objects"] == {} for f in slide["observation"]["frames"])  # the other engine fills them
    assert slide["scene"]["horizon_s"] == slide["observation"]["frames"][-1]["t_s"]
    observed = tmp_path / "observed"
    observed.mkdir()
    case = CASES["slide"](0)
    (observed / "slide_0.json").write_text(json.dumps({**case.observation, "truth": case.truth, "heavier": [],
                                                       "scored": list(case.scored)}))
    result = subprocess.run([sys.executable, str(REPO / "benchmarks" / "inference.py"), "--cases", "5", "--workers",
                             "0", "--families", "slide", "--observed", str(observed), "--out", str(tmp_path)],
                            capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    (row,) = json.loads((tmp_path / "inference.json").read_text())["results"]["slide"]["rows"]
    assert row["seed"] == 0 and row["covered"] == {"box.friction": True}


def test_mesh_acceptance_reports_each_file_accepted_or_refused_with_its_line(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    from tests.test_meshes import _uv_seamed_cube_obj, mug_mesh

    models = tmp_path / "models"
    models.mkdir()
    (models / "seamed_cube.obj").write_text(_uv_seamed_cube_obj())
    mug_mesh(closed=False).export(models / "open_mug.obj")
    assert isinstance(trimesh.load(models / "open_mug.obj"), trimesh.Trimesh)
    result = subprocess.run([sys.executable, str(REPO / "benchmarks" / "mesh_acceptance.py"), str(models), "--out",
                             str(tmp_path / "out")], capture_output=True, text=True, timeout=600, env=ENV)
    assert result.returncode == 0, result.stderr[-3000:]
    data = json.loads((tmp_path / "out" / "mesh_acceptance.json").read_text())
    rows = {r["file"]: r for r in data["rows"]}
    assert rows["seamed_cube.obj"]["accepted"] and rows["seamed_cube.obj"]["fell"] is False
    assert rows["seamed_cube.obj"]["volume_m3"] == pytest.approx(0.05 ** 3, rel=1e-6)
    assert rows["seamed_cube.obj"]["repaired"] is None
    # open (no base, no floor): repaired, saying how (issue 73's ladder), and standing
    assert rows["open_mug.obj"]["accepted"] and rows["open_mug.obj"]["fell"] is False
    assert rows["open_mug.obj"]["repaired"].startswith("open: remeshed watertight from 24 voxels across")
    assert data["summary"]["files"] == 2 and data["summary"]["accepted"] == 2


def test_robot_time_runs_its_steps_one_after_another_and_sets_each_figure_beside_its_target(tmp_path):
    command = [sys.executable, str(REPO / "benchmarks" / "robot_time.py"), "--steps", "zoo_2026", "--per-family", "1",
               "--families", "launch", "--busy", "--out", str(tmp_path)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600, env=ENV, cwd=REPO)
    assert result.returncode == 0, result.stderr[-3000:]
    report = (tmp_path / "busy" / "robot_time.md").read_text()
    assert "beside a process spinning on one core" in report
    assert "| zoo, seed 2026: `default` checked / unchecked vs `paper` | " in report and "| >= 5x checked, every bar met |" in report
    assert json.loads((tmp_path / "busy" / "zoo_2026" / "zoo.json").read_text())["families"].keys() == {"launch"}
    wrong = subprocess.run(command[:2] + ["--steps", "zoo", "--out", str(tmp_path)], capture_output=True, text=True,
                           timeout=60, env=ENV, cwd=REPO)
    assert wrong.returncode != 0 and wrong.stderr.strip().endswith(
        "--steps: unknown 'zoo'; choose from zoo_2026, zoo_2027, towers, questions, depth")
