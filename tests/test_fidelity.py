"""Self-checking answers (ipe_ros.engine.fidelity): refinement, verification, escalation, verdicts.

Each path is forced deterministically: a real scene on which `default` and the reference disagree
(zoo ramp 2026/4, seed 0: the stack at the ramp's foot topples in 7 of 8 `default` samples and in
none of `paper`'s), a real
rollout that ends deep inside another body at the default's settings, and injected maps that fail a
sample or cut the escalation off as a spent budget would.
"""

from __future__ import annotations

import dataclasses

import pytest

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine.config import DEFAULT_QUERIES
from ipe_ros.engine.errors import ConfigError
from ipe_ros.engine.fidelity import VERDICTS, SelfCheck, reference_settings
from ipe_ros.engine.rollout import SampleOutcome, run_sample
from ipe_ros.engine.scene_io import load_scenes
from ipe_ros.engine.examples import example_scene_path
from ipe_ros.engine.zoo import zoo_scene, zoo_sigma_m

QUERY = QuerySpec(queries=DEFAULT_QUERIES)
REFERENCE = reference_settings().name
CHECK_FIELDS = ("fidelity", "refined_samples", "self_check", "wall_s")


def _answer(p) -> dict:
    return {k: v for k, v in p.to_dict().items() if k not in CHECK_FIELDS}


class CountingMap:
    """A map that runs tasks here and remembers every call's tasks; ``tamper(task, outcome)`` may
    replace an outcome (a physics failure, a spent budget)."""

    def __init__(self, tamper=None):
        self.calls: list[list] = []
        self._tamper = tamper

    def __call__(self, fn, items, on_lost=None):
        self.calls.append(list(items))
        out = [fn(t) for t in items]
        return [self._tamper(t, o) for t, o in zip(items, out)] if self._tamper else out


@pytest.fixture(scope="module")
def tower():
    return load_scenes(example_scene_path())[0]


@pytest.fixture(scope="module")
def contradicted_scene():
    """On this ramp `default` topples the stack the reference keeps standing (see the module doc)."""
    return zoo_scene("ramp", 2026, 4)


def _ramp_model(scene, samples=4):
    return ModelConfig(sigma_m=zoo_sigma_m(scene), samples=samples)


def test_the_verification_runs_first_in_the_same_map_as_the_fast_samples(tower):
    spy = CountingMap()
    p = predict(tower, ModelConfig(sigma_m=0.01, samples=3), preset("default"), QUERY, seed=4, map_fn=spy)
    assert len(spy.calls) == 1
    assert [t.settings.name for t in spy.calls[0]] == [REFERENCE, "default", "default", "default"]
    assert [t.index for t in spy.calls[0]] == [0, 0, 1, 2]
    assert p.fidelity == "verified" and p.self_check["verified_samples"] == 1
    assert p.self_check["settings"] == {"samples": "default", "verification": REFERENCE}


def test_a_verified_answer_is_the_fast_answer_unchanged(tower):
    """The check never changes an answer it agrees with (seed 4: no rollout ends unhealthy)."""
    model = ModelConfig(sigma_m=0.01, samples=3)
    checked = predict(tower, model, preset("default"), QUERY, seed=4)
    unchecked = predict(tower, model, preset("default"), QUERY, seed=4, check=None)
    assert (checked.fidelity, unchecked.fidelity, checked.refined_samples) == ("verified", "unverified", 0)
    assert _answer(checked) == _answer(unchecked)


def test_reference_settings_are_not_checked_and_no_check_runs_nothing_more(tower):
    spy = CountingMap()
    model = ModelConfig(sigma_m=0.01, samples=2)
    p = predict(tower, model, preset("paper"), QUERY, seed=1, map_fn=spy)
    assert p.fidelity == "reference" and [len(c) for c in spy.calls] == [2]
    spy = CountingMap()
    p = predict(tower, model, preset("default"), QUERY, seed=1, map_fn=spy, check=SelfCheck(enabled=False))
    assert p.fidelity == "unverified" and [len(c) for c in spy.calls] == [2]


def test_a_contradicted_scene_is_escalated_to_the_reference_answer(contradicted_scene):
    model = _ramp_model(contradicted_scene)
    unchecked = predict(contradicted_scene, model, preset("default"), QUERY, seed=0, check=None)
    checked = predict(contradicted_scene, model, preset("default"), QUERY, seed=0)
    reference = predict(contradicted_scene, model, reference_settings(), QUERY, seed=0, check=None)
    assert unchecked.object_fall_probability["block1"] - reference.object_fall_probability["block1"] >= 0.5
    assert checked.fidelity == "escalated"
    # the first verified sample disagreed; two more confirmed it
    assert (checked.self_check["verified_samples"], checked.self_check["disagreeing_samples"]) == (3, 3)
    assert checked.self_check["escalated_samples"] == 4
    assert checked.self_check["settings"]["escalation"] == REFERENCE
    expected = _answer(reference)
    expected["request"] = _answer(checked)["request"]  # it says what was asked: the default preset
    assert _answer(checked) == expected


def test_contradicted_when_the_budget_ends_before_the_escalation(contradicted_scene):
    def spent(task, outcome):  # the budget runs out once the verification is done
        if task.settings.name == REFERENCE and task.index > 0:
            return dataclasses.replace(outcome, ok=False, budget_stopped=True, error="BudgetExceeded: spent",
                                       rollouts=(), initial_positions_m=None, initial_orientations_xyzw=None)
        return outcome

    model = _ramp_model(contradicted_scene)
    p = predict(contradicted_scene, model, preset("default"), QUERY, seed=0, map_fn=CountingMap(spent))
    unchecked = predict(contradicted_scene, model, preset("default"), QUERY, seed=0, check=None)
    assert p.fidelity == "contradicted"
    assert _answer(p) == _answer(unchecked)  # the fast answer, flagged: the robot must not act on it


def test_one_disagreement_that_more_samples_do_not_confirm_is_chaos_not_a_verdict(tower):
    def flip_first_verification(task, outcome: SampleOutcome):
        if task.settings.name == REFERENCE and task.index == 0 and len(spy.calls) == 1:
            rollout = outcome.rollouts[0]
            flipped = dataclasses.replace(rollout, fallen=~rollout.fallen, any_fell=not rollout.any_fell)
            return dataclasses.replace(outcome, rollouts=(flipped,))
        return outcome

    spy = CountingMap(flip_first_verification)
    model = ModelConfig(sigma_m=0.01, samples=6)
    p = predict(tower, model, preset("default"), QUERY, seed=4, map_fn=spy)
    assert [(t.settings.name, t.index) for t in spy.calls[1]] == [(REFERENCE, 1), (REFERENCE, 2)]
    assert p.fidelity == "verified"
    assert (p.self_check["verified_samples"], p.self_check["disagreeing_samples"]) == (3, 1)
    assert _answer(p) == _answer(predict(tower, model, preset("default"), QUERY, seed=4, check=None))


def test_a_failed_fast_sample_is_rerun_at_the_reference(tower):
    def fail_second(task, outcome: SampleOutcome):
        if task.settings.name == "default" and task.index == 1:
            return dataclasses.replace(outcome, ok=False, error="PhysicsError: injected", rollouts=())
        return outcome

    model = ModelConfig(sigma_m=0.01, samples=3)
    spy = CountingMap(fail_second)
    p = predict(tower, model, preset("default"), QUERY, seed=4, map_fn=spy)
    assert (p.samples, p.failed_samples, p.refined_samples) == (3, 0, 1)
    assert p.self_check["refined_reasons"] == {"1": "failed"} and p.fidelity == "verified"
    assert [(t.settings.name, t.index) for t in spy.calls[1]] == [(REFERENCE, 1)]
    rerun = run_sample(dataclasses.replace(spy.calls[1][0]))
    assert (p.outcomes[1].rollouts[0].final_positions_m == rerun.rollouts[0].final_positions_m).all()


def test_a_rollout_ending_inside_another_body_is_refined(tower):
    """A real hard case: at the default's steps one rollout of the example tower ends mid-impact at
    the horizon, a block 6% of its size inside another (sample 2 of seed 2)."""
    model = ModelConfig(sigma_m=0.01, samples=3)
    unchecked = predict(tower, model, preset("default"), QUERY, seed=2, check=None)
    checked = predict(tower, model, preset("default"), QUERY, seed=2)
    assert unchecked.max_penetration_fraction > 0.05
    assert checked.max_penetration_fraction <= 0.05
    assert checked.self_check["refined_reasons"] == {"2": "penetration"}


def test_every_unhealthy_rollout_is_replaced_by_its_reference_rerun(tower):
    """With a zero tolerance every rollout that ends touching anything is refined: the answer is
    then the reference's, sample for sample."""
    model = ModelConfig(sigma_m=0.01, samples=3)
    strict = SelfCheck(max_end_penetration_fraction=1e-12)
    checked = predict(tower, model, preset("default"), QUERY, seed=4, check=strict)
    reference = predict(tower, model, reference_settings(), QUERY, seed=4, check=None)
    assert checked.refined_samples == 3 and set(checked.self_check["refined_reasons"]) == {"0", "1", "2"}
    for mine, theirs in zip(checked.outcomes, reference.outcomes):
        assert (mine.rollouts[0].final_positions_m == theirs.rollouts[0].final_positions_m).all()


def test_ground_truth_is_verified_too(tower):
    spy = CountingMap()
    p = predict(tower, ModelConfig(sigma_m=0.0, samples=48), preset("default"), QUERY, map_fn=spy)
    assert p.deterministic and p.fidelity in VERDICTS and p.fidelity != "unverified"
    assert [t.settings.name for t in spy.calls[0]] == [REFERENCE, "default"]


def test_self_check_settings_are_validated_with_the_field_named():
    with pytest.raises(ConfigError, match=r"^self_check.verify_samples: must be an integer in \[0, 1000\], got -1$"):
        SelfCheck(verify_samples=-1)
    with pytest.raises(ConfigError, match=r"^self_check.enabled: must be true or false, got 'yes'$"):
        SelfCheck(enabled="yes")
    with pytest.raises(ConfigError, match=r"^self_check: must be a SelfCheck or None"):
        predict(zoo_scene("drop", 1, 0), ModelConfig(samples=1), preset("default"), QUERY, check="on")


def test_the_node_parameters_set_the_check():
    from ipe_ros.ros.params import PARAMETERS, config_from_values

    values = {spec.name: spec.default for spec in PARAMETERS}
    assert config_from_values(values).check == SelfCheck()
    values.update({"self_check": False, "verify_samples": 3})
    assert config_from_values(values).check == SelfCheck(enabled=False, verify_samples=3)


def test_anytime_sampling_is_checked_on_the_samples_it_drew(tower):
    from ipe_ros.engine.sampler import AdaptiveStop

    stop = AdaptiveStop(deadline_s=1e-6, batch_size=2)  # stops after the first batch
    p = predict(tower, ModelConfig(sigma_m=0.01, samples=8), preset("default"), QUERY, seed=4, stop=stop,
                check=SelfCheck(verify_samples=3))
    assert (p.samples, p.stopped_by) == (2, "deadline")
    assert p.fidelity == "verified" and p.self_check["verified_samples"] == 2
