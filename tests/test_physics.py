"""Basic physics: rest stays at rest, overhangs fall, noise separation injects no energy, pushes push."""

import math
from dataclasses import replace

import numpy as np
import pytest

from ipe_ros.engine import Box, ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine import Request
from ipe_ros.engine import simulation
from ipe_ros.engine.config import DEFAULT_QUERIES
from ipe_ros.engine.scene.generators import make_table
from ipe_ros.engine.sampling.perturb import draw_sample_inputs
from ipe_ros.engine.scene.bodies import Scene

from .helpers import block, floor_scene

ALL = QuerySpec(queries=frozenset({"fall", "direction", "far"}))


@pytest.mark.parametrize("name", ["paper", "default"])
def test_resting_box_stays_put_for_two_seconds(name):
    scene = floor_scene(block("a", 0.3, -0.2, 0.1))
    p = predict(scene, Request(model=ModelConfig(), settings=preset(name), query=ALL, budget_s=None))
    assert p.deterministic and p.samples == 1 and p.failed_samples == 0
    rollout = p.outcomes[0].rollouts[0]
    assert np.allclose(rollout.final_positions_m, [[0.3, -0.2, 0.1]], atol=1e-4)
    assert p.fall_fraction == 0.0 and p.direction_rad is None and p.far_m == 0.0


def test_the_answer_reports_the_horizon_that_was_simulated():
    """A scene's own horizon_s replaces the preset's; the request says which one ran."""
    scene = replace(floor_scene(block("a", 0.3, -0.2, 0.1)), horizon_s=0.5)
    p = predict(scene, Request(model=ModelConfig(), settings=preset("paper"), query=ALL, budget_s=None))
    assert p.outcomes[0].rollouts[0].simulated_s == pytest.approx(0.5)
    assert p.request["horizon_s"] == 0.5
    assert predict(floor_scene(block("a", 0.3, -0.2, 0.1)),
                   Request(model=ModelConfig(), settings=preset("paper"), query=ALL, budget_s=None)).request[
        "horizon_s"] == preset("paper").horizon_s


def test_block_overhanging_more_than_half_its_length_falls_towards_the_overhang():
    # bottom block lies along y (0.6 long); the top block sticks out 0.35 m (> half of 0.6) towards +y
    scene = floor_scene(block("base", 0, 0, 0.1), block("top", 0, 0.35, 0.3))
    p = predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=ALL, budget_s=None))
    assert p.object_fall_probability == {"base": 0.0, "top": 1.0}
    assert p.direction_rad == pytest.approx(math.pi / 2, abs=0.3)
    assert p.far_m > 0.3


def test_block_overhanging_less_than_half_stays():
    scene = floor_scene(block("base", 0, 0, 0.1), block("top", 0, 0.25, 0.3))
    p = predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=ALL, budget_s=None))
    assert p.fall_fraction == 0.0


def test_deep_interpenetration_is_separated_without_injecting_energy():
    # two boxes occupying nearly the same space: a naive simulation would launch them apart
    scene = floor_scene(block("a", 0, 0, 0.1), block("b", 0.02, 0.01, 0.1))
    settings = preset("default")
    inputs = draw_sample_inputs(scene, ModelConfig(), np.random.default_rng(0))
    world = simulation.build_world(scene, inputs.positions_m, inputs.masses_kg, settings)
    simulation.depenetrate(world, settings)
    positions, _ = simulation.read_poses(world)
    gap = abs(positions[0, 0] - positions[1, 0])
    assert gap >= 0.2 - 1e-3  # side by side now (the 0.2 m x extents no longer overlap)
    assert np.allclose(positions[:, 2], 0.1, atol=1e-3)  # nothing was lifted or sunk
    for _ in range(100):
        simulation.pybullet().stepSimulation(physicsClientId=world.client)
    assert simulation.read_velocities(world)[0].max() < 0.05


def test_large_noise_on_a_stack_separates_and_rolls_out_without_divergence():
    # sigma = 0.1 m on 0.2 m blocks; failed_samples counts any rollout whose speed exceeded the
    # physical bound (free fall plus push), i.e. any energy the separation or solver injected
    scene = floor_scene(block("a", 0, 0, 0.1), block("b", 0.0, 0.0, 0.3), block("c", 0.0, 0.0, 0.5))
    p = predict(scene,
                Request(model=ModelConfig(sigma_m=0.1, samples=6), settings=preset("default"), query=ALL, seed=3,
                        budget_s=None))
    assert p.failed_samples == 0
    for outcome in p.outcomes:
        assert np.all(np.isfinite(outcome.initial_positions_m))


def table_scene(kind: str) -> Scene:
    """Two red cubes 5 cm from the -x edge, two yellow cubes 5 cm from the -y edge (table 2.4 x 1.6 m)."""
    cube = (0.2, 0.2, 0.2)
    boxes = [block("r0", -0.95, -0.15, 0.1, extents=cube, group="red"),
             block("r1", -0.95, 0.15, 0.1, extents=cube, group="red"),
             block("y0", -0.15, -0.65, 0.1, extents=cube, group="yellow"),
             block("y1", 0.15, -0.65, 0.1, extents=cube, group="yellow")]
    boxes = [replace(b, friction=0.5) for b in boxes]
    return Scene(name=f"bump_{kind}", objects=tuple(boxes), support=make_table(kind), gravity_m_s2=(0, 0, -9.81))


def test_cued_bump_on_a_walled_table_changes_which_colour_falls_off():
    # The table is bumped towards +x (cue 0 deg, +-45 deg): boxes slide towards -x (+-45 deg) relative to
    # it, about 0.8 m. On the flat table the red cubes always go over the -x edge and the yellow ones
    # over the -y edge when the slide has enough -y in it; on T1 a wall along the -x edge holds the reds.
    model = ModelConfig(sigma_m=0.01, phi_m_s2=(10.0,), force_direction_rad=0.0, samples=16)
    query = QuerySpec(queries=frozenset({"bump"}))
    flat = predict(table_scene("T0"),
                   Request(model=model, settings=preset("default"), query=query, seed=1, budget_s=None))
    walled = predict(table_scene("T1"),
                     Request(model=model, settings=preset("default"), query=query, seed=1, budget_s=None))  # walls on the +-x edges
    assert flat.failed_samples == walled.failed_samples == 0
    assert flat.fell_off_fraction_by_group["red"] > 0.9
    assert walled.fell_off_fraction_by_group["red"] < 0.1
    assert 0.1 < walled.fell_off_fraction_by_group["yellow"] < 0.9
    assert flat.bump_ratio > 0.6 and walled.bump_ratio < 0.1  # red share of what fell off


def test_no_push_machinery_without_phi_and_push_with_phi():
    scene = floor_scene(block("a", 0, 0, 0.4, extents=(0.2, 0.2, 0.8)))
    still = predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=ALL, budget_s=None))
    pushed = predict(scene,
                     Request(model=ModelConfig(phi_m_s2=(15.0,), force_direction_rad=0.0, cue_half_width_rad=0.0, samples=1),
                             settings=preset("default"), query=ALL, budget_s=None))
    assert still.fall_fraction == 0.0
    # a tall narrow box on a floor jerked towards +x topples backwards, towards -x
    assert pushed.fall_fraction == 1.0
    assert abs(abs(pushed.direction_rad) - math.pi) < 0.3


def test_bump_query_needs_a_table():
    from ipe_ros.engine import ConfigError

    with pytest.raises(ConfigError, match="^queries: the bump query needs a table support"):
        predict(floor_scene(block("a", 0, 0, 0.1)),
                Request(model=ModelConfig(), settings=preset("default"), query=QuerySpec(queries=frozenset({"bump"})),
                        budget_s=None))


def test_failed_rollouts_are_counted_not_raised():
    scene = floor_scene(block("a", 0, 0, 0.1), block("b", 0.001, 0.0, 0.1))
    settings = preset("default").changed(depenetration={"max_iterations": 1})
    p = predict(scene,
                Request(model=ModelConfig(sigma_m=0.001, samples=3), settings=settings, query=ALL, check=None,
                        budget_s=None))
    assert p.samples == 0 and p.failed_samples == 3 and p.fall_fraction is None
    assert p.failure_reasons == ("PhysicsError: boxes still overlap after 1 depenetration rounds; lower sigma or "
                                 "raise depenetration.max_iterations",)
    # the self-check reruns failed samples at the reference, whose separation has its 200 rounds
    checked = predict(scene,
                      Request(model=ModelConfig(sigma_m=0.001, samples=3), settings=settings, query=ALL,
                              budget_s=None))
    assert (checked.samples, checked.failed_samples, checked.refined_samples) == (3, 0, 3)
    assert checked.self_check["refined_reasons"] == {"0": "failed", "1": "failed", "2": "failed"}


def test_mu_sets_the_models_own_densities():
    from ipe_ros.engine.sampling.perturb import MODEL_LIGHT_DENSITY_KG_M3, dynamic_masses

    scene = floor_scene(block("a", 0, 0, 0.1, mass_kg=4.0799, group="light"),
                        block("b", 0, 0, 0.3, mass_kg=40.8, group="Heavy"))
    assert dynamic_masses(scene, None).tolist() == [4.0799, 40.8]
    light = MODEL_LIGHT_DENSITY_KG_M3 * 0.024
    assert dynamic_masses(scene, 1.0) == pytest.approx([light, light], rel=1e-12)
    assert dynamic_masses(scene, 6.0) == pytest.approx([light, 6 * light], rel=1e-12)


def test_early_termination_ends_a_resting_stack_before_the_horizon():
    scene = floor_scene(block("b0", 0, 0, 0.1), block("b1", 0, 0, 0.3))
    p = predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=QuerySpec(), budget_s=None))
    assert p.fall_fraction == 0.0
    assert p.outcomes[0].rollouts[0].simulated_s < 1.0  # rest from 0.3 s on, confirmed over 0.2 s


def test_early_termination_does_not_wait_for_a_box_that_cannot_fall():
    # A slab lying on a slippery floor, pushed: it slides on past the 2 s horizon, but lying flat on
    # the floor it can never drop, so "does it fall?" is decided from the start. Asking where it
    # ends up (direction) still waits for it to come to rest.
    slab = replace(block("slab", 0, 0, 0.05, extents=(0.4, 0.4, 0.1)), friction=0.02)
    scene = floor_scene(slab)
    model = ModelConfig(phi_m_s2=(3.0,), force_direction_rad=0.0, cue_half_width_rad=0.0, samples=1)
    fall_only = predict(scene,
                        Request(model=model, settings=preset("default"), query=QuerySpec(queries=frozenset({"fall"})),
                                budget_s=None))
    where_to = predict(scene,
                       Request(model=model, settings=preset("default"),
                               query=QuerySpec(queries=frozenset({"fall", "direction"})), budget_s=None))
    assert fall_only.fall_fraction == where_to.fall_fraction == 0.0
    # the push until 0.2 s, then the 0.15 s rest window, on the ~0.05 s grid of rest checks
    assert fall_only.outcomes[0].rollouts[0].simulated_s < 0.5
    assert where_to.outcomes[0].rollouts[0].simulated_s == pytest.approx(2.0, abs=0.01)  # the horizon
    assert abs(where_to.outcomes[0].rollouts[0].final_positions_m[0, 0]) > 0.5  # it did slide on


def test_a_fallen_body_that_moves_on_holds_up_the_end_of_a_fall_only_question():
    # zoo drop 2026/0: a cube dropped from 2.2 m has fallen at once, then bounces into block1 and
    # knocks it off block0 about 1 s later. Asking only "what falls?" must not end while block1
    # stands still meanwhile: wherever the run that waits for every body to rest (far) sees block1
    # knocked off, so does the fall-only one (it may see more: a block that has fallen is decided,
    # and one that later props itself back up is not waited for; `paper` knocks it off in all 4)
    from ipe_ros.engine.checking.fidelity import NO_CHECK
    from ipe_ros.engine.scene.zoo import zoo_scene, zoo_sigma_m

    scene = zoo_scene("drop", 2026, 0)
    model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=4)
    fall_only, to_rest = ([bool(o.rollouts[0].fallen[1]) for o in predict(scene,
                                                                          Request(model=model,
                                                                                  settings=preset("default"),
                                                                                  query=QuerySpec(queries=frozenset(asked)),
                                                                                  check=NO_CHECK, budget_s=None)).outcomes]
        for asked in ({"fall"}, {"fall", "far"}))
    assert any(to_rest)
    assert all(alone for alone, waited in zip(fall_only, to_rest) if waited)


def _three_block_tower_with_a_borderline_top():
    """A 3-block tower whose top block overhangs by 0.28 of its 0.2 m width: with 2 cm of noise some
    samples keep it, some drop it, so "will anything fall?" is uncertain."""
    return floor_scene(block("b0", 0, 0, 0.1, extents=(0.2, 0.2, 0.2)),
                       block("b1", 0.0, 0, 0.3, extents=(0.2, 0.2, 0.2)),
                       block("b2", 0.095, 0, 0.5, extents=(0.2, 0.2, 0.2)))


def test_what_falls_off_is_decided_once_below_the_table_top_and_agrees_with_waiting_for_rest():
    # bump alone: a block below the table top has fallen off and need not come to rest on the floor;
    # asked with direction (which waits for every block to rest), the same blocks are off the table
    model = ModelConfig(sigma_m=0.01, phi_m_s2=(10.0, 30.0), force_direction_rad=0.0, samples=6)
    scene = table_scene("T0")
    alone = predict(scene,
                    Request(model=model, settings=preset("default"), query=QuerySpec(queries=frozenset({"bump"})),
                            seed=4, budget_s=None))
    waiting = predict(scene,
                      Request(model=model, settings=preset("default"),
                              query=QuerySpec(queries=frozenset({"bump", "direction"})), seed=4, budget_s=None))
    assert alone.failed_samples == waiting.failed_samples == 0
    ended_sooner = 0
    for quick, slow in zip(alone.outcomes, waiting.outcomes):
        for a, b in zip(quick.rollouts, slow.rollouts):
            assert np.array_equal(a.value("fell_off"), b.value("fell_off"))
            ended_sooner += a.simulated_s < b.simulated_s
    assert any(r.value("fell_off").any() for o in alone.outcomes for r in o.rollouts)
    assert ended_sooner >= len(alone.outcomes)  # most rollouts stop before everything is at rest
    assert alone.fell_off_fraction_by_group == waiting.fell_off_fraction_by_group


def test_will_anything_fall_stops_at_the_first_fall_and_agrees_with_the_full_rollout():
    scene = _three_block_tower_with_a_borderline_top()
    model = ModelConfig(sigma_m=0.02, samples=12)
    yes_no = predict(scene,
                     Request(model=model, settings=preset("default"),
                             query=QuerySpec(queries=frozenset({"any_fall"})), seed=3, budget_s=None))
    full = predict(scene,
                   Request(model=model, settings=preset("default"),
                           query=QuerySpec(queries=frozenset({"fall", "any_fall"})), seed=3, budget_s=None))
    fell_any = [o.rollouts[0].value("any_fell") for o in yes_no.outcomes]
    assert fell_any == [bool(o.rollouts[0].fallen.any()) for o in full.outcomes]  # same noisy scenes, same answers
    assert 0 < sum(fell_any) < len(fell_any), "the scene should be uncertain under this seed"
    assert yes_no.any_fall_probability == full.any_fall_probability == sum(fell_any) / len(fell_any)
    lo, hi = yes_no.any_fall_probability_ci95
    assert lo < yes_no.any_fall_probability < hi
    # the yes/no rollouts that saw a fall ended early; the fraction query had to wait for rest
    for quick, slow, fell in zip(yes_no.outcomes, full.outcomes, fell_any):
        if fell:
            assert quick.rollouts[0].simulated_s < slow.rollouts[0].simulated_s
    assert yes_no.fall_fraction is None and yes_no.outcomes[0].rollouts[0].fallen is None


def _collapsing(settings, factor: int, iterations: int | None = None):
    return settings.changed(f"{settings.name}-collapse{factor}",
                            collapse={"step_factor": factor, "solver_iterations": iterations})


def test_collapse_steps_change_nothing_while_nothing_falls():
    # a stable stack never triggers the switch: bit-identical to the fine step throughout
    scene = floor_scene(block("b0", 0, 0, 0.1), block("b1", 0, 0.05, 0.3), block("b2", 0, 0, 0.5))
    model = ModelConfig(sigma_m=0.005, samples=4)
    fine = predict(scene,
                   Request(model=model, settings=_collapsing(preset("default"), 1), query=QuerySpec(), seed=1,
                           budget_s=None))
    coarse = predict(scene,
                     Request(model=model, settings=_collapsing(preset("default"), 4, 30), query=QuerySpec(), seed=1,
                             budget_s=None))
    assert fine.fall_fraction == coarse.fall_fraction == 0.0
    for a, b in zip(fine.outcomes, coarse.outcomes):
        assert np.array_equal(a.rollouts[0].final_positions_m, b.rollouts[0].final_positions_m)
        assert a.rollouts[0].simulated_s == b.rollouts[0].simulated_s


def test_collapse_steps_start_at_the_first_fall_and_keep_the_time_grid():
    # the top block overhangs and falls; the rest of the rollout runs up to 3x coarser steps,
    # recorded as often as with fine steps, and the rollout ends exactly on the horizon
    cube = (0.2, 0.2, 0.2)
    scene = floor_scene(block("base", 0, 0, 0.1, extents=cube), block("top", 0.16, 0, 0.3, extents=cube))
    no_early = preset("default").changed(early_stop={"enabled": False})
    fine = physics_rollout(scene, _collapsing(no_early, 1))
    coarse = physics_rollout(scene, _collapsing(no_early, 3))
    assert coarse.simulated_s == pytest.approx(fine.simulated_s) == pytest.approx(no_early.horizon_s)
    # one frame per 12 ticks of the fine step, taken at the end of the step that reached it
    fine_times, coarse_times = (np.array([t for t, *_ in r.trajectory]) for r in (fine, coarse))
    assert len(coarse_times) == len(fine_times)
    dt = no_early.time_step_s
    assert np.all((coarse_times >= fine_times - 1e-12) & (coarse_times < fine_times + 3 * dt - 1e-12))
    # until the top block clearly fell (dropped by half its 0.2 m height) the two are the same
    # simulation; afterwards they differ, and agree
    fell_at = next(i for i, (_, pos, _) in enumerate(fine.trajectory) if pos[1, 2] < 0.3 - 0.5 * 0.2)
    for (_, a, _), (_, b, _) in zip(fine.trajectory[:fell_at], coarse.trajectory[:fell_at]):
        assert np.array_equal(a, b)
    assert not np.array_equal(fine.trajectory[-1][1], coarse.trajectory[-1][1])
    for rollout in (fine, coarse):
        assert rollout.fallen.tolist() == [False, True]
        assert rollout.final_positions_m[1, 2] == pytest.approx(0.1, abs=0.005)  # on the floor


class _StepCounter(simulation.Probe):
    """Counts pybullet steps by the phase they ran in."""

    def __init__(self) -> None:
        self.steps = dict.fromkeys(simulation.PHASES, 0)

    def step(self, phase, run):
        run()
        self.steps[phase] += 1


def test_collapse_steps_that_make_energy_go_back_to_the_trials_latest_anchor_not_its_start():
    """A chain of 18 dominoes, asked where they land: in sample 2 the collapse steps, begun at
    0.3 s, make energy at a late impact. Going back to where they began reran the rest at the fine
    step (1656 pybullet steps in all); a trial that has gone ``anchor_after_steps`` without making
    energy begins again at its next look, so the undo reruns only what follows the latest anchor
    (1330 steps) and what fell is the same. A rollout whose collapse steps make no energy is bit for
    bit the same: saving the world at an anchor changes nothing in it. On the direct solver, as
    `default` solved the chain before ``direct_solver_min_restitution``, ``direct_solver_for_impacts_only``
    and ``bounce_from_touch`` (and to its residual of then):
    on the sequential-impulse solver its collapse steps make no energy to undo."""
    from ipe_ros.engine.config import DEFAULT_QUERIES
    from ipe_ros.engine.sampling.rollout import run_sample
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.scene.zoo import zoo_scene, zoo_sigma_m

    scene = zoo_scene("dominoes", 2026, 2)
    model, query = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=3), QuerySpec(queries=DEFAULT_QUERIES)
    assert preset("default").collapse.anchor_after_steps == 300
    direct = preset("default").changed(solver={"direct_solver_min_restitution": 0.0, "residual_threshold": 3e-6,
                                               "direct_solver_for_impacts_only": False,
                                               "bounce_from_touch": False})
    runs = {}
    for name, settings in {"start": direct.changed(collapse={"anchor_after_steps": None}), "anchor": direct}.items():
        for index in (1, 2):
            counter = _StepCounter()
            outcome = run_sample(make_tasks(scene, model, settings, query, seed=2)[index], probe=counter)
            assert outcome.ok, outcome.error
            runs[name, index] = (outcome.rollouts[0], counter.steps)
    for index in (1, 2):
        assert runs["start", index][0].fallen.tolist() == runs["anchor", index][0].fallen.tolist()
    kept_start, kept_anchor = runs["start", 1][0], runs["anchor", 1][0]
    assert not kept_start.collapse_undone and not kept_anchor.collapse_undone
    np.testing.assert_array_equal(kept_start.final_positions_m, kept_anchor.final_positions_m)
    (undone_start, steps_start), (undone_anchor, steps_anchor) = runs["start", 2], runs["anchor", 2]
    assert undone_start.collapse_undone and undone_anchor.collapse_undone
    # the same collapse steps up to the energy; the fine rerun from the anchor (828 fine steps -> 502)
    assert steps_anchor["collapse"] == steps_start["collapse"]
    assert steps_anchor["fine"] < 0.7 * steps_start["fine"]
    assert sum(steps_anchor.values()) < 0.85 * sum(steps_start.values())


def test_settling_runs_the_first_ticks_in_substeps_on_the_same_time_grid():
    # the overhanging top block falls with and without settling; frames come at the same times and
    # the rollout ends on the horizon; one substep is no settling at all (bit-identical)
    cube = (0.2, 0.2, 0.2)
    scene = floor_scene(block("base", 0, 0, 0.1, extents=cube), block("top", 0.16, 0, 0.3, extents=cube))
    base = preset("default").changed(early_stop={"enabled": False}, collapse={"step_factor": 1})
    plain = physics_rollout(scene, base.changed(settling={"duration_s": 0.0, "substeps": 1}))
    one = physics_rollout(scene, base.changed(settling={"duration_s": 0.1, "substeps": 1}))
    settled = physics_rollout(scene, base.changed(settling={"duration_s": 0.1, "substeps": 3}))
    assert np.array_equal(plain.final_positions_m, one.final_positions_m)
    assert [t for t, *_ in settled.trajectory] == [t for t, *_ in plain.trajectory]
    assert settled.simulated_s == plain.simulated_s == pytest.approx(base.horizon_s)
    assert not np.array_equal(settled.trajectory[2][1], plain.trajectory[2][1])  # after settling: a different integration
    assert settled.fallen.tolist() == plain.fallen.tolist() == [False, True]


def physics_rollout(scene, settings):
    """The ground-truth rollout of ``scene`` with a trajectory every 12 fine steps (0.05 s)."""
    from ipe_ros.engine.sampling.rollout import SampleTask, run_sample

    task = SampleTask(scene=scene, model=ModelConfig(), settings=settings, query=QuerySpec(), index=0,
                      seed=np.random.SeedSequence(0), record_every=12)
    outcome = run_sample(task)
    assert outcome.ok, outcome.error
    return outcome.rollouts[0]


@pytest.mark.parametrize("group, field, value, message", [
    ("collapse", "step_factor", 0, "collapse.step_factor: must be an integer in [1, 100] (1: no collapse steps), got 0"),
    ("collapse", "step_factor", 2.0,
     "collapse.step_factor: must be an integer in [1, 100] (1: no collapse steps), got 2.0"),
    ("collapse", "solver_iterations", 0,
     "collapse.solver_iterations: must be an integer in [1, 10000] or None, got 0"),
    ("collapse", "anchor_after_steps", 0,
     "collapse.anchor_after_steps: must be an integer in [1, 1000000] or None, got 0"),
    ("collapse", "residual_threshold", 0.0, "collapse.residual_threshold: must be a finite number > 0, got 0.0"),
    ("settling", "substeps", 0, "settling.substeps: must be an integer in [1, 100] (1: no settling substeps), got 0"),
    ("settling", "duration_s", -0.1, "settling.duration_s: must be a finite number >= 0, got -0.1"),
    ("early_stop", "growth_factor", 0.5, "early_stop.growth_factor: must be in [1, 10), got 0.5"),
    ("solver", "iterations", 0, "solver.iterations: must be an integer in [1, 10000], got 0"),
    ("solver", "multibodies_from_aspect", 0.5,
     "solver.multibodies_from_aspect: must be a length-to-thickness ratio >= 1 or None, got 0.5"),
    ("solver", "direct_solver_min_restitution", 1.5,
     "solver.direct_solver_min_restitution: must be a restitution in [0, 1], got 1.5"),
    ("solver", "direct_solver_from_speed_m_s", -1.0,
     "solver.direct_solver_from_speed_m_s: must be a speed >= 0 or None, got -1.0"),
])
def test_each_settings_group_validates_its_own_fields(group, field, value, message):
    from ipe_ros.engine import ConfigError

    with pytest.raises(ConfigError) as info:
        preset("default").changed(**{group: {field: value}})
    assert str(info.value) == message


def test_changed_names_the_unknown_field():
    from ipe_ros.engine import ConfigError

    with pytest.raises(ConfigError, match=r"^collapse: .*unexpected keyword argument 'factor'.*; its fields are "
                                          r"step_factor, solver_iterations, drop_fraction, fine_before_end_s, end_substeps, "
                                          r"max_created_energy_fraction, quiet_sizes_per_s, max_travel_fraction, "
                                          r"end_travel_fraction, anchor_after_steps, residual_threshold$"):
        preset("default").changed(collapse={"factor": 2})
    with pytest.raises(ConfigError, match="^solver_iterations: not a field of SimSettings$"):
        preset("default").changed(solver_iterations=2)


@pytest.mark.parametrize("name", ["paper", "accurate", "fine", "default"])
def test_a_sliding_box_stops_where_coulomb_friction_says_under_every_preset(name):
    """No drag but friction: pybullet's default damping of multibodies (`paper`'s representation)
    stopped a box sliding at 3 m/s 11% short, while `default`'s rigid bodies slid the full distance."""
    from ipe_ros.engine import Body, Floor, Scene
    from ipe_ros.engine.scene.shapes import BoxShape

    speed, friction = 3.0, 0.2  # the floor's 1.0 times the box's 0.2
    box = Body("box", BoxShape((0.2, 0.2, 0.2)), (0.0, 0.0, 0.1), (0.0, 0.0, 0.0, 1.0), friction=friction,
               restitution=0.0, mass_kg=8.0, linear_velocity_m_s=(speed, 0.0, 0.0))
    scene = Scene(name="slide", objects=(box,), support=Floor(friction=1.0, restitution=0.0))
    p = predict(scene,
                Request(model=ModelConfig(sigma_m=0.0), settings=preset(name),
                        query=QuerySpec(queries=frozenset({"far"})), check=None, budget_s=None))
    coulomb_m = speed ** 2 / (2 * friction * 9.81)
    assert p.outcomes[0].rollouts[0].final_positions_m[0, 0] == pytest.approx(coulomb_m, rel=0.01)


def test_end_substeps_read_a_collapse_at_the_horizon_at_a_finer_step():
    """A tower collapsing at the horizon: with half steps for the last 0.1 s nothing ends inside
    another by more than the default's own end (and the setting changes only that last part)."""
    from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes
    from ipe_ros.engine.predict import predict
    from ipe_ros.engine.predict import Request

    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    query = QuerySpec(queries=frozenset({"fall", "direction"}))  # run to the horizon, every pose read
    model = ModelConfig(sigma_m=0.04, samples=6)
    plain = predict(tower,
                    Request(model=model, settings=preset("default"), query=query, seed=2, check=None, budget_s=None))
    halved = predict(tower,
                     Request(model=model, settings=preset("default").changed(collapse={"end_substeps": 2}),
                             query=query, seed=2, check=None, budget_s=None))
    assert halved.max_penetration_fraction <= max(plain.max_penetration_fraction, 0.05)
    for a, b in zip(plain.outcomes, halved.outcomes):  # the same noisy scenes
        np.testing.assert_array_equal(a.initial_positions_m, b.initial_positions_m)


def test_the_end_phase_takes_as_many_substeps_as_keep_a_landing_within_the_healthy_end():
    """Sample 0 of seed 8 ends mid-impact at the horizon, a block 10% of its size inside another at
    half steps; substeps that keep every corner within 5% of the smallest extent per substep end it
    healthy (``collapse.end_travel_fraction``); which blocks fell is as at half steps, sample by
    sample (the end phase is the last 0.1 s of a collapse). `default` takes no half steps besides
    (``collapse.end_substeps`` 1). On the fine steps' residual the case was found at (3e-6)."""
    from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes
    from ipe_ros.engine.config import DEFAULT_QUERIES
    from ipe_ros.engine.predict import predict
    from ipe_ros.engine.predict import Request

    tower = load_scenes("ipe_ros/data/example_tower.json")[0]
    model, query = ModelConfig(sigma_m=0.01, samples=3), QuerySpec(queries=DEFAULT_QUERIES)
    assert preset("default").collapse.end_travel_fraction == 0.05
    then = preset("default").changed(solver={"residual_threshold": 3e-6})
    halves = predict(tower,
                     Request(model=model,
                             settings=then.changed(collapse={"end_travel_fraction": None, "end_substeps": 2}),
                             query=query, seed=8, check=None, budget_s=None))
    limited = predict(tower, Request(model=model, settings=then, query=query, seed=8, check=None, budget_s=None))
    assert halves.outcomes[0].rollouts[0].penetration_fraction > 0.1
    assert limited.max_penetration_fraction < 0.05
    for a, b in zip(halves.outcomes, limited.outcomes):
        np.testing.assert_array_equal(a.initial_positions_m, b.initial_positions_m)  # the same noisy scenes
        np.testing.assert_array_equal(a.rollouts[0].fallen, b.rollouts[0].fallen)


def _separated(scene: Scene) -> np.ndarray:
    """The scene's dynamic bodies as a sample starts them (built, overlaps removed, set down)."""
    from ipe_ros.engine.sampling.rollout import separated_world

    inputs = draw_sample_inputs(scene, ModelConfig(object_noise=False), np.random.default_rng(0))
    return simulation.read_poses(separated_world(scene, preset("default"), inputs))[0]


def test_heights_that_are_estimates_are_set_down_onto_their_supports_from_the_bottom_up():
    # a detector's heights: the bottom block 2 mm above the floor, the middle one 3 mm into it (the
    # overlap is removed first), the top one turned across it and 4 mm above; a block beside the stack
    # touching it must not hold it up
    scene = replace(floor_scene(block("a", 0, 0, 0.102), block("b", 0.01, 0, 0.297),
                                Box(name="c", extents_m=(0.6, 0.1, 0.2), position_m=(0.0, 0.0, 0.504),
                                    orientation_xyzw=(0, 0, math.sin(0.35), math.cos(0.35)), friction=0.9,
                                    restitution=0.0, mass_kg=1.0),
                                block("beside", 0.2, 0, 0.1)), set_down_m=0.01)
    z = _separated(scene)[:, 2]
    assert z == pytest.approx([0.1, 0.3, 0.5, 0.1], abs=2e-5)
    as_given = _separated(replace(scene, set_down_m=0.0))[:, 2]
    assert as_given[2] - as_given[1] > 0.202  # as given, the top block hovers (the overlap below removed)


def test_set_down_leaves_a_body_farther_up_than_asked_and_works_for_any_shape():
    from ipe_ros.engine import Body, Cylinder

    lying = Body(name="can", shape=Cylinder(radius_m=0.05, length_m=0.3), position_m=(0.0, 0.0, 0.2553),
                 orientation_xyzw=(math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)), friction=0.9,
                 restitution=0.0, mass_kg=1.0)
    high = block("high", 1.0, 0.0, 0.13)  # 3 cm up: a thrown box, not an estimate
    z = _separated(replace(floor_scene(block("a", 0, 0, 0.1), lying, high), set_down_m=0.01))[:, 2]
    assert z == pytest.approx([0.1, 0.25, 0.13], abs=2e-5)


def test_a_tower_with_estimated_heights_stands_only_when_set_down():
    # each block 2 mm above the one below (a detector's heights): dropped, the near-balanced top (its
    # blocks' centre of mass 3 mm inside the bottom block's edge) is knocked over; set down, it
    # stands as the true tower does
    offsets = [0.0, 0.05, 0.1, 0.14]
    truth = floor_scene(*(block(f"b{i}", x, 0, 0.1 + 0.2 * i) for i, x in enumerate(offsets)))
    estimated = floor_scene(*(block(f"b{i}", x, 0, 0.1 + 0.2 * i + 0.002 * (i + 1)) for i, x in enumerate(offsets)))
    model, queries = ModelConfig(samples=1, object_noise=False), QuerySpec(queries=DEFAULT_QUERIES)
    assert predict(truth, Request(model=model, settings=preset("default"), query=queries, budget_s=None)).any_fall_probability == 0
    assert predict(estimated, Request(model=model, settings=preset("default"), query=queries, budget_s=None)).any_fall_probability == 1
    assert predict(replace(estimated, set_down_m=0.01),
                   Request(model=model, settings=preset("default"), query=queries, budget_s=None)).any_fall_probability == 0


def test_thin_boxes_on_the_direct_solver_are_built_in_multibodies_which_hold_their_friction():
    """Plain rigid bodies let friction creep: the zoo's plates 2026/3 tips its plate4 onto an edge,
    where in plain rigid bodies it slides past its fall threshold in every sample; in `paper`'s
    multibodies, and in `default`'s now, it rests in about half (k = 64: 0.50, 0.41 and 1.00).
    Samples 1 and 7 rest in `paper`."""
    from ipe_ros.engine.sampling import rollout
    from ipe_ros.engine.predict import make_tasks
    from ipe_ros.engine.scene.zoo import scene_zoo, zoo_sigma_m

    plates = scene_zoo(2026, 4, ("plates",))[3]
    default = preset("default")
    # plain rigid bodies on the direct solver, as `default` built every scene before
    plain = default.changed("default", solver={"multibodies_from_aspect": None, "direct_solver_min_restitution": 0.0})
    masses = [b.mass_kg for b in plates.dynamic_objects]
    assert not simulation.in_plain_rigid_bodies(plates, default, masses)
    assert simulation.in_plain_rigid_bodies(plates, plain, masses)
    # both decide it: a thin box, and the direct solver (any bounce), which alone holds friction
    still = replace(plates, objects=tuple(replace(b, restitution=0.0) for b in plates.objects))
    assert simulation.in_plain_rigid_bodies(still, default, masses)
    thick = floor_scene(*(replace(block(f"b{i}", 0.0, 0.0, 0.05 + 0.1 * i), restitution=0.5) for i in range(2)))
    assert simulation.uses_direct_solver(thick, default, [1.0, 1.0])
    assert simulation.in_plain_rigid_bodies(thick, default, [1.0, 1.0])

    model, query = ModelConfig(sigma_m=zoo_sigma_m(plates), samples=8), QuerySpec(queries=frozenset({"fall"}))
    for i in (1, 7):
        fell = {}
        for name, settings in (("paper", preset("paper")), ("default", default), ("plain", plain)):
            outcome = rollout.run_sample(make_tasks(plates, model, settings, query, seed=3)[i])
            assert outcome.ok, outcome.error
            fell[name] = bool(outcome.rollouts[0].fallen[4])
        assert fell == {"paper": False, "default": False, "plain": True}, i


def test_the_direct_solver_runs_only_where_a_bounce_gives_back_a_share_of_an_impact_worth_its_cost():
    """A chain of dominoes at restitution 0.05 on a 0.1 floor (0.005 together) took 2.7x the time on
    the direct solver, with the same answers: `default` solves such scenes with the sequential-impulse
    solver from a combined restitution of 0.1 down, unless a body is thrown in at 1 m/s or more; `paper`
    keeps the direct one for any bounce, and thin boxes keep it in `default` too (it holds their
    friction)."""
    from ipe_ros.engine.scene.zoo import scene_zoo

    default, paper = preset("default"), preset("paper")
    dominoes, bouncy, plates = (scene_zoo(2026, 1, (family,))[0] for family in ("dominoes", "bouncy", "plates"))
    for scene in (dominoes, bouncy, plates):
        assert simulation.uses_direct_solver(scene, paper, [b.mass_kg for b in scene.dynamic_objects])
    assert simulation.combined_restitution(dominoes) == pytest.approx(0.005)
    assert not simulation.uses_direct_solver(dominoes, default, [b.mass_kg for b in dominoes.dynamic_objects])
    assert simulation.combined_restitution(bouncy) >= 0.1
    assert simulation.uses_direct_solver(bouncy, default, [b.mass_kg for b in bouncy.dynamic_objects])
    assert simulation.combined_restitution(plates) < 0.1
    assert simulation.uses_direct_solver(plates, default, [b.mass_kg for b in plates.dynamic_objects])
    # a body thrown in keeps it: launch 2027/1's ball at 3.8 m/s, 0.05 together; not a domino nudged at 0.4
    launch = scene_zoo(2027, 2, ("launch",))[1]
    assert simulation.combined_restitution(launch) < 0.1 and default.solver.direct_solver_from_speed_m_s == 1.0
    assert simulation.uses_direct_solver(launch, default, [b.mass_kg for b in launch.dynamic_objects])
    world = simulation.build_world(dominoes, np.array([b.position_m for b in dominoes.dynamic_objects]),
                                   np.array([b.mass_kg for b in dominoes.dynamic_objects]), default)
    assert world.direct_solver is False
