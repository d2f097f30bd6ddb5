"""Validation against the authors' stimuli and ground truth (skipped when ../shared is absent).

Figures printed here (run with -s) are the ones quoted in README.
"""


import numpy as np
import pytest

from ipe_ros.analysis import paper_data
from ipe_ros.engine import ModelConfig, QuerySpec, load_scenes, predict, preset
from ipe_ros.engine import Context, Request

from .conftest import shared_file

#: the authors' 60 towers and more at paper settings
pytestmark = pytest.mark.slow

FALL = QuerySpec(queries=frozenset({"fall"}))
#: the authors' later code counts a block as moved when its 3-D displacement exceeds a quarter short side
MOVED_M = 0.05


def authors_outcomes(dataset: str) -> dict[str, tuple[int, int]]:
    """stimulus -> (blocks that fell, stood) under the authors' simulation; skips without the data."""
    outcomes = paper_data.authors_outcomes(dataset, shared_file(paper_data.OUTCOMES_FILE).parent)
    return {name: (o.blocks_fell, int(o.stable)) for name, o in outcomes.items()}


@pytest.mark.parametrize("preset_name", ["default", "paper"])
def test_ground_truth_model_agrees_with_the_authors_on_exp1_towers(pool, preset_name):
    scenes = load_scenes(shared_file("willitfall.csv"))
    truth = authors_outcomes("stability_original_fall")
    agree, ours_moved, theirs_moved = 0, [], []
    for scene in scenes:
        p = predict(scene, Request(model=ModelConfig(), settings=preset(preset_name), query=FALL, budget_s=None),
                    Context(map_fn=pool.map))
        assert p.deterministic and p.samples == 1 and p.failed_samples == 0
        outcome = p.outcomes[0]
        moved = int((np.linalg.norm(outcome.rollouts[0].final_positions_m - outcome.initial_positions_m, axis=1)
                     > MOVED_M).sum())
        nfell, stable = truth[scene.name]
        agree += (p.fall_fraction == 0) == bool(stable)
        ours_moved.append(moved)
        theirs_moved.append(nfell)
    r = float(np.corrcoef(ours_moved, theirs_moved)[0, 1])
    print(f"\n[{preset_name}] ground truth: stable/unstable agrees on {agree}/60 towers; "
          f"moved-block count r = {r:.3f}")
    assert agree >= 57
    assert r >= 0.85


@pytest.mark.parametrize("preset_name, rest_threshold", [("default", None), ("fine", None), ("fine", 1.0)])
def test_early_termination_waits_out_a_slow_tip(preset_name, rest_threshold):
    """tower_01143: the authors' simulation topples one block, which starts to tip slowly while
    another block is still settling from the start. Early termination must see that block's
    motion grow (box by box; the liveliest box alone ended the default rollout at 0.35 s), however
    loosely "at rest" is read (a noise floor relative to the rest thresholds hid the tip, at
    1.4 mm/s, once they were 0.2 sizes/s)."""
    (scene,) = load_scenes(shared_file("willitfall.csv"), towers=["tower_01143_0000000000"])
    assert authors_outcomes("stability_original_fall")[scene.name][1] == 0  # the authors': falls
    settings = preset(preset_name)
    if rest_threshold is not None:
        settings = settings.changed(early_stop={"speed_sizes_per_s": rest_threshold, "angular_rad_s": rest_threshold})
    p = predict(scene, Request(model=ModelConfig(), settings=settings, query=FALL, budget_s=None))
    rollout = p.outcomes[0].rollouts[0]
    assert rollout.fallen.tolist() == [False] * 8 + [True, False]
    assert rollout.simulated_s > 1.0


def test_ipe_finds_towers_that_are_stable_but_look_likely_to_fall(pool):
    """The paper's 'delicately balanced' illusion: ground truth stable, IPE (sigma = 0.2 sides) says fall."""
    truth = authors_outcomes("stability_original_fall")
    stable = [name for name, (_n, s) in truth.items() if s == 1]
    scenes = load_scenes(shared_file("willitfall.csv"), towers=stable[:12])
    model = ModelConfig(sigma_m=0.04, samples=16)
    illusions = []
    for scene in scenes:
        assert predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=FALL, budget_s=None)).fall_fraction == 0.0
        p = predict(scene, Request(model=model, settings=preset("default"), query=FALL, seed=0, budget_s=None),
                    Context(map_fn=pool.map))
        if p.fall_fraction_ci95[0] > 0.1:  # even the interval's lower end says blocks fall
            illusions.append((scene.name, round(p.fall_fraction, 3)))
    print(f"\nstable towers the IPE expects to fall: {illusions}")
    assert len(illusions) >= 1


def test_mass_state_pairs_get_different_predictions(pool):
    """willitfall-mass.csv at ratio 10: same geometry, complementary heavy masks -> different answers."""
    scenes = load_scenes(shared_file("willitfall-mass.csv"))
    by_geometry: dict[str, list] = {}
    for scene in scenes:
        name, ratio = scene.name.split("@ratio=")
        if ratio == "10":
            by_geometry.setdefault(name.rsplit("_", 1)[0], []).append(scene)
    pairs = [v for v in by_geometry.values() if len(v) == 2][:4]
    assert len(pairs) == 4
    model = ModelConfig(sigma_m=0.04, samples=16)
    insensitive = ModelConfig(sigma_m=0.04, samples=16, mu=1.0)
    differences = []
    for a, b in pairs:
        pa, pb = (predict(s, Request(model=model, settings=preset("default"), query=FALL, seed=4, budget_s=None),
                          Context(map_fn=pool.map)) for s in (a, b))
        differences.append(abs(pa.fall_fraction - pb.fall_fraction))
        # the mass-insensitive model (mu = 1) cannot tell the pair apart: same seeds, same geometry
        qa, qb = (predict(s,
                          Request(model=insensitive, settings=preset("default"), query=FALL, seed=4, budget_s=None),
                          Context(map_fn=pool.map)) for s in (a, b))
        assert qa.fall_fraction == qb.fall_fraction
    print(f"\nwithin-pair |delta fall fraction| at ratio 10: {np.round(differences, 3).tolist()}")
    assert np.mean(differences) > 0.05
    assert sum(d > 0.05 for d in differences) >= 2


@pytest.mark.parametrize("tower", ["tower_00500_0000000000", "tower_01452_0000000000"])
def test_the_self_checks_reference_waits_out_a_slow_tip_as_paper_does(tower):
    """The self-check's reference ends rollouts at rest. Read as loosely as `default` reads it (0.4
    sizes/s), `paper`'s physics was called at rest on these two towers before a block tipped over,
    and the checked ground truth, escalated to that reference, said they stand (the authors: a block
    falls)."""
    from ipe_ros.engine.checking.fidelity import reference_settings

    (scene,) = load_scenes(shared_file("willitfall.csv"), towers=[tower])
    assert authors_outcomes("stability_original_fall")[scene.name][1] == 0  # the authors': falls
    for settings in (reference_settings(), preset("paper")):
        assert predict(scene, Request(model=ModelConfig(), settings=settings, query=FALL, check=None, budget_s=None)).fall_fraction == 0.1, settings.name
    assert predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=FALL, budget_s=None)).fall_fraction == 0.1
