"""An answer does not depend on which way the scene points: every zoo family, turned and shifted.

Each family's scene is answered as it is and turned by 37 deg about the vertical and shifted by
(0.3, -0.2) m (``scene.turn.turned``), with the same seeds. Its noise is drawn along the world's axes
either way, so the turned scene's samples are other draws of the same distribution, not the same
draws turned: the answers agree within sampling and chaos, not to the bit. Tolerances (k = 16): each
object's |dP(falls)| at most 0.45 (two independent proportions at 0.5 differ by 0.18 SD), their mean
over the scene at most 0.15; a decisive fall direction (decisiveness >= 0.8 both ways) turned by the
same 37 deg within 25 deg: a circular mean of 16 spread directions moves by up to ~20 deg between
two draws (the bouncy family, seeds 3-6: 7-21 deg at k = 16, 4-10 deg at k = 64); a friction
that knows the world's axes turns a slide by up to 45 deg. What they catch: with friction that knew the world's axes (the direct
solver for whole rollouts, before simulation/impacts.py) the strike family's scene answered 0.33
mean and 0.56 max |dP| turned (0.06 and 0.19 now). The issue's table, through the CLI, closes it.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine import Context, Request
from ipe_ros.engine.config import DEFAULT_QUERIES
from ipe_ros.engine.errors import SceneError
from ipe_ros.engine.scene.generators import make_table
from ipe_ros.engine.scene.turn import turned
from ipe_ros.engine.scene.bodies import Scene
from ipe_ros.engine.scene.zoo import FAMILIES, zoo_scene, zoo_sigma_m

from .helpers import block

YAW_RAD = math.radians(37.0)
SHIFT_M = (0.3, -0.2)
QUERY = QuerySpec(queries=DEFAULT_QUERIES)


@pytest.mark.slow
@pytest.mark.parametrize("family", list(FAMILIES))
def test_a_zoo_scene_turned_about_the_vertical_answers_the_same(family, pool):
    scene = zoo_scene(family, 2026, 0)
    model = ModelConfig(sigma_m=zoo_sigma_m(scene), samples=16)
    straight, other = (predict(s,
                               Request(model=model, settings=preset("default"), query=QUERY, seed=3, check=None,
                                       budget_s=None),
                               Context(map_fn=pool.map))
                       for s in (scene, turned(scene, YAW_RAD, SHIFT_M)))
    assert straight.failed_samples == other.failed_samples == 0
    differences = np.array([abs(straight.object_fall_probability[k] - other.object_fall_probability[k])
                            for k in straight.object_fall_probability])
    assert differences.max() <= 0.45, straight.object_fall_probability | {"turned": other.object_fall_probability}
    assert differences.mean() <= 0.15
    if straight.direction_rad is not None and other.direction_rad is not None \
            and min(straight.direction_decisiveness, other.direction_decisiveness) >= 0.8:
        off = math.remainder(other.direction_rad - straight.direction_rad - YAW_RAD, 2 * math.pi)
        assert abs(math.degrees(off)) <= 25.0


def test_a_turned_scene_keeps_its_bodies_poses_relative_to_each_other():
    scene = zoo_scene("strike", 2026, 0)
    other = turned(scene, YAW_RAD, SHIFT_M)
    for a, b in zip(scene.objects, other.objects):
        assert math.dist(a.position_m, (0.0, 0.0, a.position_m[2])) == pytest.approx(
            math.dist(b.position_m, (SHIFT_M[0], SHIFT_M[1], b.position_m[2])))
        assert np.linalg.norm(b.linear_velocity_m_s) == pytest.approx(np.linalg.norm(a.linear_velocity_m_s))
    twice = turned(turned(scene, YAW_RAD), -YAW_RAD)
    for a, b in zip(scene.objects, twice.objects):
        np.testing.assert_allclose(a.position_m, b.position_m, atol=1e-12)
        assert abs(float(np.dot(a.orientation_xyzw, b.orientation_xyzw))) == pytest.approx(1.0)


def test_a_table_turns_by_quarter_turns_only():
    table_scene = Scene(name="table", objects=(block("a", 0.3, 0.1, 0.1),), support=make_table("T1"))
    quarter = turned(table_scene, math.pi / 2)
    assert quarter.support.size_m == table_scene.support.size_m[::-1]
    with pytest.raises(SceneError, match=r"support: a table's sides lie along x and y: turn it by a multiple of "
                                         r"90 deg, not 37 deg"):
        turned(table_scene, YAW_RAD)


@pytest.mark.parametrize("heading_deg", [0, 30, 45])
def test_the_cli_slides_the_issues_box_straight_to_coulombs_distance(heading_deg, tmp_path, capsys):
    """Through the door a user takes (`ipe predict --ground-truth --query final_pose --json`), the
    issue's table: a 1 kg, 10 x 10 x 5 cm box, friction 0.5 on 1.0, restitution 0.2, launched at
    2 m/s, stops at Coulomb's 0.408 m (2%) straight on (1 deg), whichever way it is launched (it
    stopped at 0.328 m heading 18 deg when launched at 30 deg). The box stays along the world's axes:
    a box turned from them slides too far in pybullet whatever the solver (tests/test_mechanics.py,
    ``KNOWN``)."""
    from ipe_ros.cli import main
    from ipe_ros.engine.scene.bodies import Box, Floor
    from ipe_ros.engine.scene.format import write_scenes

    heading = math.radians(heading_deg)
    box = Box("box", (0.1, 0.1, 0.05), (0.3, -0.2, 0.025), (0.0, 0.0, 0.0, 1.0), friction=0.5, restitution=0.2,
              mass_kg=1.0, linear_velocity_m_s=(2 * math.cos(heading), 2 * math.sin(heading), 0.0))
    path = tmp_path / "slide.json"
    write_scenes([Scene(name="slide", objects=(box,), support=Floor(friction=1.0, restitution=0.2))], path)
    assert main(["predict", str(path), "--ground-truth", "--query", "final_pose", "--workers", "0", "--json"]) == 0
    x, y, _ = json.loads(capsys.readouterr().out)["final_pose"]["box"]["position_m"]
    travel_x, travel_y = x - 0.3, y + 0.2
    assert math.hypot(travel_x, travel_y) == pytest.approx(2.0 ** 2 / (2 * 0.5 * 9.81), rel=0.02)
    assert abs(math.degrees(math.remainder(math.atan2(travel_y, travel_x) - heading, 2 * math.pi))) <= 1.0
