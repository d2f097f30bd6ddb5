"""The `ipe` command line: JSON lines, readable table, generators, one-line errors with exit 2."""

import json
import subprocess
import sys

import pytest

from ipe_ros.cli import main
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine import load_scenes

REQUIRED = {"scene", "samples", "fall_fraction", "fall_fraction_ci95", "object_fall_probability",
            "direction_rad", "direction_decisiveness", "far_m", "failed_samples", "wall_s"}


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "ipe_ros.cli", *args], capture_output=True, text=True, timeout=300)


def test_predict_json_lines_hold_the_documented_fields():
    out = run_cli("predict", str(example_scene_path()), "--samples", "4", "--workers", "2", "--json")
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1
    record = json.loads(lines[0])
    assert REQUIRED <= set(record)
    assert record["scene"] == "example_tower" and record["samples"] == 4
    assert out.stderr == ""


def test_will_anything_fall_query_reports_a_probability_with_its_interval(capsys):
    assert main(["predict", str(example_scene_path()), "--query", "any_fall", "--samples", "6", "--workers", "0",
                 "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    lo, hi = record["any_fall_probability_ci95"]
    assert 0.0 <= lo <= record["any_fall_probability"] <= hi <= 1.0
    assert record["fall_fraction"] is None and record["request"]["queries"] == ["any_fall"]
    assert main(["predict", str(example_scene_path()), "--query", "any_fall", "--samples", "2", "--workers", "0"]) == 0
    assert "P(anything falls):" in capsys.readouterr().out


def test_predict_table_and_ground_truth(capsys):
    assert main(["predict", str(example_scene_path()), "--ground-truth", "--workers", "0"]) == 0
    text = capsys.readouterr().out
    assert "sigma = 0 m" in text and "example_tower" in text and "P(fall)" in text


def _uncertain_tower(tmp_path, sigma_m: float):
    """The example tower with every block's own position noise set, written to a file."""
    from dataclasses import replace

    from ipe_ros.engine.scene.format import write_scenes

    tower = load_scenes(example_scene_path())[0]
    noisy = replace(tower, objects=tuple(replace(b, position_sigma_m=sigma_m) for b in tower.objects))
    path = tmp_path / "uncertain.json"
    write_scenes([noisy], path)
    return path


def test_ground_truth_takes_the_scene_as_given_even_where_bodies_give_their_own_noise(tmp_path, capsys):
    """--ground-truth is sigma = phi = 0 and no noise at all: a tower whose blocks each carry their
    own position noise gets the answer of the same tower without it, from one rollout."""
    def ground_truth(path) -> dict:
        assert main(["predict", str(path), "--ground-truth", "--workers", "0", "--json", "--no-self-check"]) == 0
        return json.loads(capsys.readouterr().out)

    exact = ground_truth(example_scene_path())
    noisy = ground_truth(_uncertain_tower(tmp_path, 0.05))
    assert noisy["deterministic"] and noisy["samples"] == 1
    assert noisy["object_fall_probability"] == exact["object_fall_probability"]
    assert noisy["request"]["object_noise"] is False  # the answer says it drew no body's own noise


def test_sigma_zero_with_bodies_own_noise_is_not_deterministic(tmp_path, capsys):
    """sigma = 0 without --ground-truth keeps each block's own noise: k samples, not one rollout
    that claims to be deterministic."""
    path = _uncertain_tower(tmp_path, 0.05)
    assert main(["predict", str(path), "--sigma", "0", "--samples", "3", "--workers", "0", "--json",
                 "--no-self-check"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert not record["deterministic"] and record["samples"] == 3
    assert "object_noise" not in record["request"]  # drawn, as by default


def test_generate_tower_and_table_write_loadable_scenes(tmp_path):
    towers, tables = tmp_path / "towers.json", tmp_path / "tables.json"
    assert main(["generate", "tower", "--count", "2", "--pairs", "10", "--seed", "5", "-o", str(towers)]) == 0
    assert main(["generate", "table", "--configurations", "2", "--seed", "5", "-o", str(tables)]) == 0
    assert len(load_scenes(towers)) == 6  # each tower and its two heavy/light masks
    assert len(load_scenes(tables)) == 10  # 2 configurations x 5 tables


@pytest.mark.parametrize("args, message", [
    (["predict", "/nonexistent.json"], "ipe: error: /nonexistent.json: no such file"),
    (["predict", "EXAMPLE", "--query", "fall,fly"], "ipe: error: argument --query: unknown query 'fly'; "
                                                    "choose from fall, any_fall, direction, far, bump, contact, rest, "
                                                    "final_pose, tipped"),
    (["predict", "EXAMPLE", "--samples", "0"], "ipe: error: --samples: must be an integer in [1, 100000], got 0"),
    (["predict", "EXAMPLE", "--sigma", "99"], "ipe: error: --sigma: must be at most 10 m (check the units), got 99.0"),
    (["ask", "remove", "EXAMPLE", "--sigma", "99"], "ipe: error: --sigma: must be at most 10 m (check the units), "
                                                    "got 99.0"),
    (["predict", "EXAMPLE", "--phi", "-1"], "ipe: error: --phi: must be a finite number >= 0, got -1.0"),
    (["predict", "EXAMPLE", "--sigma", "nan"], "ipe: error: argument --sigma: expected a finite number, got 'nan'"),
    (["predict", "EXAMPLE", "--tower", "nope"], "ipe: error: --tower: no scene named 'nope' in example_tower.json"),
    (["predict", "EXAMPLE", "--query", "bump"], "ipe: error: --query: the bump query needs a table support (it "
                                                "counts boxes that fall off the table's edge); drop 'bump' or give "
                                                "the scene a table"),
    (["predict", "EXAMPLE", "--verify-samples", "5000"], "ipe: error: --verify-samples: must be an integer in "
                                                         "[0, 1000], got 5000"),
    (["predict", "EXAMPLE", "--no-self-check", "--verify-samples", "3"],
     "ipe: error: --verify-samples: needs --self-check, which is off; drop one of them"),
    (["ask", "remove", "EXAMPLE", "--verify-samples", "3"],
     "ipe: error: --verify-samples: needs --self-check, which is off; drop one of them"),
    (["predict", "EXAMPLE", "--query", "fall,contact"], "ipe: error: --contact: the contact query needs pairs to "
                                                        "watch: give A:B (B may be support), or drop contact from "
                                                        "the queries"),
])
def test_bad_input_exits_2_with_one_line(args, message):
    args = [str(example_scene_path()) if a == "EXAMPLE" else a for a in args]
    out = run_cli(*args)
    assert out.returncode == 2
    assert out.stderr.strip() == message
    assert out.stdout == ""


def test_bad_json_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"name": "x", "boxes": [], "support": {"type": "floor"}, "gravity_m_s2": [0, 0, -9.8]}))
    out = run_cli("predict", str(bad))
    assert out.returncode == 2
    assert out.stderr.strip() == "ipe: error: support.height_m: required field is missing"


def test_ask_support_clear_place_push_on_the_command_line(tmp_path, capsys):
    from ipe_ros.engine.scene.format import write_scenes
    from tests.test_actions import STACK

    path = tmp_path / "stack.json"
    write_scenes([STACK], path)
    common = ["--samples", "4", "--sigma", "0.005", "--workers", "0"]
    assert main(["ask", "support", str(path), *common, "--json", "--png", str(tmp_path / "graph.png")]) == 0
    graph = json.loads(capsys.readouterr().out)
    assert graph["edges"] == [["bottom", "top", 1.0]] and (tmp_path / "graph.png").stat().st_size > 1000
    assert main(["ask", "clear", str(path), *common]) == 0
    assert "1. remove top" in capsys.readouterr().out
    box = '{"name": "new", "shape": {"type": "box", "extents_m": [0.2, 0.2, 0.2]}, "mass_kg": 1, "friction": 0.6, "restitution": 0}'
    assert main(["ask", "place", str(path), *common, "--object", box, "--at", "0,0", "--json"]) == 0
    placed = json.loads(capsys.readouterr().out)["candidates"][0]
    assert placed["position_m"][2] == pytest.approx(0.5, abs=1e-3) and placed["any_fall_probability"] == 0.0
    assert placed["object_fall_probability"] is None  # the ranking reads "does anything fall?" alone
    assert main(["ask", "place", str(path), *common, "--object", box, "--at", "0,0", "--json", "--what-falls"]) == 0
    placed = json.loads(capsys.readouterr().out)["candidates"][0]
    assert placed["object_fall_probability"] == {"bottom": 0.0, "top": 0.0, "new": 0.0}
    assert main(["ask", "remove", str(path), *common, "--object", "top", "--safe-below", "0.05"]) == 0
    assert "(not asked: --what-falls)" in capsys.readouterr().out
    assert main(["ask", "push", str(path), *common, "--object", "bottom", "--velocity", "2,0"]) == 0
    assert "push/bottom" in capsys.readouterr().out
    assert main(["ask", "remove", str(path), *common, "--object", "nope"]) == 2
    assert capsys.readouterr().err.strip() == "ipe: error: actions[1].names: no object named 'nope' in 'stack'"


def test_ask_takes_the_ground_truth_too(tmp_path, capsys):
    """`ipe ask --ground-truth`: no noise at all, so one rollout per variant and exact answers (a
    point, not an interval), as `ipe predict --ground-truth` gives."""
    from ipe_ros.engine.scene.format import write_scenes
    from tests.test_actions import STACK

    path = tmp_path / "stack.json"
    write_scenes([STACK], path)
    assert main(["ask", "remove", str(path), "--object", "bottom", "--ground-truth", "--samples", "8",
                 "--workers", "0", "--json"]) == 0
    answer = json.loads(capsys.readouterr().out)
    assert answer["samples_requested"] == 1
    removal = next(v for v in answer["variants"] if v["label"] == "remove/bottom")
    assert removal["simulated"] and removal["samples"] == 1 and removal["object_fall_probability"] == {"top": 1.0}
    assert removal["any_fall_probability_ci95"] == [1.0, 1.0]
    # a push with noise of its own is no ground truth: refused, not answered from k noisy samples
    assert main(["ask", "push", str(path), "--object", "top", "--velocity", "1,0", "--speed-sigma", "0.1",
                 "--ground-truth", "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip() == (
        "ipe: error: actions[1]: the ground truth takes a push exactly as given, but this one has noise of its own "
        "(a direction or speed sigma); drop it, or ask without the ground truth")


def test_long_work_shows_plain_progress_lines_off_a_terminal_and_a_bar_on_one(capsys, monkeypatch):
    import io
    import sys

    from ipe_ros.progress import steps

    assert list(steps(range(45), "towers")) == list(range(45))
    assert capsys.readouterr().err.splitlines() == ["  towers: 20/45", "  towers: 40/45", "  towers: 45/45"]

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert list(steps(range(3), "towers")) == [0, 1, 2]
    assert "towers:" in terminal.getvalue() and "/3 [" in terminal.getvalue() and "\r" in terminal.getvalue()  # a bar


@pytest.mark.slow
def test_predict_draws_the_answer_as_a_png(tmp_path):
    out = tmp_path / "tower.png"
    run = run_cli("predict", str(example_scene_path()), "--samples", "4", "--workers", "0", "--png", str(out))
    assert run.returncode == 0, run.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    two = tmp_path / "two.json"
    assert run_cli("generate", "tower", "--count", "2", "--seed", "1", "-o", str(two)).returncode == 0
    several = run_cli("predict", str(two), "--samples", "2", "--png", str(out))
    assert several.returncode == 2
    assert several.stderr.strip() == (f"ipe: error: --png: draws one scene, but {two} holds 2; choose one with --tower")


def test_a_file_with_bad_scenes_answers_every_good_one_and_reports_each_refused_one(tmp_path):
    from ipe_ros.engine.scene.format import scene_to_dict

    good = scene_to_dict(load_scenes(example_scene_path())[0])
    unreadable = dict(good, name="broken", objects=[dict(good["objects"][0], mass_kg=-1.0)])
    copies = [dict(o, name=f"{o['name']}_{c}", position_m=[o["position_m"][0] + 3.0 * c, *o["position_m"][1:]])
              for c in (1, 2) for o in good["objects"]]
    # readable, but far beyond the budget (a third more would run, cut off by it): 3 towers for 60 s
    too_costly = dict(good, name="too_costly", horizon_s=60.0, objects=good["objects"] + copies)
    mixed = tmp_path / "mixed.json"
    mixed.write_text(json.dumps([good, unreadable, dict(good, name="second"), too_costly]))
    out = run_cli("predict", str(mixed), "--samples", "2", "--workers", "0", "--json", "--budget", "1")
    assert out.returncode == 2, out.stderr
    lines = [json.loads(line) for line in out.stdout.strip().splitlines()]
    refusals, answers = lines[:2], lines[2:]  # refusals first: at once, before the predictions run
    assert [(r["index"], r["scene"]) for r in refusals] == [(1, "broken"), (3, "too_costly")]
    assert refusals[0]["error"] == "scenes[1].objects[0] ('block0').mass_kg: mass in kg must be > 0, got -1.0"
    assert refusals[1]["error"].startswith("--budget (too_costly): ")
    assert [a["scene"] for a in answers] == ["example_tower", "second"] and all(a["samples"] == 2 for a in answers)
    table = run_cli("predict", str(mixed), "--samples", "2", "--workers", "0", "--budget", "1")
    assert table.returncode == 2 and "example_tower" in table.stdout and "second" in table.stdout
    assert table.stderr.splitlines()[0] == ("ipe: refused scene 1 (broken): scenes[1].objects[0] ('block0').mass_kg: "
                                            "mass in kg must be > 0, got -1.0")
    mixed.write_text(json.dumps([unreadable, too_costly]))  # nothing left to answer: one line more says so
    none = run_cli("predict", str(mixed), "--samples", "2", "--budget", "1")
    assert none.returncode == 2
    assert none.stderr.splitlines()[-1] == f"ipe: error: {mixed}: none of its 2 scenes can be answered (each refusal is reported)"
    mixed.write_text(json.dumps([unreadable, dict(unreadable, name="broken_too")]))  # none even read (issue 76)
    unread = run_cli("predict", str(mixed), "--samples", "2", "--budget", "1")
    assert unread.returncode == 2
    assert unread.stderr.splitlines() == [
        "ipe: refused scene 0 (broken): scenes[0].objects[0] ('block0').mass_kg: mass in kg must be > 0, got -1.0",
        "ipe: refused scene 1 (broken_too): scenes[1].objects[0] ('block0').mass_kg: mass in kg must be > 0, got -1.0",
        "ipe: error: json: none of the 2 scenes can be read (each refusal is reported)"]


def test_the_parsers_experiment_names_and_scales_are_the_analyses_own():
    from ipe_ros import cli
    from ipe_ros.analysis.experiments import EXPERIMENTS
    from ipe_ros.analysis.human import SCALES

    assert cli.EXPERIMENT_NAMES == tuple(EXPERIMENTS) and cli.HUMAN_SCALES == SCALES


def test_vector_options_take_negative_numbers():
    """A camera at negative x (README's ``--camera-pose "$(cat camera_pose.txt)"``) and a push towards -x."""
    from ipe_ros.cli import build_parser, glue_negative_vectors

    pose = "-0.85,0.1,0.6,0,0,0,1"
    argv = ["predict", "scene.json", "--camera-pose", pose, "--force-direction", "-30"]
    args = build_parser().parse_args(glue_negative_vectors(argv))
    assert args.camera_pose == pose and args.force_direction_deg == -30.0
    args = build_parser().parse_args(glue_negative_vectors(["ask", "push", "scene.json", "--object", "top",
                                                            "--velocity", "-0.4,0"]))
    assert args.velocity == (-0.4, 0.0)
    assert glue_negative_vectors(["--x", "-1,2", "--y=-3,4", "-v", "-5,6"]) == ["--x=-1,2", "--y=-3,4", "-v", "-5,6"]


def test_errors_name_the_file_and_the_option_as_typed(tmp_path, capsys):
    path = str(example_scene_path())
    assert main(["ask", "remove", path, "--safe-below", "2", "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip() == "ipe: error: --safe-below: must be in (0, 1], got 2.0"
    assert main(["ask", "push", path, "--object", "nothere", "--velocity", "1,0", "--workers", "0"]) == 2
    assert capsys.readouterr().err.strip().startswith("ipe: error: --object: no dynamic object named 'nothere'")
    latin = tmp_path / "latin1.json"
    latin.write_bytes('{"name": "caf\xe9"}'.encode("latin-1"))
    assert main(["predict", str(latin)]) == 2
    assert capsys.readouterr().err.strip() == (f"ipe: error: {latin}: not UTF-8 text (byte 0xe9 at offset 13); "
                                               "save the file as UTF-8")
