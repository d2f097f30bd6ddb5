"""The SI's Bayesian vision system: renderer, likelihood, sampler and the IPE fed from it.

Statistical checks use fixed seeds and state their tolerances."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipe_ros.engine import ConfigError, ModelConfig, QuerySpec, WorkerPool, load_scenes, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.vision import VisionSettings, default_cameras, effective_sample_size, perceive
from ipe_ros.engine.vision.camera import look_at
from ipe_ros.engine.vision.likelihood import blur, log_likelihood
from ipe_ros.engine.vision.mcmc import ImageModel, run_chain
from ipe_ros.engine.vision.render import BACKGROUND_GREY, render, render_views, scene_mesh
from ipe_ros.engine.vision.tinyrenderer import grey_with_pybullet
from tests.helpers import block, floor_scene

TOWER = load_scenes("ipe_ros/data/example_tower.json")[0]
SMALL = VisionSettings(resolution_px=64, chain_samples=300, burn_in=50)


def _model(scene, settings, cameras=None):
    cameras = cameras or default_cameras(scene, resolution_px=settings.resolution_px)
    mesh = scene_mesh(scene)
    return ImageModel(mesh, cameras, render_views(mesh, cameras), settings), mesh


def test_our_renderer_draws_the_silhouettes_pybullets_software_renderer_draws():
    for camera in default_cameras(TOWER, resolution_px=128):
        _, theirs = grey_with_pybullet(TOWER, camera)
        ours = render(scene_mesh(TOWER), camera) != BACKGROUND_GREY
        iou = (ours & theirs).sum() / (ours | theirs).sum()
        assert iou >= 0.85, iou  # edge pixels differ (pixel-centre conventions); measured 0.90-0.96 at 256 px
        assert abs(int(ours.sum()) - int(theirs.sum())) <= 0.05 * theirs.sum()


def test_the_true_state_has_the_highest_likelihood_among_shifted_copies():
    model, mesh = _model(TOWER, VisionSettings(resolution_px=128))
    truth = model.log_likelihood(mesh.positions_m)
    assert truth == 0.0  # the evidence is the true state's own rendering
    for body in (0, 4, 9):
        for shift in ((0.02, 0), (-0.05, 0), (0, 0.03), (0.1, -0.1)):
            moved = mesh.positions_m.copy()
            moved[body, :2] += shift
            assert model.log_likelihood(moved) < truth, (body, shift)


def test_a_block_hidden_from_every_view_is_unconstrained():
    wall = block("wall", 0.0, 0.0, 0.5, extents=(1.0, 0.2, 1.0))
    hidden = block("hidden", 0.0, 0.4, 0.1, extents=(0.2, 0.2, 0.2))
    scene = floor_scene(wall, hidden)
    # three views from -y, 10 degrees apart, low: the wall hides the small block from all of them
    cameras = tuple(look_at((6 * math.sin(a), -6 * math.cos(a), 0.3), (0.0, 0.0, 0.3), 128, 128, math.radians(40))
                    for a in np.radians([-10, 0, 10]))
    model, mesh = _model(scene, VisionSettings(resolution_px=128), cameras)
    truth = model.log_likelihood(mesh.positions_m)
    moved = mesh.positions_m.copy()
    moved[1, :2] += (0.05, 0.05)
    assert model.log_likelihood(moved) == truth  # nothing it could look like changes
    moved = mesh.positions_m.copy()
    moved[0, :2] += (0.05, 0.0)
    assert model.log_likelihood(moved) < truth  # while the wall is seen


def test_incremental_rendering_equals_rendering_from_scratch():
    model, mesh = _model(TOWER, VisionSettings(resolution_px=96))
    state = mesh.positions_m.copy()
    model.start(state)
    rng = np.random.default_rng(3)
    for step in range(60):
        body = int(rng.integers(0, 10))
        moved = state[body].copy()
        moved[:2] += 0.05 * rng.standard_normal(2)
        candidate = model.propose(body, moved)
        trial = state.copy()
        trial[body] = moved
        assert candidate == pytest.approx(model.log_likelihood(trial), abs=1e-9)
        if step % 2 == 0:
            model.accept()
            state = trial


@pytest.mark.slow
def test_one_block_posterior_matches_the_blur_limited_laplace_approximation():
    """For one visible block the log-likelihood is locally quadratic in its offset d:
    -d' H d / 2 with H = sum over pixels of J J' / sd^2, J the blurred image's derivative. The chain's
    SD must match sqrt(diag(H^-1)) within 20% (seed 11, 6000 samples: ESS ~ 500, so the SD's own
    sampling error is ~3%)."""
    scene = floor_scene(block("cube", 0.0, 0.0, 0.1, extents=(0.2, 0.2, 0.2)))
    # a wide likelihood SD: the posterior spans several pixels, where the quadratic picture holds
    settings = VisionSettings(resolution_px=96, chain_samples=6000, burn_in=500, proposal_sd_m=0.03,
                              likelihood_sd_grey=2048.0)
    model, mesh = _model(scene, settings)
    eps = 0.01

    def blurred(offset):
        moved = mesh.positions_m.copy()
        moved[0, :2] += offset
        return blur(np.stack([render(mesh, c, moved) for c in model.cameras]), settings.blur_at_resolution_px)
    jx = (blurred((eps, 0)) - blurred((-eps, 0))) / (2 * eps)
    jy = (blurred((0, eps)) - blurred((0, -eps))) / (2 * eps)
    sd = settings.sd_at_resolution_grey
    h = np.array([[np.sum(jx * jx), np.sum(jx * jy)], [np.sum(jx * jy), np.sum(jy * jy)]]) / sd ** 2
    expected = np.sqrt(np.diag(np.linalg.inv(h)))
    chain = run_chain(model, mesh.positions_m, 1, settings, np.random.default_rng(11))
    observed = chain.positions_m[:, 0, :2].std(axis=0)
    assert chain.effective_sample_size > 200
    np.testing.assert_allclose(observed, expected, rtol=0.2)
    assert 0.005 < expected.min()  # a posterior wide enough to be sampled, not a point


def test_the_effective_sample_size_of_known_chains():
    rng = np.random.default_rng(5)
    assert effective_sample_size(rng.standard_normal(4000)) == pytest.approx(4000, rel=0.15)
    ar = np.zeros(20000)
    for t in range(1, len(ar)):  # AR(1) with rho = 0.9: ESS = n (1 - rho) / (1 + rho)
        ar[t] = 0.9 * ar[t - 1] + rng.standard_normal()
    assert effective_sample_size(ar) == pytest.approx(20000 * 0.1 / 1.9, rel=0.25)
    assert effective_sample_size(np.ones(100)) == 1.0


@pytest.mark.slow
def test_chains_and_vision_predictions_are_determined_by_the_seed_whatever_the_workers():
    first = perceive(TOWER, 4, SMALL, np.random.default_rng(9), check_ess=False)
    again = perceive(TOWER, 4, SMALL, np.random.default_rng(9), check_ess=False)
    np.testing.assert_array_equal(first.chain.positions_m, again.chain.positions_m)
    model = ModelConfig(samples=4, perception="vision", vision=VisionSettings(resolution_px=64, chain_samples=600,
                                                                              burn_in=100))
    query = QuerySpec(queries=frozenset({"fall", "direction"}))
    alone = predict(TOWER, Request(model=model, settings=preset("default"), query=query, seed=2, budget_s=None))
    with WorkerPool(2) as pool:
        pooled = predict(TOWER, Request(model=model, settings=preset("default"), query=query, seed=2, budget_s=None),
                         Context(map_fn=pool.map))
    strip = lambda p: {k: v for k, v in p.to_dict().items() if k != "wall_s"}  # noqa: E731
    assert strip(alone) == strip(pooled)
    perception = alone.request["perception"]
    assert perception["kind"] == "vision" and 0 < perception["acceptance_rate"] < 1
    assert perception["effective_sample_size"] >= 2 and alone.samples == 4


def test_a_chain_too_short_for_k_is_refused_by_name():
    with pytest.raises(ConfigError) as refused:
        perceive(TOWER, 48, SMALL, np.random.default_rng(0))
    assert str(refused.value).startswith("vision.chain_samples: the chain of 300 samples (250 after burn-in) gave an "
                                         "effective sample size of ")
    assert str(refused.value).endswith("too few for 48 roughly independent scene samples (needs >= 24); lengthen "
                                       "the chain or ask for fewer samples")


def test_vision_settings_refuse_bad_values_by_name():
    with pytest.raises(ConfigError, match=r"^vision.burn_in: must be an integer in \[0, chain_samples\), got 500$"):
        VisionSettings(chain_samples=500, burn_in=500)
    with pytest.raises(ConfigError, match=r"^perception: must be one of gaussian, vision, depth, got 'lidar'$"):
        ModelConfig(perception="lidar")


def test_the_likelihood_scales_with_resolution_to_the_same_evidence():
    """At 128 px with blur and SD scaled, shifted blocks cost about what they cost at 256 px (within
    25%: edges fall on different pixels)."""
    costs = []
    for resolution in (128, 256):
        model, mesh = _model(TOWER, VisionSettings(resolution_px=resolution))
        total = 0.0
        for body in (2, 5, 8):
            for shift in ((0.04, 0.0), (0.0, -0.04)):
                moved = mesh.positions_m.copy()
                moved[body, :2] += shift
                total += model.log_likelihood(moved)
        costs.append(total)
    assert costs[0] == pytest.approx(costs[1], rel=0.25)
    assert log_likelihood(np.zeros((2, 2)), np.ones((2, 2)), 1.0) == -2.0


@pytest.mark.slow
def test_ipe_predict_with_vision_perception_and_its_recording(tmp_path):
    import json
    import subprocess
    import sys

    from rerun.chunk import RrdReader

    rrd = tmp_path / "vision.rrd"
    run = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "predict", "ipe_ros/data/example_tower.json", "--json",
                          "--perception", "vision", "--samples", "4", "--chain-samples", "600",
                          "--vision-resolution", "48", "--workers", "0", "--vision-rrd", str(rrd)],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    answer = json.loads(run.stdout)
    assert answer["request"]["perception"]["kind"] == "vision" and answer["samples"] == 4
    entities = {c.entity_path for c in RrdReader(rrd).stream().to_chunks()}
    assert {"/vision/views/0", "/vision/views/2", "/world/vision/block0", "/vision/chain/acceptance",
            "/vision/chain/log_likelihood"} <= entities
    wrong = subprocess.run([sys.executable, "-m", "ipe_ros.cli", "predict", "ipe_ros/data/example_tower.json",
                            "--chain-samples", "600"], capture_output=True, text=True, timeout=120)
    assert wrong.returncode == 2
    assert wrong.stderr.strip() == ("ipe: error: --perception: --chain-samples, --vision-resolution and --vision-rrd "
                                    "need --perception vision")
