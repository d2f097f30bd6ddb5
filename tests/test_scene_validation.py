"""Every kind of bad scene gets an error naming the object and field and saying what is allowed."""

import copy
import math
import json

import numpy as np
import pytest

from ipe_ros.engine import SceneError, scene_from_dict, scene_to_dict, scenes_from_json
from ipe_ros.engine.scene.generators import generate_towers

from .helpers import block, floor_scene


@pytest.fixture()
def good() -> dict:
    return scene_to_dict(floor_scene(block("a", 0, 0, 0.1), block("b", 0, 0, 0.3)))


def error_for(data) -> str:
    with pytest.raises(SceneError) as info:
        scene_from_dict(data)
    return str(info.value)


def test_good_scene_loads(good):
    assert scene_from_dict(good).name == "test"


def test_nan_position_names_object_and_field(good):
    good["objects"][1]["position_m"][0] = float("nan")
    assert error_for(good) == ("objects[1] ('b').position_m: position in metres must be finite numbers, "
                               "got [nan, 0.0, 0.3]")


def test_inf_mass(good):
    good["objects"][0]["mass_kg"] = float("inf")
    assert error_for(good) == "objects[0] ('a').mass_kg: mass in kg must be finite, got inf"


def test_zero_size(good):
    good["objects"][0]["shape"]["extents_m"] = [0.2, 0.0, 0.2]
    assert error_for(good) == ("objects[0] ('a').shape.extents_m: every extent must be a finite number > 0 metres, "
                               "got [0.2, 0.0, 0.2]")


def test_negative_mass(good):
    good["objects"][1]["mass_kg"] = -1
    assert error_for(good) == "objects[1] ('b').mass_kg: mass in kg must be > 0, got -1.0"


def test_non_unit_quaternion(good):
    good["objects"][0]["orientation_xyzw"] = [0, 0, 0, 0.9]
    assert error_for(good) == ("objects[0] ('a').orientation_xyzw: must be a unit quaternion (norm within 0.001 of 1),"
                               " got norm 0.9; normalise it")


def test_object_below_support(good):
    good["objects"][0]["position_m"][2] = 0.05
    assert error_for(good) == ("objects[0] ('a').position_m: the body's lowest point z = -0.05 m is below the support "
                               "surface at z = 0 m; raise it by at least 0.05 m")


def test_unknown_field(good):
    good["objects"][0]["colour"] = "red"
    assert error_for(good).startswith("objects[0].colour: unknown field; allowed fields are name, shape,")


def test_missing_field_is_not_defaulted(good):
    del good["objects"][0]["friction"]
    assert error_for(good) == "objects[0].friction: required field is missing"
    data = copy.deepcopy(good)
    del data["gravity_m_s2"]
    assert error_for(data) == "gravity_m_s2: required field is missing"


def test_mass_or_density_not_both(good):
    good["objects"][0]["density_kg_m3"] = 500.0
    assert error_for(good) == "objects[0] ('a').mass_kg: give mass_kg or density_kg_m3, not both"


def test_too_many_objects(good):
    good["objects"] = [dict(good["objects"][0], name=f"b{i}") for i in range(10_000)]
    assert error_for(good) == "objects: 10000 objects exceed the maximum of 200; split the scene or raise max_objects"


def test_max_objects_is_configurable(good):
    with pytest.raises(SceneError, match="2 objects exceed the maximum of 1"):
        scene_from_dict(good, max_objects=1)


def test_duplicate_names(good):
    good["objects"][1]["name"] = "a"
    assert error_for(good) == "objects[1].name: duplicate name 'a'; names must be unique"


def test_gravity_must_point_down(good):
    good["gravity_m_s2"] = [0, 0, 9.81]
    assert error_for(good) == "gravity_m_s2: z must be negative (z is up), got 9.81"


def test_unknown_support_type(good):
    good["support"]["type"] = "trampoline"
    assert error_for(good) == "support.type: must be \"floor\" or \"table\", got 'trampoline'"


def test_empty_scene(good):
    good["objects"] = []
    assert error_for(good) == "objects: the scene has no dynamic object: nothing can fall"


def test_malformed_json_and_nan_literals():
    with pytest.raises(SceneError, match=r"^json: malformed JSON at line 1 column 2"):
        scenes_from_json("{oops")
    text = json.dumps(scene_to_dict(floor_scene(block("a", 0, 0, 0.1)))).replace("0.9", "NaN", 1)
    with pytest.raises(SceneError, match="^json: NaN is not a valid number; use finite numbers only"):
        scenes_from_json(text)


def test_obstacles_must_be_static():
    from ipe_ros.engine.scene.generators import generate_tables

    scene = generate_tables(1, configurations=1, tables=("T1",))[0]
    data = scene_to_dict(scene)
    data["support"]["obstacles"][0]["static"] = False
    assert error_for(data) == ("support.obstacles[0] ('wall+x').static: obstacles are attached to the table and "
                               "must be static: true")


def test_errors_in_a_list_of_scenes_name_the_scene():
    scenes = [scene_to_dict(s) for s in generate_towers(3, 2)]
    scenes[1]["objects"][2]["shape"]["extents_m"] = [1, 1, -1]
    with pytest.raises(SceneError, match=r"^scenes\[1\]\.objects\[2\] \('block2'\)\.shape\.extents_m: every extent"):
        scenes_from_json(json.dumps(scenes))


def _table_scene(*boxes):
    from ipe_ros.engine import Scene, Table

    table = Table(top_height_m=0.5, size_m=(1.0, 1.0), center_xy_m=(0.0, 0.0), thickness_m=0.05, friction=0.8,
                  restitution=0.0, floor_z_m=0.0)
    return scene_from_dict(scene_to_dict(Scene(name="edge", objects=tuple(boxes), support=table,
                                               gravity_m_s2=(0.0, 0.0, -9.81))))


def _brick_over_edge(touch_from_inner_end_m: float, tilt_rad: float = math.radians(15)):
    """A 0.2 x 0.1 x 0.05 m brick whose bottom face touches the table's +x edge (x = 0.5, z = 0.5)
    this far from its inner end, tilted down towards +x: its outer end hangs below the top, off the table."""
    from ipe_ros.engine import Box

    u = np.array([math.cos(tilt_rad), -math.sin(tilt_rad)])  # along the bottom face, in x-z
    n = np.array([math.sin(tilt_rad), math.cos(tilt_rad)])  # its outward normal
    inner_corner = np.array([0.5, 0.5]) - touch_from_inner_end_m * u
    x, z = inner_corner + 0.1 * u + 0.025 * n
    q = (0.0, math.sin(tilt_rad / 2), 0.0, math.cos(tilt_rad / 2))
    return Box(name="brick", extents_m=(0.2, 0.1, 0.05), position_m=(float(x), 0.0, float(z)), orientation_xyzw=q,
               friction=0.8, restitution=0.0, mass_kg=1.0)


def test_a_brick_tilted_over_the_table_edge_is_not_below_the_table():
    brick = _brick_over_edge(0.12)
    assert brick.position_m[0] < 0.5  # its centre is over the table, its outer end 21 mm below the top, off it
    assert _table_scene(brick).objects[0].name == "brick"


def test_a_corner_inside_the_table_top_is_refused_where_the_centre_is_off_the_table():
    brick = _brick_over_edge(0.02)  # pushed 10 cm further out, the bottom face now cuts into the slab's edge
    data = scene_to_dict(_table_scene(_brick_over_edge(0.12)))
    data["objects"][0]["position_m"] = [brick.position_m[0] - 0.03, 0.0, brick.position_m[2] - 0.01]
    assert data["objects"][0]["position_m"][0] > 0.5
    message = error_for(data)
    assert message.startswith("objects[0] ('brick').position_m: the body's lowest point z = ")
    assert "below the support surface at z = 0.5 m; raise it by at least" in message


def test_a_scene_is_checked_in_full_once_and_its_count_every_time(monkeypatch):
    """A request's scene is checked where it is read, costed and predicted: the full check runs once,
    marked on the scene itself (no table shared between the node's threads), and max_objects still
    applies at each later check."""
    import dataclasses

    from ipe_ros.engine.scene import validation as scene_module

    tower = dataclasses.replace(generate_towers(5, 1)[0])  # a fresh value, never checked
    calls = []
    full_check = scene_module._validate
    monkeypatch.setattr(scene_module, "_validate", lambda s, n: calls.append(s.name) or full_check(s, n))
    for _ in range(3):
        assert scene_module.validate_scene(tower) is tower
    assert calls == [tower.name]
    with pytest.raises(SceneError, match=r"^objects: 10 objects exceed the maximum of 4; split the scene"):
        scene_module.validate_scene(tower, max_objects=4)
    renamed = dataclasses.replace(tower, name="renamed")  # a new value is checked anew
    scene_module.validate_scene(renamed)
    assert calls == [tower.name, "renamed"]
    mutable = dataclasses.replace(tower, name="mutable", objects=list(tower.objects))  # could change later
    scene_module.validate_scene(mutable)
    scene_module.validate_scene(mutable)
    assert calls == [tower.name, "renamed", "mutable", "mutable"]
    assert not any(isinstance(v, dict) and v and isinstance(next(iter(v)), tuple)
                   for v in vars(scene_module).values())  # no memo keyed by scenes
