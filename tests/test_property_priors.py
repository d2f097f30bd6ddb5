"""Uncertain masses, frictions and restitutions inside a prediction (issue 72, item 1): the scene's
priors and the model-wide spread, each sample drawing its own values, and the property that moves
the answer most."""

import dataclasses
import json
import math

import jsonschema
import numpy as np
import pytest

from ipe_ros.engine import predict
from ipe_ros.engine import Context, Request
from ipe_ros.engine.errors import ConfigError, SceneError
from ipe_ros.engine.request import build_request
from ipe_ros.engine.sampling.perturb import draw_sample, dynamic_masses, is_deterministic, sample_properties
from ipe_ros.engine.scene.format import scene_from_dict, scene_to_dict
from ipe_ros.engine.scene.schema import SCHEMA_PATH
from ipe_ros.engine.scene.properties import LogNormal, PropertySpread, Uniform, without_priors

G = 9.81
FRICTION = (0.3, 0.7)  # the box's friction prior; the floor's is 1.0 (pybullet multiplies the two)
SPEED_M_S = 2.0


def _scene(box_fields: dict | None = None, support_fields: dict | None = None, *, objects=None) -> dict:
    box = {"name": "box", "shape": {"type": "box", "extents_m": [0.1, 0.1, 0.05]}, "position_m": [0.0, 0.0, 0.025],
           "orientation_xyzw": [0, 0, 0, 1], "friction": 0.5, "restitution": 0.0, "mass_kg": 1.0,
           "linear_velocity_m_s": [SPEED_M_S, 0.0, 0.0], **(box_fields or {})}
    support = {"type": "floor", "height_m": 0.0, "friction": 1.0, "restitution": 0.0, **(support_fields or {})}
    return {"format": "ipe_ros.scene/2", "name": "slide", "gravity_m_s2": [0, 0, -G], "support": support,
            "objects": objects or [box]}


def _request(samples: int, **inputs):
    return build_request(samples=samples, sigma_m=0.0, queries=("far",), self_check=False, **inputs)


# ---- the scene format ------------------------------------------------------------------------


def test_priors_read_and_written_back_as_given():
    data = _scene({"mass_prior": {"log_sd": 0.5}, "friction_prior": {"uniform": [0.3, 0.7]},
                   "restitution_prior": {"uniform": [0.0, 0.4]}},
                  {"friction_prior": {"log_uniform": [0.2, 2.0]}})
    scene = scene_from_dict(data)
    assert scene.objects[0].priors == (("mass_kg", LogNormal(1.0, 0.5)), ("friction", Uniform(0.3, 0.7)),
                                       ("restitution", Uniform(0.0, 0.4)))
    again = scene_from_dict(json.loads(json.dumps(scene_to_dict(scene))))
    assert again == scene
    # and the published JSON Schema accepts what the reader does
    jsonschema.Draft202012Validator(json.loads(SCHEMA_PATH.read_text())).validate(scene_to_dict(scene))


def test_a_log_normal_mass_centres_on_the_mass_a_density_gives():
    data = _scene({"mass_kg": None, "density_kg_m3": 400.0, "mass_prior": {"log_sd": 0.2}})
    del data["objects"][0]["mass_kg"]
    (prior,) = [p for prop, p in scene_from_dict(data).objects[0].priors if prop == "mass_kg"]
    assert prior == LogNormal(pytest.approx(400.0 * 0.1 * 0.1 * 0.05), 0.2)


@pytest.mark.parametrize("fields, where, message", [
    ({"friction_prior": {"log_sd": 9}}, "objects[0].friction_prior.log_sd", "must be a number in (0, 5], got 9"),
    ({"restitution_prior": {"log_sd": 0.3}}, "objects[0].restitution_prior",
     "a restitution is bounded by 1: give it a uniform prior, not log_sd"),
    ({"friction_prior": {"uniform": [0.5, 20]}}, "objects[0].friction_prior.uniform",
     "must satisfy 0 <= LOW < HIGH <= 10 for friction (physical bounds), got [0.5, 20]"),
    ({"static": True, "linear_velocity_m_s": [0, 0, 0], "mass_prior": {"log_sd": 0.3}}, "objects[0].mass_prior",
     "a static object does not move, so its mass plays no part; remove the prior"),
    ({"size_prior": {"log_sd": 0.3}}, "objects[0].size_prior", "unknown field"),
])
def test_a_bad_prior_is_refused_naming_its_field(fields, where, message):
    data = _scene(fields)
    if fields.get("static"):  # a scene needs a dynamic object besides the static one
        data["objects"].append(dict(_scene()["objects"][0], name="other", position_m=[1.0, 0.0, 0.025]))
    with pytest.raises(SceneError) as caught:
        scene_from_dict(data)
    assert caught.value.field == where
    assert message in str(caught.value)


def test_the_support_takes_surface_priors_only():
    with pytest.raises(SceneError) as caught:
        scene_from_dict(_scene(support_fields={"mass_prior": {"log_sd": 0.3}}))
    assert caught.value.field == "support.mass_prior"


# ---- drawing ---------------------------------------------------------------------------------


def test_exact_scenes_draw_nothing_and_stay_deterministic():
    scene = scene_from_dict(_scene())
    request = _request(4)
    assert sample_properties(scene, request.model) == ()
    assert is_deterministic(scene, request.model)
    assert request.model.property_spread is None  # so a stored result's key is what it always was
    assert "property_influence" not in predict(scene,
                                               Request(model=request.model, settings=request.settings,
                                                       query=request.query, budget_s=None)).to_dict()


def test_each_value_is_a_function_of_the_sample_seed_and_its_owner_only():
    # keyed by the owner's name and the property: a robot question's variant that removes another
    # object (or a scene listing its objects in another order) draws the same values for the rest
    data = _scene({"friction_prior": {"uniform": list(FRICTION)}})
    other = dict(_scene()["objects"][0], name="other", position_m=[0.0, 1.0, 0.025])
    both = scene_from_dict(_scene(objects=[other, data["objects"][0]]))
    alone = scene_from_dict(data)
    model = _request(4).model
    seeds = np.random.SeedSequence(7).spawn(4)
    drawn_both = [dict(draw_sample(both, model, s)[1].properties) for s in seeds]
    drawn_alone = [dict(draw_sample(alone, model, s)[1].properties) for s in seeds]
    assert [d["box.friction"] for d in drawn_both] == [d["box.friction"] for d in drawn_alone]
    assert "other.friction" not in drawn_both[0]  # its friction is exact
    assert len({d["box.friction"] for d in drawn_alone}) == 4
    # the positions and push drawn on the sample's main stream are those of the exact scene
    exact = scene_from_dict(_scene())
    for s in seeds:
        assert np.array_equal(draw_sample(alone, model, s)[1].positions_m, draw_sample(exact, model, s)[1].positions_m)


def test_the_ground_truth_takes_the_scene_exactly_as_given():
    scene = scene_from_dict(_scene({"friction_prior": {"uniform": list(FRICTION)}}))
    truth = build_request(ground_truth=True, mass_log_sd=0.5)
    assert sample_properties(scene, truth.model) == ()
    assert is_deterministic(scene, truth.model)
    # a model's own spread, given explicitly, still applies beside the scene taken as given
    spread = dataclasses.replace(truth.model, property_spread=PropertySpread(friction_log_sd=0.2))
    assert [(o, p) for o, p, _ in sample_properties(scene, spread)] == [("box", "friction"), ("support", "friction")]
    assert without_priors(scene).objects[0].priors == ()


def test_the_model_wide_spread_reaches_every_surface_and_dynamic_mass():
    scene = scene_from_dict(_scene({"restitution": 0.95}))
    model = _request(4, mass_log_sd=0.3, friction_log_sd=0.2, restitution_half_width=0.1).model
    uncertain = {(o, p): prior for o, p, prior in sample_properties(scene, model)}
    assert uncertain == {("box", "mass_kg"): LogNormal(1.0, 0.3), ("box", "friction"): LogNormal(0.5, 0.2),
                         ("box", "restitution"): Uniform(0.85, 1.0),  # cut at 1
                         ("support", "friction"): LogNormal(1.0, 0.2), ("support", "restitution"): Uniform(0.0, 0.1)}
    assert not is_deterministic(scene, model)
    with pytest.raises(ConfigError) as caught:
        build_request(restitution_half_width=1.5)
    assert str(caught.value) == "restitution_half_width: must be a number in [0, 1] (0: off), got 1.5"


def test_under_mu_a_drawn_mass_scales_the_model_mass():
    data = _scene({"group": "heavy", "mass_prior": {"uniform": [2.0, 4.0]}})
    scene = scene_from_dict(data)
    plain, heavy = _request(2).model, _request(2, mu=10.0).model
    seed = np.random.SeedSequence(3)
    _, free = draw_sample(scene, plain, seed)
    _, scaled = draw_sample(scene, heavy, seed)
    drawn = dict(free.properties)["box.mass_kg"]
    assert free.masses_kg[0] == pytest.approx(drawn)
    model_mass = dynamic_masses(scene, 10.0)[0]  # mu x the model's light density x the volume
    assert scaled.masses_kg[0] == pytest.approx(model_mass * drawn / 1.0)


# ---- what the samples say --------------------------------------------------------------------


def test_each_sample_slides_its_own_friction_s_distance():
    """Coulomb friction stops a slide at v^2 / (2 mu g), mu the product of the two surfaces' values:
    each sample's travel follows the friction it drew, within 2% (the mechanics suite's tolerance for
    a slide in every preset)."""
    scene = scene_from_dict(_scene({"friction_prior": {"uniform": list(FRICTION)}}))
    request = _request(12)
    prediction = predict(scene,
                         Request(model=request.model, settings=request.settings, query=request.query, seed=4,
                                 budget_s=None))
    assert prediction.samples == 12 and not prediction.deterministic
    for outcome in prediction.outcomes:
        mu = dict(outcome.properties)["box.friction"] * 1.0
        travel = np.linalg.norm(outcome.rollouts[0].final_positions_m[0, :2] - outcome.initial_positions_m[0, :2])
        assert travel == pytest.approx(SPEED_M_S ** 2 / (2 * mu * G), rel=0.02), mu


def test_the_influence_names_friction_not_a_mass_that_cannot_matter():
    """A slide's length does not depend on the mass (Coulomb), so the mass's difference must be noise
    (within 3 standard errors) and the friction's large: below the median friction (0.5) the box
    slides 0.52 m on average, above it 0.34 m (v^2 / (2 g) E[1/mu] over each half of the prior)."""
    scene = scene_from_dict(_scene({"friction_prior": {"uniform": list(FRICTION)}, "mass_prior": {"log_sd": 0.7}}))
    request = build_request(samples=32, sigma_m=0.0, queries=("final_pose",), self_check=False)
    answer = predict(scene,
                     Request(model=request.model, settings=request.settings, query=request.query, seed=9,
                             budget_s=None)).to_dict()
    first, second = answer["property_influence"]
    assert first["property"] == "box.friction" and first["object"] == "box" and first["outcome"] == "travel_m"
    assert first["below_median"] > first["above_median"] and first["difference"] == pytest.approx(-0.18, abs=0.06)
    assert second["property"] == "box.mass_kg"
    assert abs(second["difference"]) < 3 * second["difference_se"] + 1e-3
    assert math.isclose(first["median"], np.median([dict(o.properties)["box.friction"]
                                                    for o in predict(scene,
                                                                     Request(model=request.model,
                                                                             settings=request.settings,
                                                                             query=request.query, seed=9,
                                                                             budget_s=None)).outcomes]))


def test_the_fall_probability_follows_the_friction_prior():
    """A box launched at 1.8 m/s, 0.4 m from a table's edge, goes over it where mu < v^2 / (2 g 0.4)
    = 0.41 (its centre past the edge; it then tips off): P(fall) is the prior's mass below that,
    (0.41 - 0.2) / 0.6 = 0.36, within 3 binomial SDs for 48 samples (0.21)."""
    data = _scene({"friction_prior": {"uniform": [0.2, 0.8]}, "position_m": [0.1, 0.0, 0.025],
                   "linear_velocity_m_s": [1.8, 0.0, 0.0]},
                  {"type": "table", "top_height_m": 0.0, "size_m": [1.0, 1.0], "center_xy_m": [0.0, 0.0],
                   "thickness_m": 0.05, "floor_z_m": -0.75, "obstacles": []})
    del data["support"]["height_m"]
    scene = scene_from_dict(data)
    request = build_request(samples=48, sigma_m=0.0, queries=("fall",), self_check=False)
    prediction = predict(scene,
                         Request(model=request.model, settings=request.settings, query=request.query, seed=2,
                                 budget_s=None))
    threshold = 1.8 ** 2 / (2 * G * 0.4)
    expected = (threshold - 0.2) / 0.6
    assert prediction.object_fall_probability["box"] == pytest.approx(expected, abs=3 * math.sqrt(
        expected * (1 - expected) / 48))
    # and sample by sample: every box that fell drew a friction below the threshold's neighbourhood
    for outcome in prediction.outcomes:
        mu = dict(outcome.properties)["box.friction"]
        if abs(mu - threshold) > 0.05:
            assert bool(outcome.rollouts[0].fallen[0]) == (mu < threshold), mu
    (top, *_) = prediction.property_influence
    assert top["property"] == "box.friction" and top["difference"] < -0.5


def test_the_draws_do_not_depend_on_the_worker_count(pool):
    scene = scene_from_dict(_scene({"friction_prior": {"uniform": list(FRICTION)}, "mass_prior": {"log_sd": 0.3}}))
    request = _request(6, restitution_half_width=0.1)
    serial = predict(scene,
                     Request(model=request.model, settings=request.settings, query=request.query, seed=3,
                             budget_s=None))
    pooled = predict(scene,
                     Request(model=request.model, settings=request.settings, query=request.query, seed=3,
                             budget_s=None),
                     Context(map_fn=pool.map))
    assert [o.properties for o in serial.outcomes] == [o.properties for o in pooled.outcomes]
    assert [o.properties[0][0] for o in serial.outcomes] == ["box.mass_kg"] * 6
    assert serial.property_influence == pooled.property_influence
