"""Anytime sampling: a target interval width or a deadline ends sampling early, reproducibly."""

from __future__ import annotations

import pytest

from ipe_ros.engine import AdaptiveStop, ConfigError, ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.sampling.estimate import wilson_interval
from tests.helpers import block, floor_scene, without_timing

FALL = QuerySpec(queries=frozenset({"fall"}))
STANDING = floor_scene(block("a", 0, 0, 0.1), block("b", 0, 0, 0.3))  # nothing can fall at sigma = 1 mm
MODEL = ModelConfig(sigma_m=0.001, samples=48)


def test_a_target_width_stops_as_soon_as_it_is_met_and_equals_a_run_of_that_k(pool):
    stop = AdaptiveStop(ci_width=0.35, batch_size=4, min_samples=4)
    p = predict(STANDING,
                Request(model=MODEL, settings=preset("default"), query=FALL, seed=3, stop=stop, budget_s=None),
                Context(map_fn=pool.map))
    # all samples agree (nothing falls): the Wilson interval [0, hi] first fits 0.35 at n = 8
    assert wilson_interval(0.0, 4)[1] > 0.35 >= wilson_interval(0.0, 8)[1]
    assert (p.stopped_by, p.samples, p.samples_requested, p.fall_fraction) == ("ci_width", 8, 48, 0.0)
    same_k = predict(STANDING,
                     Request(model=ModelConfig(sigma_m=0.001, samples=8), settings=preset("default"), query=FALL,
                             seed=3, budget_s=None),
                     Context(map_fn=pool.map))
    for key in ("fall_fraction", "fall_fraction_ci95", "object_fall_probability"):
        assert getattr(p, key) == getattr(same_k, key)


def test_an_uncertain_scene_needs_more_samples_than_a_certain_one(pool):
    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    stop = AdaptiveStop(ci_width=0.3, batch_size=4)
    risky = predict(tower,
                    Request(model=ModelConfig(sigma_m=0.04, samples=48), settings=preset("default"), query=FALL,
                            seed=0, stop=stop, budget_s=None),
                    Context(map_fn=pool.map))
    lo, hi = risky.fall_fraction_ci95
    assert risky.stopped_by == "ci_width" and hi - lo <= 0.3 and risky.samples > 8


def test_a_deadline_ends_sampling_and_says_so(pool):
    stop = AdaptiveStop(deadline_s=1e-6, batch_size=2)  # over as soon as the first batch ran
    p = predict(STANDING,
                Request(model=MODEL, settings=preset("default"), query=FALL, seed=0, stop=stop, budget_s=None),
                Context(map_fn=pool.map))
    assert (p.stopped_by, p.samples) == ("deadline", 2)  # the first batch always runs
    plenty = predict(STANDING,
                     Request(model=ModelConfig(sigma_m=0.001, samples=4), settings=preset("default"), query=FALL,
                             seed=0, stop=AdaptiveStop(deadline_s=600.0, batch_size=2), budget_s=None))
    assert (plenty.stopped_by, plenty.samples) == ("samples", 4)
    assert without_timing(plenty.to_dict())["fall_fraction"] == 0.0


@pytest.mark.parametrize("kwargs, message", [
    (dict(ci_width=0.0), "ci_width: must be in (0, 1], got 0.0"),
    (dict(deadline_s=-1.0), "deadline_s: must be a finite number of seconds > 0, got -1.0"),
    (dict(batch_size=0), "batch_size: must be an integer >= 1, got 0"),
])
def test_bad_rules_are_named(kwargs, message):
    with pytest.raises(ConfigError) as info:
        AdaptiveStop(**kwargs)
    assert str(info.value) == message


def test_a_width_target_needs_the_fall_query():
    with pytest.raises(ConfigError, match=r"^ci_width: a target interval width needs the fall or any_fall query"):
        predict(STANDING,
                Request(model=MODEL, settings=preset("default"), query=QuerySpec(queries=frozenset({"far"})),
                        stop=AdaptiveStop(ci_width=0.2), budget_s=None))
