"""Properties from observed motion (engine/inference): the observation's refusals, analytic answers on
observations the engine makes at `paper` with a tracker's noise, an inconsistent observation, the
answer independent of workers, and `ipe infer` on the command line. Coverage over many cases is
tests/test_inference_coverage.py (slow) and benchmarks/inference.py."""

from __future__ import annotations

import copy
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from ipe_ros.engine.errors import ConfigError, SceneError
from ipe_ros.engine.inference.infer import InferSettings, infer
from ipe_ros.engine.inference.known import CASES, probe_push
from ipe_ros.engine.inference.observation import MAX_FRAMES, observation_from_dict, observation_from_json
from ipe_ros.engine.scene.properties import LogNormal, LogUniform, Normal, Uniform

G = 9.81


@pytest.fixture(scope="module")
def probe():
    return probe_push(np.random.default_rng(3))


def refusal(data) -> str:
    with pytest.raises((ConfigError, SceneError)) as caught:
        observation_from_dict(data)
    return str(caught.value)


def edited(base: dict, edit) -> dict:
    data = copy.deepcopy(base)
    edit(data)
    return data


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["frames"].__setitem__(slice(0, 2), d["frames"][1::-1]),
     "frames[1].t_s: frames must be in time order after t = 0: 0.033333 s follows 0.066667 s"),
    (lambda d: d["frames"][0].__setitem__("t_s", -0.1), "frames[0].t_s: must be a number in (0, 10], got -0.1"),
    (lambda d: d["frames"][0].__setitem__("t_s", float("nan")), "frames[0].t_s: must be a number in (0, 10], got nan"),
    (lambda d: d["frames"][-1].__setitem__("t_s", 11.0), "frames[29].t_s: must be a number in (0, 10], got 11.0"),
    (lambda d: d["frames"][2]["objects"].__setitem__("ghost", {"position_m": [0, 0, 0]}),
     "frames[2].objects.ghost: no dynamic object 'ghost' in the scene"),
    (lambda d: d["unknowns"][0].__setitem__("object", "ghost"),
     "unknowns[0].object: no dynamic object 'ghost' in the scene (or \"support\")"),
    (lambda d: d["unknowns"].append({"group": "blue", "property": "mass_kg", "prior": {"log_sd": 0.5}}),
     "unknowns[2].group: no dynamic object has group 'blue'"),
    (lambda d: d["unknowns"][0].__setitem__("property", "colour"),
     "unknowns[0].property: unknown property 'colour'; choose from mass_kg, friction, restitution"),
    (lambda d: d["unknowns"][1].__setitem__("prior", {"uniform": [-0.5, 0.9]}),
     "unknowns[1].prior.uniform: must satisfy 0 <= LOW < HIGH <= 10 for friction (physical bounds), got [-0.5, 0.9]"),
    (lambda d: d["unknowns"][0].__setitem__("prior", {"log_uniform": [0.0, 5.0]}),
     "unknowns[0].prior.log_uniform: must satisfy 1e-06 <= LOW < HIGH <= 1e+06 for mass_kg (physical bounds), "
     "got [0.0, 5.0]"),
    (lambda d: d["unknowns"].append(dict(d["unknowns"][0])),
     "unknowns[2]: box's mass_kg is already unknown in unknowns[0]"),
    (lambda d: d["unknowns"].append({"object": "support", "property": "mass_kg", "prior": {"log_sd": 1}}),
     "unknowns[2].property: the support has no mass; its friction or restitution may be unknown"),
    (lambda d: d["actions"][0].__setitem__("at_s", 1.5), "actions[0].at_s: must be a number in [0, 1], got 1.5"),
    (lambda d: d.__setitem__("position_sd_m", 0), "position_sd_m: must be a number in (0, 1], got 0"),
    (lambda d: d.__setitem__("format", "ipe_ros.observation/9"),
     "format: must be 'ipe_ros.observation/1', got 'ipe_ros.observation/9'"),
    (lambda d: d["scene"]["objects"][0].__setitem__("mass_kg", -1), "scene.objects[0] ('box').mass_kg: mass in kg must be > 0, got -1.0"),
])
def test_each_bad_observation_is_refused_in_one_line_naming_the_field(probe, edit, message):
    text = refusal(edited(probe, edit))
    assert text.startswith(message) and "\n" not in text


def test_a_million_frames_and_an_oversized_file_are_refused_before_any_work(probe):
    many = edited(probe, lambda d: d.__setitem__("frames", [d["frames"][0]] * 10**6))
    assert refusal(many) == f"frames: 1000000 frames exceed the maximum of {MAX_FRAMES}; send every n-th frame"
    with pytest.raises(ConfigError, match=r"^observation: 16000001 characters exceed the maximum of 16000000; "):
        observation_from_json(" " * 16_000_001)
    with pytest.raises(ConfigError, match=r"^observation: NaN is not a valid number"):
        observation_from_json('{"position_sd_m": NaN}')


def test_an_object_left_without_initial_velocity_needs_frames_to_estimate_it(probe):
    def drop_velocity(d):
        del d["scene"]["objects"][0]["linear_velocity_m_s"]
        d["frames"] = d["frames"][:1]
    assert refusal(edited(probe, drop_velocity)) == (
        "scene.objects: 'box' has no initial velocity and fewer than 2 frames see it; give its linear_velocity_m_s "
        "(0 for at rest) or frames of it")
    observation = observation_from_dict(edited(probe, lambda d: d["scene"]["objects"][0].pop("linear_velocity_m_s")))
    assert observation.unknown_velocity == ("box",)


@pytest.mark.parametrize("prior", [Uniform(0.1, 0.9), LogUniform(0.05, 5.0), LogNormal(0.5, 0.7), Normal(1.0, 0.3)])
def test_each_prior_maps_its_support_onto_the_line_and_back(prior):
    z = np.linspace(-6, 6, 13)
    assert np.allclose(prior.coordinate(prior.value(z)), z)
    # the prior's density in its coordinate is a density: it integrates to 1
    grid = np.linspace(-40, 40, 40001)
    assert np.exp(prior.log_density_z(grid)).sum() * (grid[1] - grid[0]) == pytest.approx(1.0, abs=1e-6)
    # draws from uniforms are distributed as the prior says (median at z = 0)
    assert prior.z_from_uniform(0.5) == pytest.approx(0.0)


def test_a_pushed_box_gives_its_mass_and_friction_within_the_intervals(probe):
    answer = infer(observation_from_dict(probe), InferSettings(seed=1))
    assert answer.consistent and answer.stopped_by in ("ess", "rounds")
    mass, friction = answer.estimate("box.mass_kg"), answer.estimate("box.friction")
    assert mass.low_90 <= 0.8 <= mass.high_90 and friction.low_90 <= 0.45 <= friction.high_90
    # 1.2 N s on 0.8 kg is 1.5 m/s; the box stops after v^2 / (2 mu g) = 0.255 m: both within 10%
    assert mass.median == pytest.approx(0.8, rel=0.1) and friction.median == pytest.approx(0.45, rel=0.1)
    assert answer.worst_residual_m < 0.02 and answer.failed == 0
    refined = {b.name: b for b in answer.refined_scene.objects}["box"]
    assert refined.mass_kg == mass.median and refined.friction == friction.median
    # what is still uncertain rides along as the object's priors: log-normal, the 90% interval's width
    priors = dict(refined.priors)
    assert priors["friction"].median == friction.median
    assert priors["friction"].value(1.6449) == pytest.approx(friction.high_90, rel=0.05 * (
        friction.high_90 / friction.low_90))  # a log-normal's 95th percentile, where the interval's ends are skewed
    assert set(priors) == {"mass_kg", "friction"}


def test_a_push_during_the_window_gives_the_mass_and_friction_too():
    """The robot pushes at 0.4 s, while it watches: the box rests, then slides 1.2 N s / m far as a
    push at t = 0 would make it; the push is simulated at its time (a timed push of the scene)."""
    observation = observation_from_dict(probe_push(np.random.default_rng(3), at_s=0.4))
    assert observation.actions[0].at_s == 0.4 and observation.window_s == pytest.approx(1.4)
    answer = infer(observation, InferSettings(seed=1))
    assert answer.consistent
    mass, friction = answer.estimate("box.mass_kg"), answer.estimate("box.friction")
    assert mass.low_90 <= 0.8 <= mass.high_90 and friction.low_90 <= 0.45 <= friction.high_90
    assert mass.median == pytest.approx(0.8, rel=0.1) and friction.median == pytest.approx(0.45, rel=0.1)


@pytest.mark.parametrize("family, seed", [("slide", 0), ("bounce", 1)])
def test_a_slide_and_a_bounce_recover_the_closed_form_property(family, seed):
    case = CASES[family](seed)
    answer = infer(observation_from_dict(case.observation), InferSettings(seed=seed))
    (label,) = case.scored
    estimate = answer.estimate(label)
    assert estimate.low_90 <= case.truth[label] <= estimate.high_90
    assert estimate.median == pytest.approx(case.truth[label], rel=0.1)


@pytest.mark.slow
def test_a_head_on_collision_says_which_box_is_heavier_and_by_how_much(pool):
    case = CASES["head-on"](1)  # b is 2.75x a
    answer = infer(observation_from_dict(case.observation), InferSettings(seed=1), pool.map)
    (pair,) = answer.heavier
    p_first = pair.p_a_heavier if pair.a == case.heavier[0] else 1 - pair.p_a_heavier
    assert p_first > 0.95
    ratio = pair.ratio_median if pair.a == case.heavier[0] else 1 / pair.ratio_median
    assert ratio == pytest.approx(case.true_ratio, rel=0.15)


def test_an_object_that_jumps_is_answered_as_inconsistent_not_with_a_posterior(probe):
    def jump(d):
        d["frames"][20]["objects"]["box"]["position_m"][1] += 0.5
    answer = infer(observation_from_dict(edited(probe, jump)), InferSettings(seed=0))
    assert not answer.consistent and answer.estimates == () and answer.refined_scene is None
    assert answer.message.startswith("no property values reproduce the observation: worst residual 49")
    assert answer.message.endswith(f"mm at t = {probe['frames'][20]['t_s']:g} s on box")


@pytest.mark.slow
def test_the_answer_does_not_depend_on_the_worker_count(pool):
    case = CASES["head-on"](2)
    observation = observation_from_dict(case.observation)
    settings = InferSettings(seed=4, sampler=InferSettings().sampler.__class__(particles_per_round=8, max_rounds=3))
    here, there = infer(observation, settings), infer(observation, settings, pool.map)
    assert here.estimates == there.estimates and here.heavier == there.heavier


def test_ipe_infer_answers_the_generated_probe_push_in_json(tmp_path):
    path = tmp_path / "obs.json"
    made = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "generate", "probe-push", "--seed", "2", "-o",
                           str(path)], capture_output=True, text=True, timeout=120)
    assert made.returncode == 0, made.stderr
    out = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "infer", str(path), "--workers", "0", "--json",
                          "--unknown", "box.friction", "--refined", str(tmp_path / "refined.json")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    answer = json.loads(out.stdout)
    assert list(answer["unknowns"]) == ["box.friction"] and answer["consistent"]
    low, high = answer["unknowns"]["box.friction"]["interval_90"]
    assert low <= 0.45 <= high
    refined = json.loads((tmp_path / "refined.json").read_text())
    assert refined["objects"][0]["friction"] == answer["unknowns"]["box.friction"]["median"]
    assert refined["objects"][0]["friction_prior"]["median"] == answer["unknowns"]["box.friction"]["median"]
    # predicting from the refined scene draws the friction still uncertain, and names it
    predicted = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "predict", str(tmp_path / "refined.json"),
                                "--workers", "0", "--samples", "8", "--sigma", "0", "--query", "final_pose",
                                "--json"], capture_output=True, text=True, timeout=300)
    assert predicted.returncode == 0, predicted.stderr
    (influence,) = json.loads(predicted.stdout)["property_influence"]
    assert influence["property"] == "box.friction" and influence["outcome"] == "travel_m"
    bad = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "infer", str(path), "--unknown", "box.colour"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "ipe: error: --unknown: 'box.colour' is not an unknown of obs.json; it has box.mass_kg, box.friction"]


def test_the_observation_schema_is_current_and_holds_the_generated_observations(probe):
    import jsonschema
    from referencing import Registry, Resource

    from ipe_ros.engine.inference.schema import SCHEMA_PATH, observation_schema, schema_text
    from ipe_ros.engine.scene.schema import SCHEMA_ID, scene_schema

    assert SCHEMA_PATH.read_text() == schema_text(), "regenerate it: python -m ipe_ros.engine.inference.schema"
    jsonschema.Draft202012Validator.check_schema(observation_schema())
    registry = Registry().with_resource(SCHEMA_ID, Resource.from_contents(scene_schema()))
    validator = jsonschema.Draft202012Validator(observation_schema(), registry=registry)
    for data in (probe, *(CASES[f](0).observation for f in CASES)):
        validator.validate(data)
    assert not validator.is_valid(edited(probe, lambda d: d["unknowns"][0].__setitem__("property", "colour")))


def test_ipe_infer_records_the_frames_the_rollout_and_the_posterior(probe, tmp_path):
    from rerun.chunk import RrdReader  # as tests/test_rerun_log.py reads recordings

    from ipe_ros.viz.inference_log import write_inference_rrd

    observation = observation_from_dict(probe)
    answer = infer(observation, InferSettings(seed=2, sampler=InferSettings().sampler.__class__(max_rounds=3)))
    path = tmp_path / "infer.rrd"
    write_inference_rrd(path, observation, answer)
    entities = {c.entity_path for c in RrdReader(path).stream().to_chunks()}
    assert {"/world/observed/box", "/world/observed/box/path", "/world/rollout/box", "/world/rollout/box/path",
            "/posterior/box.mass_kg", "/posterior/box.friction"} <= entities
    assert answer.draws.shape == (400, 2)


def test_an_unknown_initial_velocity_is_a_nuisance_estimated_from_the_frames():
    from ipe_ros.engine.inference.known import observe, sliding_box

    rng = np.random.default_rng(11)
    data = observe(sliding_box(1.6, 0.5, 0.7), 1.2, rng, velocity_unknown=("box",), unknowns=[
        {"object": "box", "property": "friction", "prior": {"uniform": [0.05, 1.2]}}])
    observation = observation_from_dict(data)
    assert observation.unknown_velocity == ("box",)
    answer = infer(observation, InferSettings(seed=3))
    friction = answer.estimate("box.friction")
    assert friction.low_90 <= 0.5 <= friction.high_90 and friction.median == pytest.approx(0.5, rel=0.05)


@pytest.mark.parametrize("make, message", [
    (lambda d: (d / "zero.json").symlink_to("/dev/zero") or d / "zero.json",
     r"observation: .*zero\.json is not a regular file \(a folder, a FIFO or a device\)"),
    (lambda d: d, r"observation: .* is not a regular file \(a folder, a FIFO or a device\)"),
    (lambda d: d / "missing.json", r"observation: .*missing\.json: no such file"),
    (lambda d: (d / "latin.json").write_bytes(b'{"scene": "\xe9"}') and d / "latin.json",
     r"observation: .*latin\.json: not UTF-8 text; write the observation as JSON"),
])
def test_an_observation_file_that_is_no_file_to_read_is_refused_in_one_line(tmp_path, make, message):
    """A link to /dev/zero was read until memory ran out; a folder or a missing file ended in an
    OSError's words without the field."""
    path = make(tmp_path)
    bad = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "infer", str(path)], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2, bad.stderr
    (line,) = bad.stderr.strip().splitlines()
    assert re.fullmatch(r"ipe: error: " + message, line), line
