"""The JSON format round-trips losslessly; the paper's CSV loads as documented."""

import dataclasses
import json

import pytest

from ipe_ros.engine import SceneError, load_scenes, scene_from_dict, scene_to_dict, scenes_from_tower_csv
from ipe_ros.engine.scene.generators import generate_tables, generate_towers, state_pair
from ipe_ros.engine.scene.format import write_scenes

from .conftest import shared_file

CSV_HEADER = (",name,object,friction,mass,pos_x,pos_y,pos_z,quat_w,quat_x,quat_y,quat_z,restitution,"
              "scale_x,scale_y,scale_z,blocktype,ratio\n")


def test_json_round_trip_is_exact_for_towers_pairs_and_tables(tmp_path):
    import numpy as np

    towers = generate_towers(7, 3)
    pair = state_pair(towers[0], np.random.default_rng(0), ratio=10.0)
    scenes = towers + list(pair) + generate_tables(7, configurations=2)
    scenes[0] = dataclasses.replace(scenes[0], set_down_m=0.004)  # heights that are estimates
    for scene in scenes:
        again = scene_from_dict(json.loads(json.dumps(scene_to_dict(scene))))
        assert again == scene
    path = tmp_path / "all.json"
    write_scenes(scenes, path)
    assert load_scenes(path) == scenes


def test_example_file_loads():
    from ipe_ros.engine.scene.examples import example_scene_path

    (scene,) = load_scenes(example_scene_path())
    assert scene.name == "example_tower" and len(scene.objects) == 10


def write_csv(path, rows):
    lines = [CSV_HEADER]
    for i, (name, obj, x, y, z, blocktype, ratio) in enumerate(rows):
        lines.append(f"{i},{name},{obj},0.894,{4.08 * (ratio if blocktype else 1)},{x},{y},{z},"
                     f"1.0,0.0,0.0,0.0,0.0,0.2,0.6,0.2,{blocktype},{ratio}\n")
    path.write_text("".join(lines))


def test_tower_csv_groups_by_name_and_ratio(tmp_path):
    path = tmp_path / "mass.csv"
    rows = []
    for ratio in (0.1, 10):
        rows += [("tower_1_01", "block0", 0, 0, 0.1, 0, ratio), ("tower_1_01", "block1", 0, 0, 0.3, 1, ratio)]
    write_csv(path, rows)
    scenes = scenes_from_tower_csv(path)
    assert [s.name for s in scenes] == ["tower_1_01@ratio=0.1", "tower_1_01@ratio=10"]
    heavy = scenes[1].objects[1]
    assert heavy.group == "heavy" and heavy.mass_kg == pytest.approx(40.8)
    assert scenes[1].objects[0].group == "light"
    # quaternion columns are (w, x, y, z); the engine stores (x, y, z, w)
    assert heavy.orientation_xyzw == (0.0, 0.0, 0.0, 1.0)
    assert [s.name for s in scenes_from_tower_csv(path, towers=["tower_1_01"])] == [s.name for s in scenes]
    assert [s.name for s in scenes_from_tower_csv(path, towers=["tower_1_01@ratio=10"])] == ["tower_1_01@ratio=10"]
    with pytest.raises(SceneError, match="^--tower: no tower named 'nope' in mass.csv"):
        scenes_from_tower_csv(path, towers=["nope"])


def test_tower_csv_rejects_bad_rows(tmp_path):
    path = tmp_path / "bad.csv"
    write_csv(path, [("t", "block0", 0, 0, 0.05, 0, 1)])
    with pytest.raises(SceneError, match=r"^bad.csv:t:objects\[0\] \('block0'\).position_m: the body's lowest point"):
        scenes_from_tower_csv(path)


def test_a_bad_tower_of_a_csv_is_handed_to_on_refused_and_the_others_are_read(tmp_path):
    path = tmp_path / "some_bad.csv"
    write_csv(path, [("a", "block0", 0, 0, 0.3, 0, 1), ("b", "block0", 0, 0, 0.05, 0, 1), ("c", "block0", 0, 0, 0.3, 0, 1)])
    refused = []
    assert [s.name for s in scenes_from_tower_csv(path, on_refused=refused.append)] == ["a", "c"]
    [refusal] = refused
    assert (refusal.index, refusal.name) == (1, "b")
    assert str(refusal.error).startswith("some_bad.csv:b:objects[0] ('block0').position_m: the body's lowest point")
    with pytest.raises(SceneError, match="^some_bad.csv: none of the 1 towers asked for can be read"):
        scenes_from_tower_csv(path, towers=["b"], on_refused=refused.append)


def test_paper_csv_loads_all_60_towers():
    scenes = load_scenes(shared_file("willitfall.csv"))
    assert len(scenes) == 60
    assert all(len(s.objects) == 10 for s in scenes)
    for scene in scenes:
        for box in scene.objects:
            assert box.extents_m == pytest.approx((0.2, 0.6, 0.2), abs=1e-6)
            assert box.group == "light"
