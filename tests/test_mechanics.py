"""Mechanics with closed-form answers, in every preset and in every direction.

Every answer is checked against `paper`, and `paper` is pybullet too: an error the presets share
cannot show there. Textbook mechanics shows it. Each case is one ground-truth rollout (sigma = phi
= 0) of a scene whose outcome has a closed form, run in every preset, with the scene pointed in
several directions about the vertical: an answer must not depend on how the scene happens to be
turned (a sliding box used to veer towards the world's axes wherever a bounce was possible: the
direct solver's friction is a box, not a cone; simulation/impacts.py).

An incline is gravity tilted by its angle (the same physics as a tilted floor, in the floor's
frame), which lets the slope face any direction without a ramp body. Bullet combines two surfaces'
frictions and restitutions by multiplying them; every case states the combined values it uses.

Tolerances, and why:
- a slide's stopping distance within 2% of v^2 / (2 mu g), its heading within 1 deg of its launch
  (the issue's bar; the step discretises the last few millimetres of the slide: measured < 0.5%);
- sliding and tipping thresholds on an incline: 2-3 deg either side of tan theta = mu and of the
  centre of mass over the edge (the block starts from rest, so a margin decides, not a fit);
- a bounce's apex within 3% of e^2 h (the impact is resolved within one step: at `default`'s
  1/180 s a 3 m/s landing is found up to 17 mm early or late, and the ball lands that far into the
  floor, its contacts solved from the touch);
- a head-on collision's momentum within 1% and its restitution within 0.03 (from the final
  positions; the impact lasts one step);
- a ball rolling without slipping down a slope within 2% of 5/7 g sin theta (a sliding ball
  would go 40% farther);
- a block on a block falls when its centre of mass is past the edge by 10% of its width, and
  stands 10% inside it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ipe_ros.engine import ModelConfig, QuerySpec, predict, preset
from ipe_ros.engine import Request
from ipe_ros.engine.scene.bodies import Body, Box, Floor, Scene, TimedPush
from ipe_ros.engine.scene.shapes import Sphere
from ipe_ros.engine.scene.turn import turned

G = 9.81
PRESETS = ["paper", "accurate", "fine", "default"]
FINAL = QuerySpec(queries=frozenset({"final_pose"}))
IDENTITY = (0.0, 0.0, 0.0, 1.0)


def _yaw(angle_rad: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(angle_rad / 2), math.cos(angle_rad / 2))


def _planar(angle_rad: float, length: float, z: float = 0.0) -> tuple[float, float, float]:
    return (length * math.cos(angle_rad), length * math.sin(angle_rad), z)


def _tilted_gravity(incline_rad: float, downhill_rad: float) -> tuple[float, float, float]:
    """Gravity on a floor tilted by ``incline_rad`` whose downhill points at ``downhill_rad``."""
    return (*_planar(downhill_rad, G * math.sin(incline_rad))[:2], -G * math.cos(incline_rad))


def _scene(*bodies: Body, floor_friction: float = 1.0, floor_restitution: float = 0.0, gravity=(0.0, 0.0, -G),
           horizon_s: float | None = None) -> Scene:
    return Scene(name="mechanics", objects=tuple(bodies), support=Floor(friction=floor_friction,
                                                                         restitution=floor_restitution),
                 gravity_m_s2=gravity, horizon_s=horizon_s)


def _ball(name: str, position_m, radius_m: float = 0.05, **fields) -> Body:
    fields.setdefault("mass_kg", 1.0)
    fields.setdefault("friction", 0.5)
    fields.setdefault("restitution", 0.0)
    return Body(name=name, shape=Sphere(radius_m), position_m=tuple(position_m), orientation_xyzw=IDENTITY, **fields)


#: Where pybullet's answer is known to miss the closed form (measured 2026-11-29; issue 70's follow-up).
#: Each is checked still to miss: a fix shows as a failure here, and its entry goes.
#: - "cone": a box sliding along its own axis while that axis is turned from the world's slides 6%
#:   (30 deg) to 11% (45 deg) too far, veering up to 2-4 deg. Every preset alike: the floor is a
#:   multibody, so its contacts go to pybullet's multibody solver, whose friction rows lie along the
#:   world's axes and whose implicit cone settles the friction along -M v, not -v (M: the rows'
#:   effective masses, unequal at a turned box's corner; for one corner at a time that predicts 1.071x
#:   and 1.111x). No pybullet route meets it (benchmarks/friction_routes.py: a plain rigid floor
#:   reaches the sequential-impulse solver, turn-invariant but clipping each row on its own, 2% short
#:   and 0.48-0.84x down a slope; a box floor leans at all four corners, veering 4-10 deg). MuJoCo
#:   meets the closed form here.
#: - "plane": on a slope facing an axis, `fine` and `default` slide 17-23% too far. pybullet's plane
#:   adds one contact point a step and keeps the others only until they drift (the contact distance),
#:   so at their coarser steps the block stands on 1-2 points and pivots from one to the next. A box
#:   floor, whose contacts give the whole face every step, meets the closed form (1.008-1.010x at
#:   1/180 s) but veers the turned slide (above) twice as far, so the plane stays.
#: - "rigid": a block sliding on a dynamic block, in `fine` and `default`, whose boxes are plain rigid
#:   bodies: a contact between two of them goes to Bullet's sequential-impulse solver (any contact with
#:   a multibody, the floor included, goes to the multibody solver), whose two friction rows are each
#:   clipped at mu N on their own (a box, not a cone). Past tan theta = mu the block slides 0.64x
#:   (0 deg) or holds (0.00-0.04x at 30-45 deg); `paper`'s multibodies slide 1.00x every way. Measured
#:   in plain pybullet, either body a multibody gives 1.00x at 1 ms and 1/180 s; both plain, 0.20-0.96x,
#:   depending on the step and on which way the slope faces.
#: - "bounce": a landing at 2.0 m/s gives back 0.94-1.11x e^2 h in `default`. Its steps, not its
#:   impacts: the ball's 4 ms step (its size's cap) lands it up to a step's travel (12 mm) into the
#:   floor, from where it rises, and whence it is pushed out after the rebound (higher); and the
#:   flight itself, integrated by semi-implicit Euler, tops out about v dt / 2 short (collapse steps,
#:   three ticks long in flight: 9 mm of a 125 mm apex). Cutting the impact's step into pieces
#:   (tried, session 51: the landing within 5% of the ball's size) gave 0.995-0.998x at 0.2 m and
#:   0.945-0.962x at 0.5 m, where it had met the bar. (`paper` and `accurate` gave back none of it until
#:   bouncing bodies' contacts were solved from the touch, not from when they are found ahead:
#:   Bullet solves a contact found ahead to the normal speed e v - d / dt, which slowed the ball a
#:   step before it landed; ``SolverSettings.bounce_from_touch``. Landings at 3.1 m/s, and `fine` at
#:   2.0 m/s, meet the closed form since an impact's step stopped removing the overlap by velocity
#:   on top of the rebound: simulation/world.py ``use_direct_solver``; they came back 1.03-1.20x
#:   high, and collisions gave back 0.48-0.57 for 0.49.)
KNOWN: dict[tuple, str] = {}


def _holds(ok: bool, key: tuple, detail) -> None:
    """Assert ``ok``, unless ``key`` is a known miss (``KNOWN``): then assert it still misses, and xfail."""
    reason = KNOWN.get(key)
    if reason is None:
        assert ok, detail
        return
    assert not ok, f"{key} now meets the closed form ({detail}): remove it from KNOWN"
    pytest.xfail(f"{reason}: {detail}")


def _known(kind: str, *keys: tuple) -> None:
    for key in keys:
        KNOWN[key] = kind


_known("cone", *[("slide", name, r, 120, 120) for name in PRESETS for r in (0.0, 0.2, 0.5)],
       ("push", "paper"), ("push", "default"),
       ("turned", "paper"), ("turned", "default"))
_known("plane", *[("incline", name, r, d) for name in ("fine", "default") for r in (0.0, 0.5) for d in (0, 30)])
_known("rigid", *[("on a block", name, d) for name in ("fine", "default") for d in (0, 30, 45)])
_known("bounce", *[("bounce", "default", e, 0.2) for e in (0.5, 0.64)])


def _end(scene: Scene, name):
    """The ground-truth rollout's end in preset ``name`` (or settings): (n, 3) centres of mass, (n, 4)
    orientations."""
    settings = preset(name) if isinstance(name, str) else name
    prediction = predict(scene,
                         Request(model=ModelConfig(sigma_m=0.0, samples=1), settings=settings, query=FINAL,
                                 check=None, budget_s=None))
    assert prediction.failed_samples == 0, prediction.failure_reasons
    rollout = prediction.outcomes[0].rollouts[0]
    return rollout.final_positions_m, rollout.final_orientations_xyzw


def _tilt_deg(orientation_xyzw) -> float:
    """How far a body's own z axis ends from the vertical."""
    x, y, z, w = orientation_xyzw
    return math.degrees(math.acos(max(-1.0, min(1.0, 1 - 2 * (x * x + y * y)))))


# -- a slide ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("restitution", [0.0, 0.2, 0.5])
@pytest.mark.parametrize("heading_deg, box_yaw_deg", [(0, 0), (30, 0), (45, 0), (120, 0), (120, 120), (-150, 17)])
def test_a_slide_stops_at_coulombs_distance_straight_on_whichever_way_it_points(name, restitution, heading_deg,
                                                                                 box_yaw_deg):
    # a 1 kg, 10 x 10 x 5 cm box, friction 0.5 on a 1.0 floor (0.5 together), launched at 2 m/s: the
    # issue's table (restitution 0.2: 0.328 m at 18 deg when launched at 30 deg, 0.290 m at 45 deg)
    heading = math.radians(heading_deg)
    box = Box("box", (0.1, 0.1, 0.05), (0.0, 0.0, 0.025), _yaw(math.radians(box_yaw_deg)), friction=0.5,
              restitution=restitution, mass_kg=1.0, linear_velocity_m_s=_planar(heading, 2.0))
    positions, _ = _end(_scene(box, floor_restitution=restitution), name)
    x, y, z = positions[0]
    expected_m = 2.0 ** 2 / (2 * 0.5 * G)
    off_deg = math.degrees(math.remainder(math.atan2(y, x) - heading, 2 * math.pi))
    _holds(abs(math.hypot(x, y) / expected_m - 1) <= 0.02 and abs(off_deg) <= 1.0,
           ("slide", name, restitution, heading_deg, box_yaw_deg), f"{math.hypot(x, y):.4f} m at {off_deg:+.2f} deg")
    assert z == pytest.approx(0.025, abs=1e-3)


@pytest.mark.parametrize("name", ["paper", "default"])
def test_on_the_direct_solver_throughout_the_slide_veered_as_the_issue_measured(name):
    # what this suite would have caught: the direct solver for the whole rollout (as every preset
    # solved a bouncy scene before) slides the issue's box at 30 deg to 0.33 m at 18 deg
    whole = preset(name).changed(solver={"direct_solver_for_impacts_only": False})
    box = Box("box", (0.1, 0.1, 0.05), (0.0, 0.0, 0.025), IDENTITY, friction=0.5, restitution=0.2, mass_kg=1.0,
              linear_velocity_m_s=_planar(math.radians(30.0), 2.0))
    positions, _ = _end(_scene(box, floor_restitution=0.2), whole)
    assert math.hypot(*positions[0, :2]) == pytest.approx(0.328, abs=0.01)
    assert math.degrees(math.atan2(positions[0, 1], positions[0, 0])) == pytest.approx(18.4, abs=0.5)


@pytest.mark.parametrize("name", ["paper", "default"])
def test_a_pushed_box_travels_as_far_as_its_impulse_says(name):
    # an impulse of 3 N s on a 2 kg box: 1.5 m/s, then v^2 / (2 mu g) with mu 0.8 x 0.5 = 0.4; bouncy
    # surfaces, pointed along no axis
    heading = math.radians(63.0)
    box = Box("box", (0.2, 0.1, 0.08), (0.3, -0.2, 0.04), _yaw(heading), friction=0.8, restitution=0.6, mass_kg=2.0,
              linear_velocity_m_s=_planar(heading, 3.0 / 2.0))
    positions, _ = _end(_scene(box, floor_friction=0.5, floor_restitution=0.6), name)
    travel = positions[0, :2] - np.array([0.3, -0.2])
    ratio = float(np.linalg.norm(travel)) / (1.5 ** 2 / (2 * 0.4 * G))
    off_deg = math.degrees(math.remainder(math.atan2(travel[1], travel[0]) - heading, 2 * math.pi))
    _holds(abs(ratio - 1) <= 0.02 and abs(off_deg) <= 1.0, ("push", name), f"{ratio:.3f}x at {off_deg:+.2f} deg")


@pytest.mark.parametrize("name", PRESETS)
def test_a_box_pushed_while_at_rest_stays_put_until_then_and_slides_coulombs_distance(name):
    # a known push at 0.35 s (an observation's action: Scene.pushes): at rest until it, then 1.5 m/s
    # along an axis, stopping v^2 / (2 mu g) = 0.287 m on (mu 0.4): 2%, as a slide launched at t = 0
    box = Box("box", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), IDENTITY, friction=0.4, restitution=0.0, mass_kg=0.5)
    scene = replace(_scene(box), horizon_s=1.5, pushes=(TimedPush("box", 0.35, (1.5, 0.0, 0.0)),))
    positions, _ = _end(scene, name)
    assert positions[0, 0] == pytest.approx(1.5 ** 2 / (2 * 0.4 * G), rel=0.02)
    assert abs(positions[0, 1]) < 1e-3
    early = _end(replace(scene, horizon_s=0.3), name)[0]  # the same scene seen before its push
    assert np.abs(early[0, :2]).max() < 1e-4


# -- an incline -------------------------------------------------------------------------------------

def _down_the_slope(travel_m, downhill_rad: float) -> tuple[float, float]:
    """A block's 1 s from rest down the 29 deg slope (friction 0.5): its travel as a multiple of
    g (sin theta - mu cos theta) / 2, and how far it veered off downhill, deg."""
    incline = math.radians(29.0)
    ratio = float(np.linalg.norm(travel_m)) / (0.5 * G * (math.sin(incline) - 0.5 * math.cos(incline)))
    return ratio, math.degrees(math.remainder(math.atan2(travel_m[1], travel_m[0]) - downhill_rad, 2 * math.pi))


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("downhill_deg", [0, 30, 45])
@pytest.mark.parametrize("restitution", [0.0, 0.5])
def test_a_block_on_an_incline_starts_to_slide_where_tan_theta_is_mu(name, downhill_deg, restitution):
    # friction 0.5 x 1.0: sliding from 26.6 deg. Below it the block stays (a friction box along the
    # world's axes would also hold it at 29 deg when the slope faces 45 deg: sqrt(2) mu N in all);
    # above, it accelerates at g (sin theta - mu cos theta)
    downhill = math.radians(downhill_deg)
    travels = {}
    for incline_deg in (24.0, 29.0):
        incline = math.radians(incline_deg)
        cube = Box("cube", (0.1, 0.1, 0.1), (0.0, 0.0, 0.05), IDENTITY, friction=0.5, restitution=restitution,
                   mass_kg=1.0)
        scene = _scene(cube, floor_restitution=restitution, gravity=_tilted_gravity(incline, downhill), horizon_s=1.0)
        positions, orientations = _end(scene, name)
        travels[incline_deg] = positions[0, :2]
        assert _tilt_deg(orientations[0]) < 1.0  # it slides, it does not tip (tipping needs 45 deg)
    assert float(np.linalg.norm(travels[24.0])) < 0.002
    ratio, off_deg = _down_the_slope(travels[29.0], downhill)
    assert ratio > 0.5  # it slides (a friction box along the axes would hold it at 45 deg)
    _holds(abs(ratio - 1) <= 0.05 and abs(off_deg) <= 1.0, ("incline", name, restitution, downhill_deg),
           f"{ratio:.3f}x at {off_deg:+.2f} deg")


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("downhill_deg", [0, 30, 45])
def test_a_block_on_a_block_on_an_incline_starts_to_slide_where_tan_theta_is_mu(name, downhill_deg):
    # the same cube on a 50 kg slab (friction 0.5 x 1.0), the slab held by the floor (5.0 x 1.0): what
    # slides is one dynamic body on another, the contact a stack's blocks make with each other
    downhill = math.radians(downhill_deg)
    travels = {}
    for incline_deg in (24.0, 29.0):
        slab = Box("slab", (1.6, 1.6, 0.1), (0.0, 0.0, 0.05), IDENTITY, friction=1.0, restitution=0.0, mass_kg=50.0)
        cube = Box("cube", (0.1, 0.1, 0.1), (0.0, 0.0, 0.15), IDENTITY, friction=0.5, restitution=0.0, mass_kg=1.0)
        scene = _scene(slab, cube, floor_friction=5.0, gravity=_tilted_gravity(math.radians(incline_deg), downhill),
                       horizon_s=1.0)
        positions, _ = _end(scene, name)
        travels[incline_deg] = positions[1, :2] - positions[0, :2]
    assert float(np.linalg.norm(travels[24.0])) < 0.002
    ratio, off_deg = _down_the_slope(travels[29.0], downhill)
    _holds(abs(ratio - 1) <= 0.05 and abs(off_deg) <= 1.0, ("on a block", name, downhill_deg),
           f"{ratio:.3f}x at {off_deg:+.2f} deg")


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("downhill_deg", [0, 45])
def test_a_tall_block_on_an_incline_tips_once_its_centre_of_mass_is_past_its_edge(name, downhill_deg):
    # 10 x 10 x 30 cm, friction 1.0 x 1.0 (no sliding below 45 deg): it tips from atan(10 / 30) = 18.4
    # deg when the slope faces a side (0 deg), and from atan(sqrt(2) x 10 / 30) = 25.2 deg when it faces a
    # corner (45 deg), where the base's half diagonal is the lever
    downhill = math.radians(downhill_deg)
    threshold_deg = math.degrees(math.atan((0.1 if downhill_deg == 0 else 0.1 * math.sqrt(2)) / 0.3))
    for incline_deg, tips in ((threshold_deg - 2.5, False), (threshold_deg + 2.5, True)):
        column = Box("column", (0.1, 0.1, 0.3), (0.0, 0.0, 0.15), IDENTITY, friction=1.0, restitution=0.0, mass_kg=1.0)
        scene = _scene(column, gravity=_tilted_gravity(math.radians(incline_deg), downhill), horizon_s=1.5)
        _, orientations = _end(scene, name)
        assert (_tilt_deg(orientations[0]) > 45.0) is tips, (incline_deg, _tilt_deg(orientations[0]))


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("downhill_deg", [0, 30, 45])
@pytest.mark.parametrize("restitution", [0.0, 0.5])
def test_a_ball_rolls_down_a_slope_at_five_sevenths_g_sin_theta(name, downhill_deg, restitution):
    # 10 deg, friction 0.5 x 1.0 (rolling needs only 2/7 tan theta = 0.05): 1 s rolls 0.608 m; a ball
    # sliding without friction would go 0.852 m
    incline, downhill = math.radians(10.0), math.radians(downhill_deg)
    ball = _ball("ball", (0.0, 0.0, 0.05), restitution=restitution)
    scene = _scene(ball, floor_restitution=restitution, gravity=_tilted_gravity(incline, downhill), horizon_s=1.0)
    positions, _ = _end(scene, name)
    travel = positions[0, :2]
    assert float(np.linalg.norm(travel)) == pytest.approx(0.5 * 5 / 7 * G * math.sin(incline), rel=0.02)
    assert abs(math.degrees(math.remainder(math.atan2(travel[1], travel[0]) - downhill, 2 * math.pi))) <= 1.0


# -- impacts ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("restitution", [0.5, 0.64])
@pytest.mark.parametrize("h", [0.2, 0.5])
def test_a_dropped_ball_bounces_back_to_e_squared_of_its_height(name, restitution, h):
    # a ball h above the floor (landing at 2.0 or 3.1 m/s); ball and floor each sqrt(e) (Bullet
    # multiplies them). The rollout ends at the apex after the first bounce: sqrt(2h/g) down, e v / g up
    radius, e = 0.05, restitution
    each = math.sqrt(e)
    ball = _ball("ball", (0.1, -0.2, h + radius), radius_m=radius, restitution=each)
    landing_m_s = math.sqrt(2 * G * h)
    apex_s = landing_m_s / G + e * landing_m_s / G
    positions, _ = _end(_scene(ball, floor_restitution=each, horizon_s=round(apex_s, 3)), name)
    ratio = (positions[0, 2] - radius) / (e ** 2 * h)
    _holds(abs(ratio - 1) <= 0.03, ("bounce", name, e, h), f"{ratio:.3f}x e^2 h")
    assert positions[0, :2] == pytest.approx([0.1, -0.2], abs=1e-4)


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("heading_deg", [0, 30, 45])
def test_a_head_on_collision_keeps_momentum_and_gives_back_its_restitution(name, heading_deg):
    # two 1 kg balls on a frictionless floor that does not bounce; ball-ball restitution 0.7 x 0.7 =
    # 0.49. A at 1 m/s meets B at rest 0.2 s later: then A goes on at (1 - e) / 2, B at (1 + e) / 2
    heading, e, v, gap_s, horizon_s = math.radians(heading_deg), 0.49, 1.0, 0.2, 1.0
    a = _ball("a", _planar(heading, 0.0, 0.05), friction=0.0, restitution=0.7, linear_velocity_m_s=_planar(heading, v))
    b = _ball("b", _planar(heading, 0.1 + v * gap_s, 0.05), friction=0.0, restitution=0.7)
    positions, _ = _end(_scene(a, b, floor_friction=0.0, horizon_s=horizon_s), name)
    along = np.array(_planar(heading, 1.0))
    after_s = horizon_s - gap_s
    a_after = (float(positions[0] @ along) - v * gap_s) / after_s
    b_after = (float(positions[1] @ along) - (0.1 + v * gap_s)) / after_s
    assert a_after + b_after == pytest.approx(v, rel=0.01)  # momentum, equal masses
    given_back = (b_after - a_after) / v
    _holds(abs(given_back - e) <= 0.03, ("collision", name, heading_deg), f"restitution {given_back:.3f}")
    sideways = positions[:, :2] @ np.array([-math.sin(heading), math.cos(heading)])
    assert np.abs(sideways).max() < 1e-3


def test_the_contact_erp_the_engine_restores_after_an_impact_is_bullets_own():
    # simulation/world.py: an impact's step runs without penetration recovery, and the steps after
    # get BULLET_CONTACT_ERP back: it must be what pybullet starts with (it has no getter), or every
    # world that once bounced would settle differently. A box sunk 5 mm pushed out, both ways.
    from ipe_ros.engine.simulation.bullet import pybullet
    from ipe_ros.engine.simulation.world import BULLET_CONTACT_ERP

    p = pybullet()

    def heights(contact_erp):
        cid = p.connect(p.DIRECT)
        try:
            p.setGravity(0, 0, -G, physicsClientId=cid)
            p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid)
            box = p.createMultiBody(1.0, p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.05] * 3, physicsClientId=cid),
                                    basePosition=[0, 0, 0.045], useMaximalCoordinates=True, physicsClientId=cid)
            if contact_erp is not None:
                p.setPhysicsEngineParameter(contactERP=contact_erp, physicsClientId=cid)
            out = []
            for _ in range(50):
                p.stepSimulation(physicsClientId=cid)
                out.append(p.getBasePositionAndOrientation(box, physicsClientId=cid)[0][2])
            return out
        finally:
            p.disconnect(cid)

    as_it_comes = heights(None)
    assert heights(BULLET_CONTACT_ERP) == as_it_comes
    assert heights(BULLET_CONTACT_ERP * 1.25) != as_it_comes  # the parameter matters here


@pytest.mark.parametrize("closing_m_s, bounces", [(0.15, False), (0.3, True)])
def test_bullet_bounces_only_contacts_closing_faster_than_the_threshold_the_engine_assumes(closing_m_s, bounces):
    # simulation/impacts.py takes the direct solver for contacts closing faster than this: it must be
    # pybullet's own threshold. pybullet alone, its contacts solved only once they touch (found
    # ahead, a slow contact loses its bounce anyway: ``SolverSettings.bounce_from_touch``), a ball with restitution
    # 1 x 1 and gravity almost off
    from ipe_ros.engine.simulation.bullet import pybullet
    from ipe_ros.engine.simulation.impacts import RESTITUTION_THRESHOLD_M_S

    assert 0.15 < RESTITUTION_THRESHOLD_M_S < 0.3
    p = pybullet()
    cid = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -1e-3, physicsClientId=cid)
        p.setTimeStep(0.001, physicsClientId=cid)
        floor = p.createMultiBody(0, p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid), physicsClientId=cid)
        ball = p.createMultiBody(1.0, p.createCollisionShape(p.GEOM_SPHERE, radius=0.05, physicsClientId=cid),
                                 basePosition=[0, 0, 0.06], useMaximalCoordinates=True, physicsClientId=cid)
        for body in (floor, ball):
            p.changeDynamics(body, -1, restitution=1.0, contactProcessingThreshold=0.0, linearDamping=0.0,
                             physicsClientId=cid)
        p.resetBaseVelocity(ball, [0, 0, -closing_m_s], [0, 0, 0], physicsClientId=cid)
        for _ in range(300):
            p.stepSimulation(physicsClientId=cid)
        rising_m_s = p.getBaseVelocity(ball, physicsClientId=cid)[0][2]
    finally:
        p.disconnect(cid)
    assert (rising_m_s > 0.5 * closing_m_s) is bounces, rising_m_s


# -- a stack ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("direction_deg", [0, 45])
def test_a_block_on_a_block_falls_once_its_centre_of_mass_is_past_the_edge(name, direction_deg):
    # two 20 cm cubes; the top one offset along a face normal (0 deg) or a diagonal (45 deg), where
    # the edge is 10 cm away along x and y alike
    direction = math.radians(direction_deg)
    edge_m = 0.1 / max(abs(math.cos(direction)), abs(math.sin(direction)))
    for fraction, falls in ((0.9, False), (1.1, True)):
        bottom = Box("bottom", (0.2, 0.2, 0.2), (0.0, 0.0, 0.1), IDENTITY, friction=0.8, restitution=0.0, mass_kg=1.0)
        top = Box("top", (0.2, 0.2, 0.2), _planar(direction, fraction * edge_m, 0.3), IDENTITY, friction=0.8,
                  restitution=0.0, mass_kg=1.0)
        positions, _ = _end(_scene(bottom, top), name)
        assert bool(positions[1, 2] < 0.2) is falls, (fraction, positions[1])


# -- turned scenes ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["paper", "default"])
def test_a_bouncy_scene_turned_about_the_vertical_ends_turned(name):
    # a ball thrown across a bouncy floor into a box that slides off: every contact has friction and
    # restitution, so both solvers take part. Turned by 37 deg, it must end turned by 37 deg (to a
    # millimetre: both run the same physics in another frame, up to rounding)
    ball = _ball("ball", (-0.4, 0.05, 0.05), restitution=0.6, friction=0.6, linear_velocity_m_s=(3.0, 0.0, 0.5))
    box = Box("box", (0.1, 0.2, 0.1), (0.1, 0.0, 0.05), _yaw(0.3), friction=0.6, restitution=0.6, mass_kg=0.5)
    scene = _scene(ball, box, floor_restitution=0.6, horizon_s=1.5)
    yaw = math.radians(37.0)
    straight, _ = _end(scene, name)
    ends_turned, _ = _end(turned(scene, yaw), name)
    expected = np.array([turned(replace(scene, objects=tuple(replace(b, position_m=tuple(p)) for b, p in
                                                             zip(scene.objects, straight))), yaw).objects[i].position_m
                         for i in range(2)])
    assert float(np.linalg.norm(straight[1, :2] - [0.1, 0.0])) > 0.05  # the box was struck and moved
    _holds(np.abs(ends_turned - expected).max() < 0.002, ("turned", name), f"{np.abs(ends_turned - expected).max():.4f} m apart")
