"""The one Monte Carlo loop (ipe_ros.engine.sampling.montecarlo): plans, the driver, shared rounds, and the
things every answer gets from it (seeds, the map with its lost workers, the budget's deadline)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pytest

from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, predict, predict_many, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.actions import remove
from ipe_ros.engine.scene.generators import generate_towers
from ipe_ros.engine.sampling.montecarlo import MonteCarlo, child_seeds, drive, mapped, together

QUERY = QuerySpec(queries=frozenset({"fall"}))


@dataclass(frozen=True)
class Job:
    value: int
    deadline_unix_s: float | None = None


def doubled(job: Job) -> int:
    return 2 * job.value


def countdown(start: int):
    """A plan whose next round depends on the last outcomes: halve until zero; the rounds it saw."""
    seen = []
    value = start
    while value:
        (value,) = yield [Job(value)]
        value //= 4  # the outcome doubled it
        seen.append(value)
    return seen


def test_a_plan_gets_its_outcomes_round_by_round_and_returns_its_result():
    rounds = []

    def run(jobs):
        rounds.append([j.value for j in jobs])
        return [doubled(j) for j in jobs]

    assert drive(countdown(64), run) == [32, 16, 8, 4, 2, 1, 0]
    assert rounds == [[64], [32], [16], [8], [4], [2], [1]]


def test_a_round_that_asks_for_nothing_is_answered_without_a_map_call():
    def plan():
        nothing = yield []
        some = yield [Job(3)]
        return nothing, some

    calls = []
    assert drive(plan(), lambda jobs: calls.append(jobs) or [doubled(j) for j in jobs]) == ([], [6])
    assert len(calls) == 1


def test_plans_together_share_each_round_and_get_their_own_outcomes_back():
    calls = []

    def run(jobs):
        calls.append([j.value for j in jobs])
        return [doubled(j) for j in jobs]

    assert drive(together([countdown(64), countdown(4), countdown(0)]), run) == [
        [32, 16, 8, 4, 2, 1, 0], [2, 1, 0], []]
    # one map call per round: the short plans ride along with the long one while they last
    assert calls == [[64, 4], [32, 2], [16, 1], [8], [4], [2], [1]]


def test_mapped_converts_outcomes_before_the_plan_sees_them():
    def plan():
        outcomes = yield [Job(1), Job(2)]
        return outcomes

    assert drive(mapped(plan(), str), lambda jobs: [doubled(j) for j in jobs]) == ["2", "4"]


def test_the_loop_stamps_the_budgets_deadline_on_every_task_and_answers_lost_workers():
    seen: list[Job] = []

    def losing_map(fn, jobs, on_lost):
        seen.extend(jobs)
        return [on_lost(j, "worker died twice") if j.value == 2 else fn(j) for j in jobs]

    before = time.time()
    loop = MonteCarlo(doubled, lambda job, why: f"lost {job.value}: {why}", losing_map, budget_s=5.0)
    assert loop.run([Job(1), Job(2), Job(3)]) == [2, "lost 2: worker died twice", 6]
    assert {j.deadline_unix_s for j in seen} == {loop.deadline_unix_s}
    assert before + 5.0 <= loop.deadline_unix_s <= time.time() + 5.0
    # without a map, in this process; without a budget, no deadline
    assert MonteCarlo(doubled, None).run([Job(4)]) == [8]


def test_seeds_are_the_children_of_one_seed_sequence_whatever_k_is():
    few, many = child_seeds(7, 3), child_seeds(7, 10)
    for a, b in zip(few, many):
        assert np.random.default_rng(a).integers(1 << 62) == np.random.default_rng(b).integers(1 << 62)
    with pytest.raises(ConfigError) as info:
        child_seeds(-1, 3)
    assert str(info.value) == "seed: must be an integer >= 0, got -1"
    with pytest.raises(ConfigError) as info:
        MonteCarlo(doubled, None, budget_s=float("nan"))
    assert str(info.value) == "budget_s: must be a finite number of seconds > 0 (or none), got nan"


class CountingMap:
    """A map in this process that counts its calls and loses the worker of one sample index."""

    def __init__(self, lose_index: int | None = None):
        self.calls: list[int] = []
        self.lose_index = lose_index

    def __call__(self, fn, tasks, on_lost=None):
        self.calls.append(len(tasks))
        return [on_lost(t, "test: worker gone") if t.index == self.lose_index else fn(t) for t in tasks]


def test_unchecked_predictions_run_in_one_map_call_alone_or_many_together():
    towers = generate_towers(5, 3)
    model = ModelConfig(sigma_m=0.03, samples=6)
    counting = CountingMap()
    alone = predict(towers[0],
                    Request(model=model, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None),
                    Context(map_fn=counting))
    assert counting.calls == [6]
    counting = CountingMap()
    answers = predict_many([(t, model, i + 1) for i, t in enumerate(towers)], preset("default"), QUERY, counting)
    assert counting.calls == [18]
    assert answers[0].object_fall_probability == alone.object_fall_probability


def test_a_lost_worker_is_a_counted_failure_in_predictions_and_questions_alike():
    tower = generate_towers(5, 1)[0]
    model = ModelConfig(sigma_m=0.03, samples=6)
    p = predict(tower,
                Request(model=model, settings=preset("default"), query=QUERY, seed=1, check=None, budget_s=None),
                Context(map_fn=CountingMap(lose_index=2)))
    assert (p.samples, p.failed_samples) == (5, 1)
    assert p.failure_reasons == ("WorkerLost: test: worker gone",)
    answers = remove(tower, [tower.objects[-1].name], model, preset("default"), seed=1, sequential=False,
                     map_fn=CountingMap(lose_index=2))
    assert [(v.label, v.samples, v.failed_samples) for v in answers.variants] == [
        ("as_is", 5, 1), (f"remove/{tower.objects[-1].name}", 5, 1)]
