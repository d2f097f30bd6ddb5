"""msg_bridge: message <-> engine conversions, without rclpy.init (message classes only)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest
from std_msgs.msg import ColorRGBA, String
from visualization_msgs.msg import Marker, MarkerArray

from ipe_ros.engine import Body, ConfigError, Floor, Prediction, Scene, SceneError, Table, load_scenes
from ipe_ros.engine.scene.generators import generate_tables
from ipe_ros.engine.query import ANSWER_FIELDS
from msg_bridge.json_text import answer_to_string, scene_to_string, string_to_answer, string_to_scene
from msg_bridge.markers import DEFAULT_DENSITY_KG_M3, markers_to_scene, scene_to_markers
from msg_bridge.prediction_markers import prediction_to_markers
from msg_bridge.outputs import fall_direction_msg, fall_fraction_msg, fall_probability_msg
from msg_bridge.stamps import header_to_stamp_ns, stamp_ns_to_header
from tests.helpers import IDENTITY, block, floor_scene

TOWER = load_scenes("ipe_ros/data/example_tower.json")[0]


def cube(ns="objects", marker_id=0, xyz=(0.0, 0.0, 0.1), scale=(0.2, 0.2, 0.2), text="", frame="world",
         rgba=(0.0, 0.0, 0.0, 0.0)) -> Marker:
    m = Marker(ns=ns, id=marker_id, type=Marker.CUBE, action=Marker.ADD, text=text)
    m.header.frame_id = frame
    m.pose.position.x, m.pose.position.y, m.pose.position.z = xyz
    m.scale.x, m.scale.y, m.scale.z = scale
    m.color = ColorRGBA(r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3])
    return m


def read(*markers: Marker, **kw):
    return markers_to_scene(MarkerArray(markers=list(markers)), **kw)


def error_of(*markers: Marker, **kw) -> str:
    with pytest.raises(SceneError) as info:
        read(*markers, **kw)
    return str(info.value)


# -- round trips -------------------------------------------------------------------------------

def test_tower_round_trips_exactly_with_its_stamp_and_frame():
    back = markers_to_scene(scene_to_markers(TOWER, "odom", 1_234_567_890_123))
    assert back.scene == TOWER
    assert (back.frame_id, back.stamp_ns) == ("odom", 1_234_567_890_123)


def test_tables_with_walls_round_trip():
    for scene in generate_tables(seed=3, configurations=1):
        back = markers_to_scene(scene_to_markers(scene, "table_frame")).scene
        assert isinstance(back.support, Table)
        assert back == scene, scene.name


def test_json_round_trip_and_answer_text():
    assert string_to_scene(scene_to_string(TOWER)) == TOWER
    assert string_to_answer(answer_to_string({"fall_fraction": 0.25, "stamp": {"sec": 1}})) == \
        {"fall_fraction": 0.25, "stamp": {"sec": 1}}
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        answer_to_string({"fall_fraction": math.nan})


def test_stamps_round_trip():
    header = stamp_ns_to_header(1_700_000_000_999_999_999, "map")
    assert (header.stamp.sec, header.stamp.nanosec, header.frame_id) == (1_700_000_000, 999_999_999, "map")
    assert header_to_stamp_ns(header) == 1_700_000_000_999_999_999
    with pytest.raises(ValueError, match=r"^stamp_ns: must be >= 0"):
        stamp_ns_to_header(-1, "map")


# -- the documented mapping ------------------------------------------------------------------------

def test_defaults_unset_quaternion_and_colour_groups():
    red = cube(marker_id=1, rgba=(0.9, 0.1, 0.1, 1.0))
    yellow = cube(marker_id=2, xyz=(1.0, 0.0, 0.1), rgba=(1.0, 0.9, 0.0, 1.0))
    plain = cube(marker_id=3, xyz=(2.0, 0.0, 0.1))
    scene = read(red, yellow, plain).scene
    assert isinstance(scene.support, Floor) and scene.support.height_m == 0.0
    assert [b.group for b in scene.objects] == ["red", "yellow", ""]
    assert [b.name for b in scene.objects] == ["objects/1", "objects/2", "objects/3"]
    assert all(b.orientation_xyzw == (0.0, 0.0, 0.0, 1.0) for b in scene.objects)  # all-zero quaternion = identity
    assert all(b.density_kg_m3 == DEFAULT_DENSITY_KG_M3 and b.mass_kg is None for b in scene.objects)
    assert scene.gravity_m_s2 == (0.0, 0.0, -9.81)


def test_text_properties_and_support_roles():
    table = cube(ns="support", marker_id=0, xyz=(0.0, 0.0, 0.7), scale=(1.0, 0.8, 0.04),
                 text="role=table friction=0.5 scene=desk gravity=-9.8")
    wall = cube(ns="support", marker_id=1, xyz=(0.45, 0.0, 0.77), scale=(0.02, 0.8, 0.1), text="name=wall")
    box = cube(marker_id=7, xyz=(0.0, 0.0, 0.77), scale=(0.1, 0.1, 0.1),
               text="name=mug mass=0.3, friction=0.6; group=red restitution=0.1")
    scene = read(table, wall, box).scene
    assert scene.name == "desk" and scene.gravity_m_s2 == (0.0, 0.0, -9.8)
    support = scene.support
    assert isinstance(support, Table)
    assert (support.top_height_m, support.size_m, support.thickness_m, support.friction) == \
        (pytest.approx(0.72), (1.0, 0.8), 0.04, 0.5)
    assert support.floor_z_m == 0.0  # the slab's underside is above z = 0: a floor there
    assert [o.name for o in support.obstacles] == ["wall"] and support.obstacles[0].static
    [mug] = scene.objects
    assert (mug.name, mug.mass_kg, mug.friction, mug.group, mug.restitution) == ("mug", 0.3, 0.6, "red", 0.1)


def test_deleteall_markers_are_ignored():
    clear = Marker(action=Marker.DELETEALL)
    assert len(read(clear, cube()).scene.objects) == 1


@pytest.mark.parametrize("markers, expected", [
    ([], "markers: the array holds no ADD markers; publish one CUBE, SPHERE, CYLINDER or TRIANGLE_LIST marker per "
         "body"),
    ([cube(frame="")], "markers[0].header.frame_id: is empty; set the frame the poses are in"),
    ([cube(), cube(marker_id=1, xyz=(1, 0, 0.1), frame="map")],
     "markers[1].header.frame_id: is 'map' but markers[0] is in 'world'; publish every marker of a scene in one frame"),
    ([cube(xyz=(math.nan, 0.0, 0.1))], "markers[0].pose.position: must be finite, got [nan, 0.0, 0.1]"),
    ([cube(scale=(0.2, 0.0, 0.2))], "markers[0].scale: full sizes must be finite and > 0 m, got [0.2, 0.0, 0.2]"),
    ([cube(), cube(xyz=(1, 0, 0.1))], "markers[1]: ns 'objects' id 0 repeats markers[0]; give each marker a unique (ns, id)"),
    ([cube(text="mass=1 density=2")], "markers[0].text: give mass or density, not both"),
    ([cube(text="colour=red")],
     "markers[0].text: unknown key 'colour'; allowed here: name, mass, density, friction, restitution, group, vx, vy, "
     "vz, wx, wy, wz, sigma, yaw_sigma, decompose"),
    ([cube(text="mass=heavy")], "markers[0].text.mass: expected a number, got 'heavy'"),
    ([cube(text="mass")], "markers[0].text: expected key=value pairs, got 'mass'"),
    ([cube(ns="support", text="role=floor")],
     "markers: no dynamic bodies: every marker is in the 'support' namespace; put the objects that may fall in another namespace"),
    ([cube(ns="support", text="role=floor"), cube(ns="support", marker_id=1, text="role=table"), cube()],
     "markers[1].text.role: a second table: a scene has one floor or one table"),
    ([cube(ns="support", text="role=shelf"), cube()], "markers[0].text.role: must be one of floor, table, obstacle, got 'shelf'"),
])
def test_bad_marker_arrays_name_the_field(markers, expected):
    assert error_of(*markers) == expected


def test_other_marker_types_are_rejected_by_type_name():
    arrow = cube()
    arrow.type = Marker.ARROW
    assert error_of(arrow) == ("markers[0].type: only CUBE, SPHERE, CYLINDER, TRIANGLE_LIST, MESH_RESOURCE markers describe "
                               "bodies here, got ARROW (ns 'objects', id 0); drop it from the scene array")
    support_ball = cube(ns="support", text="role=obstacle")
    support_ball.type = Marker.SPHERE
    assert error_of(support_ball, cube()) == ("markers[0].type: only CUBE markers describe bodies here, got SPHERE "
                                              "(ns 'support', id 0); drop it from the scene array")


def test_tilted_table_is_rejected():
    table = cube(ns="support", scale=(1, 1, 0.05), text="role=table")
    table.pose.orientation.x, table.pose.orientation.w = math.sin(0.1), math.cos(0.1)
    assert error_of(table, cube(xyz=(0, 0, 0.2))) == (
        "markers[0].pose.orientation: a table must be axis-aligned in the scene frame (identity orientation); "
        "rotate the frame instead")


def test_ten_thousand_markers_are_refused_before_conversion():
    flood = [cube(marker_id=i) for i in range(10_000)]
    assert error_of(*flood) == ("markers: 10000 markers exceed max_objects = 200; raise the max_objects parameter "
                                "or publish a smaller scene")


def test_engine_validation_errors_come_through_with_their_field():
    floating_below = cube(xyz=(0.0, 0.0, -0.5))
    message = error_of(floating_below)
    assert message.startswith("objects[0]"), message


def test_json_text_errors():
    with pytest.raises(SceneError, match=r"^data: is empty; publish one scene"):
        string_to_scene(String(data="  "))
    two = "[" + scene_to_string(TOWER).data + "," + scene_to_string(TOWER).data + "]"
    with pytest.raises(SceneError, match=r"^data: holds 2 scenes; publish one scene per message$"):
        string_to_scene(String(data=two))
    with pytest.raises(ValueError, match=r"^data: expected a JSON object, got an array$"):
        string_to_answer(String(data="[1]"))


def test_scene_names_that_cannot_ride_in_text_are_refused():
    scene = floor_scene(block("two words", 0, 0, 0.1))
    with pytest.raises(ValueError, match="cannot ride in Marker.text"):
        scene_to_markers(scene, "world")


# -- outputs -----------------------------------------------------------------------------------------

def _prediction(**kw) -> Prediction:
    base = dict(scene="t", samples=4, samples_requested=4, failed_samples=0, failure_reasons=(), deterministic=False)
    answers = {k: v for k, v in kw.items() if k in ANSWER_FIELDS and v is not None}
    return Prediction(**base, answers=answers, **{k: v for k, v in kw.items() if k not in ANSWER_FIELDS})


def test_direction_vector_is_scaled_by_decisiveness_and_zero_when_nothing_falls():
    msg = fall_direction_msg(_prediction(direction_rad=math.pi / 2, direction_decisiveness=0.75, direction_rollouts=4),
                             "map", 5)
    assert (msg.vector.x, msg.vector.y, msg.vector.z) == (pytest.approx(0.0), pytest.approx(0.75), 0.0)
    assert (msg.header.frame_id, msg.header.stamp.nanosec) == ("map", 5)
    still = fall_direction_msg(_prediction(direction_rad=None, direction_rollouts=0), "map", 5)
    assert (still.vector.x, still.vector.y, still.vector.z) == (0.0, 0.0, 0.0)
    assert fall_direction_msg(_prediction(), "map", 5) is None  # the direction query was not asked
    assert fall_fraction_msg(_prediction()) is None
    assert fall_fraction_msg(_prediction(fall_fraction=0.5)).data == 0.5
    assert fall_probability_msg(_prediction()) is None
    assert fall_probability_msg(_prediction(any_fall_probability=0.25)).data == 0.25


def test_prediction_markers_colour_objects_by_risk_and_draw_the_arrow():
    names = [b.name for b in TOWER.dynamic_objects]
    probs = {n: (1.0 if i == 0 else 0.0) for i, n in enumerate(names)}
    p = _prediction(fall_fraction=0.1, object_fall_probability=probs, direction_rad=0.0, direction_decisiveness=1.0)
    msg = prediction_to_markers(TOWER, p, "odom", 9)
    assert msg.markers[0].action == Marker.DELETEALL
    cubes = [m for m in msg.markers if m.ns == "ipe/objects"]
    assert cubes[0].color.r > 0.9 and cubes[0].color.g < 0.2      # falls: red
    assert cubes[1].color.g > 0.7 and cubes[1].color.r < 0.2      # stays: green
    [arrow] = [m for m in msg.markers if m.ns == "ipe/direction"]
    assert arrow.type == Marker.ARROW and arrow.points[1].x > arrow.points[0].x
    no_direction = prediction_to_markers(TOWER, _prediction(fall_fraction=0.0, object_fall_probability=probs),
                                         "odom", 9)
    assert not [m for m in no_direction.markers if m.ns == "ipe/direction"]


def test_msg_bridge_never_imports_rclpy():
    code = ("import sys, msg_bridge.markers, msg_bridge.outputs, msg_bridge.json_text, msg_bridge.stamps; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'rpyutils')); "
            "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr


def test_spheres_cylinders_and_triangle_lists_are_bodies_of_their_shape():
    from ipe_ros.engine import Cylinder, Sphere
    from ipe_ros.engine.scene.catalogue import cone

    ball = Body(name="ball", shape=Sphere(0.1), position_m=(1.0, 0.0, 0.1), orientation_xyzw=IDENTITY, friction=0.5,
                restitution=0.4, mass_kg=2.0, linear_velocity_m_s=(3.0, 0.0, 0.0), position_sigma_m=0.0, group="red")
    can = Body(name="can", shape=Cylinder(0.05, 0.12), position_m=(0.0, 0.5, 0.06), orientation_xyzw=IDENTITY,
               friction=0.5, restitution=0.0, density_kg_m3=300.0, yaw_sigma_rad=0.2, group="yellow")
    spike = Body(name="cone", shape=cone(0.1, 0.2), position_m=(0.0, 0.0, 0.0), orientation_xyzw=IDENTITY,
                 friction=0.5, restitution=0.0, mass_kg=1.0, angular_velocity_rad_s=(0.0, 0.0, 1.5), group="red")
    scene = Scene(name="shapes", objects=(ball, can, spike), support=Floor(friction=0.9, restitution=0.0))
    array = scene_to_markers(scene, "odom")
    types = [m.type for m in array.markers[1:]]
    assert types == [Marker.SPHERE, Marker.CYLINDER, Marker.TRIANGLE_LIST]
    assert "vx=3.0" in array.markers[1].text and "sigma=0.0" in array.markers[1].text
    back = markers_to_scene(array).scene
    assert back == scene


def test_an_ellipsoid_and_an_elliptic_cylinder_are_refused_with_the_fix():
    m = cube()
    m.type = Marker.SPHERE
    m.scale.x, m.scale.y, m.scale.z = 0.2, 0.2, 0.3
    assert error_of(m) == ("markers[0].scale: a SPHERE needs three equal scales (its diameter), got [0.2, 0.2, 0.3]; "
                           "an ellipsoid cannot be simulated: approximate it by a TRIANGLE_LIST")
    m.type = Marker.CYLINDER
    m.scale.x, m.scale.y, m.scale.z = 0.2, 0.1, 0.3
    assert error_of(m) == "markers[0].scale: a CYLINDER needs scale.x = scale.y (its diameter), got [0.2, 0.1, 0.3]"


def test_prediction_markers_draw_capsules_and_compounds_as_triangles():
    from ipe_ros.engine import Capsule, ModelConfig, QuerySpec, predict, preset
    from ipe_ros.engine import Request
    from ipe_ros.engine.scene.catalogue import l_bracket

    pill = Body(name="pill", shape=Capsule(0.03, 0.1), position_m=(0.0, 0.0, 0.03),
                orientation_xyzw=(0.0, 0.7071067811865476, 0.0, 0.7071067811865476), friction=0.5, restitution=0.0,
                mass_kg=0.1)
    bracket = Body(name="bracket", shape=l_bracket(0.2, 0.04), position_m=(0.5, 0.0, 0.0), orientation_xyzw=IDENTITY,
                   friction=0.5, restitution=0.0, mass_kg=0.5)
    scene = Scene(name="odd", objects=(pill, bracket), support=Floor(friction=0.9, restitution=0.0))
    with pytest.raises(ValueError, match=r"^objects \('pill'\)\.shape: a capsule has no marker; publish the scene on "
                                         r"~/scene_json"):
        scene_to_markers(scene, "odom")
    prediction = predict(scene,
                         Request(model=ModelConfig(), settings=preset("default"), query=QuerySpec(), budget_s=None))
    drawn = [m for m in prediction_to_markers(scene, prediction, "odom", 0).markers if m.ns == "ipe/objects"]
    assert [m.type for m in drawn] == [Marker.TRIANGLE_LIST] * 2
    assert all(len(m.points) % 3 == 0 and len(m.points) >= 12 for m in drawn)


def test_depth_images_convert_both_ways_and_name_what_is_wrong():
    import numpy as np
    from sensor_msgs.msg import Image

    from msg_bridge.depth import depth_m_to_image, image_to_depth_m

    depth = np.array([[0.0, 0.5, 1.25], [2.0, 3.5, np.nan]])
    metres = image_to_depth_m(depth_m_to_image(depth, 7, "camera", "32FC1"))
    assert np.array_equal(np.isnan(metres), np.isnan(depth)) and np.allclose(metres[:, :2], depth[:, :2])
    millimetres = depth_m_to_image(depth, 7, "camera", "16UC1")
    assert millimetres.header.frame_id == "camera" and millimetres.step == 6
    assert image_to_depth_m(millimetres).tolist() == [[0.0, 0.5, 1.25], [2.0, 3.5, 0.0]]  # NaN: no reading
    big_endian = Image(encoding="16UC1", width=1, height=1, step=2, is_bigendian=1, data=bytes([0x04, 0xD2]))
    assert image_to_depth_m(big_endian).tolist() == [[1.234]]
    with pytest.raises(ValueError, match=r"^image.encoding: must be a depth encoding \(32FC1, 16UC1, mono16\), "
                                         r"got 'rgb8'$"):
        image_to_depth_m(Image(encoding="rgb8", width=1, height=1, step=3, data=bytes(3)))
    with pytest.raises(ValueError, match=r"^image.data: holds 2 bytes, 4 x 1 expected$"):
        image_to_depth_m(Image(encoding="32FC1", width=1, height=1, step=4, data=bytes(2)))
    with pytest.raises(ValueError, match=r"^image.height: must be >= 1 pixel, got 0: an empty image$"):
        image_to_depth_m(Image(encoding="16UC1", width=4, height=0, step=8, data=b""))


def test_a_request_on_ask_is_read_once_and_routed_by_its_question(monkeypatch):
    """``~/ask`` reads a request's JSON once (it was read two or three times: for its id, for infer,
    for the question), and refuses NaN as scenes do."""
    import json as json_module

    from msg_bridge import ask_json
    from msg_bridge.ask_json import id_of, parse_request, question_from_data
    from msg_bridge.observe_json import infer_question_from_data

    reads = []
    real = json_module.loads
    monkeypatch.setattr(ask_json.json, "loads", lambda *a, **kw: reads.append(1) or real(*a, **kw))
    data = parse_request(String(data=json.dumps({"question": "remove", "id": "q1", "objects": ["b"]})))
    question, scene = question_from_data(data)
    assert (id_of(data), question.kind, scene, len(reads)) == ("q1", "remove", None, 1)
    assert data == {"question": "remove", "id": "q1", "objects": ["b"]}  # read, not consumed
    with pytest.raises(ConfigError, match=r"^observations: unknown field of an infer question; allowed: id, "
                                          r"observation$"):
        infer_question_from_data(parse_request(String(data='{"question": "infer", "observations": {}}')))
    with pytest.raises(ConfigError, match=r"^data: NaN is not a valid number; use finite numbers only$"):
        parse_request(String(data='{"question": "push", "velocity": [NaN, 0]}'))
