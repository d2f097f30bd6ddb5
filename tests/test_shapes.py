"""Bodies of every shape: geometry, the /2 scene format, validation, and what the physics does with them."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from ipe_ros.engine import (Body, BoxShape, Capsule, ConvexHull, Cylinder, Floor, ModelConfig,
                            QuerySpec, Scene, SceneError, Sphere, load_scenes, predict, preset, scene_from_dict,
                            scene_to_dict)
from ipe_ros.engine import Request
from ipe_ros.engine.scene import shapes
from ipe_ros.engine.scene.catalogue import capped_tower, cone, l_bracket, wedge
from ipe_ros.engine.scene.examples import example_scene_path
from ipe_ros.engine.sampling.perturb import draw_sample_inputs

IDENTITY = (0.0, 0.0, 0.0, 1.0)
FALL = QuerySpec(queries=frozenset({"fall", "direction"}))
EVERY_SHAPE = {
    "box": BoxShape((0.2, 0.3, 0.1)),
    "sphere": Sphere(0.1),
    "cylinder": Cylinder(0.1, 0.3),
    "capsule": Capsule(0.05, 0.2),
    "cone": cone(0.15, 0.3),
    "wedge": wedge(0.4, 0.2, 0.1),
    "bracket": l_bracket(0.3, 0.06),
}


def resting(shape, name="thing", **fields) -> Body:
    """``shape`` standing on the floor in its own orientation, its lowest point on z = 0."""
    fields.setdefault("mass_kg", 1.0)
    lowest = float(shapes.surface_points(shape)[:, 2].min())
    return Body(name=name, shape=shape, position_m=(0.0, 0.0, -lowest), orientation_xyzw=IDENTITY, friction=0.8,
                restitution=0.0, **fields)


def on_floor(*bodies, **scene_fields) -> Scene:
    return Scene(name="shapes", objects=tuple(bodies), support=Floor(friction=1.0, restitution=0.0), **scene_fields)


# --------------------------------------------------------------------------------------------
# geometry

def test_volumes_centres_and_rest_heights():
    assert shapes.volume_m3(Sphere(0.1)) == pytest.approx(4 / 3 * math.pi * 0.001)
    assert shapes.volume_m3(Cylinder(0.1, 0.3)) == pytest.approx(math.pi * 0.01 * 0.3)
    assert shapes.volume_m3(Capsule(0.05, 0.2)) == pytest.approx(math.pi * 0.0025 * 0.2 + 4 / 3 * math.pi * 0.05 ** 3)
    # a 64-sided pyramid is nearly a cone: volume pi r^2 h / 3, centre of mass a quarter up
    fine_cone = cone(0.15, 0.3, sides=64)
    assert shapes.volume_m3(fine_cone) == pytest.approx(math.pi * 0.15 ** 2 * 0.3 / 3, rel=0.01)
    assert shapes.centre_of_mass_m(fine_cone) == pytest.approx([0.0, 0.0, 0.3 / 4], abs=1e-9)
    # an L of two 0.3 x 0.06 x 0.06 plates: the mass-weighted centre of its parts
    bracket = l_bracket(0.3, 0.06)
    assert shapes.volume_m3(bracket) == pytest.approx(2 * 0.3 * 0.06 * 0.06)
    assert shapes.centre_of_mass_m(bracket) == pytest.approx([(0.15 + 0.03) / 2, 0.0, (0.03 + 0.15) / 2])
    # the lowest a body's centre of mass can rest: half the smallest side, the radius, ...
    assert shapes.min_rest_height_m(BoxShape((0.2, 0.6, 0.1))) == pytest.approx(0.05)
    assert shapes.min_rest_height_m(Cylinder(0.1, 0.05)) == pytest.approx(0.025)
    assert shapes.min_rest_height_m(fine_cone) == pytest.approx(0.3 / 4, rel=0.01)  # on its base


def test_mass_from_density_uses_the_true_volume():
    ball = resting(Sphere(0.1), mass_kg=None, density_kg_m3=1000.0)
    assert ball.resolved_mass_kg == pytest.approx(1000.0 * 4 / 3 * math.pi * 0.001)  # not its 0.2 m bounding cube


# --------------------------------------------------------------------------------------------
# the /2 format

def test_every_shape_round_trips_through_json():
    bodies = [dataclasses.replace(resting(shape, name), position_m=(float(i), 0.0, resting(shape).position_m[2]))
              for i, (name, shape) in enumerate(EVERY_SHAPE.items())]
    bodies[1] = dataclasses.replace(bodies[1], linear_velocity_m_s=(2.0, 0.0, 0.0), angular_velocity_rad_s=(0, 0, 1.0),
                                    position_sigma_m=0.0, yaw_sigma_rad=0.1)
    bodies[2] = dataclasses.replace(bodies[2], position_sigma_m=(0.01, 0.02, 0.0))
    scene = on_floor(*bodies, horizon_s=3.5)
    data = json.loads(json.dumps(scene_to_dict(scene)))
    assert data["format"] == "ipe_ros.scene/2" and data["horizon_s"] == 3.5
    assert {o["shape"]["type"] for o in data["objects"]} == {"box", "sphere", "cylinder", "capsule", "convex",
                                                             "compound"}
    assert scene_from_dict(data) == scene


def test_version_1_files_load_unchanged():
    scene = load_scenes(example_scene_path())[0]
    raw = json.loads(example_scene_path().read_text())
    assert raw["format"] == "ipe_ros.scene/1" and len(scene.objects) == len(raw["boxes"]) == 10
    assert all(isinstance(b.shape, BoxShape) and list(b.shape.extents_m) == r["extents_m"]
               for b, r in zip(scene.objects, raw["boxes"]))


@pytest.mark.parametrize("shape, field, message", [
    ({"type": "convex", "vertices_m": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]}, "shape.vertices_m",
     "the points are degenerate (all in one plane or on one line); a convex hull needs at least 4 points not "
     "all in one plane"),
    ({"type": "convex", "vertices_m": [[0, 0, 0], [1, 0, 0], [0, 1, 0]]}, "shape.vertices_m",
     "a convex hull needs at least 4 points not all in one plane, got 3"),
    ({"type": "sphere", "radius_m": 0}, "shape.radius_m", "the radius must be a finite number > 0, got 0.0"),
    ({"type": "compound", "parts": []}, "shape.parts", "a compound needs at least one part"),
    ({"type": "cylinder", "radius_m": 0.1}, "shape.length_m", "required field is missing"),
    ({"type": "cone", "radius_m": 0.1}, "shape.type",
     "must be one of box, sphere, cylinder, capsule, convex, compound, mesh, got 'cone'"),
])
def test_bad_shapes_name_the_field(shape, field, message):
    data = scene_to_dict(on_floor(resting(Sphere(0.1), "ball")))
    data["objects"][0]["shape"] = shape
    with pytest.raises(SceneError) as info:
        scene_from_dict(data)
    assert str(info.value) in (f"objects[0] ('ball').{field}: {message}", f"objects[0].{field}: {message}")


def test_a_nan_velocity_and_a_moving_static_body_are_refused():
    data = scene_to_dict(on_floor(resting(Sphere(0.1), "ball")))
    data["objects"][0]["linear_velocity_m_s"] = [1.0, float("nan"), 0.0]
    with pytest.raises(SceneError, match=r"^objects\[0\] \('ball'\)\.linear_velocity_m_s: velocity in m/s must be "
                                         r"finite numbers"):
        scene_from_dict(data)
    wall = dataclasses.replace(resting(BoxShape((1, 0.1, 1)), "wall"), static=True, mass_kg=None,
                               linear_velocity_m_s=(1.0, 0.0, 0.0))
    with pytest.raises(SceneError, match=r"^objects\[1\] \('wall'\)\.linear_velocity_m_s: a static body cannot move"):
        scene_from_dict(scene_to_dict(on_floor(resting(Sphere(0.1), "ball"), wall)))


# --------------------------------------------------------------------------------------------
# physics

@pytest.mark.parametrize("name", sorted(EVERY_SHAPE))
@pytest.mark.parametrize("preset_name", ["default", "paper"])
def test_every_shape_rests_on_the_floor(name, preset_name):
    scene = on_floor(resting(EVERY_SHAPE[name]))
    p = predict(scene, Request(model=ModelConfig(), settings=preset(preset_name), query=FALL, budget_s=None))
    end = p.outcomes[0].rollouts[0]
    assert p.failed_samples == 0 and p.fall_fraction == 0.0
    assert np.allclose(end.final_positions_m, p.outcomes[0].initial_positions_m, atol=1e-3)
    assert p.max_penetration_fraction < 0.01 and p.max_energy_gain_j < 1e-3


def test_a_cone_on_its_apex_falls_and_on_its_base_stands():
    upright = on_floor(resting(cone(0.15, 0.3)))
    flipped_shape = ConvexHull(tuple((x, y, -z) for x, y, z in cone(0.15, 0.3).vertices_m))
    tilt = (math.sin(0.02), 0.0, 0.0, math.cos(0.02))  # 2.3 degrees: no body balances on a point
    on_apex = on_floor(dataclasses.replace(resting(flipped_shape), position_m=(0.0, 0.0, 0.3), orientation_xyzw=tilt))
    assert predict(upright,
                   Request(model=ModelConfig(sigma_m=0.01, samples=4), settings=preset("default"), query=FALL,
                           budget_s=None)).fall_fraction == 0.0
    assert predict(on_apex,
                   Request(model=ModelConfig(sigma_m=0.01, samples=4), settings=preset("default"), query=FALL,
                           budget_s=None)).fall_fraction == 1.0


def test_a_ball_rolled_into_a_capped_tower_knocks_it_over():
    still = capped_tower(ball_speed_m_s=0.0)
    rolled = capped_tower(ball_speed_m_s=5.0)
    for preset_name in ("default", "paper"):
        assert predict(still, Request(model=ModelConfig(), settings=preset(preset_name), query=FALL, budget_s=None)).fall_fraction == 0.0
        hit = predict(rolled, Request(model=ModelConfig(), settings=preset(preset_name), query=FALL, budget_s=None))
        assert hit.object_fall_probability["cone"] == 1.0 and hit.failed_samples == 0
        assert hit.max_penetration_fraction < 0.05


def test_a_body_known_exactly_gets_no_noise():
    scene = capped_tower()
    model = ModelConfig(sigma_m=0.05, samples=2)
    draws = [draw_sample_inputs(scene, model, np.random.default_rng(seed)) for seed in range(5)]
    ball = [b.name for b in scene.dynamic_objects].index("ball")
    assert all(np.array_equal(d.positions_m[ball], draws[0].positions_m[ball]) for d in draws)
    assert len({float(d.positions_m[0, 0]) for d in draws}) == 5  # the boxes' own noise varies
    assert all(np.array_equal(d.positions_m[:, 2], draws[0].positions_m[:, 2]) for d in draws)  # horizontal only


def test_yaw_and_vertical_noise_where_a_body_asks_for_them():
    ball = resting(Sphere(0.1), "ball", position_sigma_m=(0.0, 0.0, 0.01))
    block = resting(BoxShape((0.2, 0.2, 0.2)), "block", yaw_sigma_rad=0.3)
    block = dataclasses.replace(block, position_m=(1.0, 0.0, 0.1))
    inputs = draw_sample_inputs(on_floor(ball, block), ModelConfig(sigma_m=0.05), np.random.default_rng(3))
    assert inputs.positions_m[0, :2].tolist() == [0.0, 0.0] and inputs.positions_m[0, 2] != 0.1
    assert inputs.orientations_xyzw[1, :2].tolist() == [0.0, 0.0] and abs(inputs.orientations_xyzw[1, 2]) > 0
    assert np.linalg.norm(inputs.orientations_xyzw[1]) == pytest.approx(1.0)


def test_the_scene_horizon_bounds_the_rollout():
    scene = on_floor(resting(Sphere(0.1), "ball", linear_velocity_m_s=(1.0, 0.0, 0.0)), horizon_s=0.5)
    p = predict(scene, Request(model=ModelConfig(), settings=preset("paper"), query=FALL, budget_s=None))
    assert p.outcomes[0].rollouts[0].simulated_s == pytest.approx(0.5)
    assert p.outcomes[0].rollouts[0].final_positions_m[0, 0] == pytest.approx(0.5 * 5 / 7, rel=0.1)  # rolling


@pytest.mark.parametrize("ratio", [1000.0, 0.001])
def test_a_1000_to_1_stack_gets_the_same_ground_truth_from_default_and_paper(ratio):
    light = resting(BoxShape((0.2, 0.2, 0.2)), "bottom", mass_kg=1.0)
    top = dataclasses.replace(resting(BoxShape((0.2, 0.2, 0.2)), "top", mass_kg=ratio), position_m=(0.0, 0.0, 0.3))
    scene = on_floor(light, top)
    answers = {name: predict(scene, Request(model=ModelConfig(), settings=preset(name), query=FALL, budget_s=None)) for name in ("default", "paper")}
    assert answers["default"].fall_fraction == answers["paper"].fall_fraction == 0.0
    for p in answers.values():
        assert p.max_penetration_fraction < 0.05


def test_energy_is_measured_and_a_bouncing_ball_gains_none():
    bouncy = dataclasses.replace(resting(Sphere(0.05), "ball", mass_kg=2.0), position_m=(0.0, 0.0, 0.5),
                                 restitution=0.9)
    scene = Scene(name="bounce", objects=(bouncy,), support=Floor(friction=0.5, restitution=0.9))
    p = predict(scene, Request(model=ModelConfig(), settings=preset("default"), query=FALL, budget_s=None))
    potential_j = 2.0 * 9.81 * 0.5
    assert 0.0 <= p.max_energy_gain_j < 0.01 * potential_j
    from ipe_ros.engine.simulation.health import energy_j

    energy = energy_j(np.array([2.0]), np.array([[0.1, 0.1, 0.2]]), np.array([0.0, 0.0, -9.81]),
                      np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 0.0, 1.0]]), np.array([[3.0, 0.0, 0.0]]),
                      np.array([[0.0, 0.0, 2.0]]))
    assert energy == pytest.approx(0.5 * 2 * 9 + 0.5 * 0.2 * 4 + 2 * 9.81 * 1.0)
