"""The camera model follows ROS's camera_info convention (image_geometry, OpenCV): pixel (u, v)'s centre
at image coordinates (u, v), its ray ((u - cx) / fx, (v - cy) / fy, 1). Checked against depth written
from that formula alone (tests/analytic_camera.py: no code shared with the engine's renderer, rays or
rasteriser), and against pybullet's renderer. Tolerances stated per test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipe_ros.engine import Body, Box, ConfigError, Floor, Scene
from ipe_ros.engine.vision import depth as D
from ipe_ros.engine.vision.camera import PinholeCamera, camera_from_info
from ipe_ros.engine.vision.tinyrenderer import depth_with_pybullet
from tests.analytic_camera import analytic_depth, optical_orientation, pixel_rays

I = (0.0, 0.0, 0.0, 1.0)


def box(name, centre, yaw, size):
    return Box(name=name, extents_m=tuple(size), position_m=tuple(centre),
               orientation_xyzw=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)), friction=0.6, restitution=0.0,
               mass_kg=1.0)


def scene_of(*objects) -> Scene:
    return Scene(name="camera", objects=objects, support=Floor(friction=0.6, restitution=0.0),
                 gravity_m_s2=(0.0, 0.0, -9.81))


EYE = (0.9, -0.75, 0.7)
#: an off-centre principal point, unequal focal lengths and a rolled camera: every convention error shows
INTRINSICS = dict(fx=530.0, fy=520.0, cx=331.3, cy=236.8, width=640, height=480)
ORIENTATION = optical_orientation(EYE, (0.0, 0.0, 0.1), roll_rad=0.15)
CAMERA = PinholeCamera(fx=INTRINSICS["fx"], fy=INTRINSICS["fy"], cx=INTRINSICS["cx"], cy=INTRINSICS["cy"],
                       width_px=640, height_px=480, position_m=EYE, orientation_xyzw=ORIENTATION)
RAYS = pixel_rays(*INTRINSICS.values(), ORIENTATION)
BOXES = (((0.02, -0.01, 0.05), 0.3, (0.06, 0.045, 0.05)), ((0.01, 0.0, 0.14), -0.2, (0.04, 0.04, 0.04)))
SCENE = scene_of(*(box(f"b{i}", c, yaw, 2 * np.asarray(half)) for i, (c, yaw, half) in enumerate(BOXES)))


def test_the_floor_and_boxes_render_as_camera_info_places_pixel_centres():
    truth = analytic_depth(RAYS, EYE, BOXES)
    floor_only = analytic_depth(RAYS, EYE, ())
    assert np.allclose(D.support_depth_m(SCENE, CAMERA), floor_only, rtol=1e-9, atol=0, equal_nan=True)
    ours = D.render_depth_m(SCENE, CAMERA)
    assert np.array_equal(np.isfinite(ours), np.isfinite(truth))  # the top rows look over the horizon
    close = ~np.isfinite(truth) | (np.abs(ours - truth) < 1e-6)
    # pixels whose centre lies within a float's reach of a silhouette edge may go either way; a half-pixel
    # shift would put ~2 rows and columns of every box edge (hundreds of pixels) apart
    assert (~close).sum() <= 3, int((~close).sum())


def test_pybullets_renderer_agrees_with_the_formula():
    """The independent evidence (tests, benchmarks) samples the same pixel centres: the floor to 0.1 mm
    everywhere, the boxes except along their silhouettes (within one pixel)."""
    truth = analytic_depth(RAYS, EYE, BOXES)
    theirs = depth_with_pybullet(SCENE, CAMERA)
    within = truth < 7.5  # its far plane is 8 m
    assert np.isfinite(theirs[within]).all()
    error = np.abs(theirs - truth)[within]
    assert np.median(error) < 1e-4 and np.mean(error < 1e-3) > 0.99


@pytest.mark.slow
def test_a_box_pose_is_recovered_far_below_a_pixel():
    """At 1.3 m one pixel is 2.5 mm wide: the posterior mean of a box guessed 2 cm and 0.1 rad off lands
    within 0.5 mm of the truth from the analytic image (0.12-0.31 mm measured; the half-pixel convention
    error put it 1.9 mm off), its yaw within 0.02 rad (the posterior's SD of yaw is 4-8 mrad here)."""
    truth = analytic_depth(RAYS, EYE, BOXES[:1])
    (centre, yaw, half), = BOXES[:1]
    guess = scene_of(box("b0", (centre[0] + 0.02, centre[1] - 0.015, centre[2]), yaw + 0.1, 2 * np.asarray(half)))
    posterior = D.run_depth_chain(guess, (D.DepthObservation(CAMERA, truth),), D.DepthSettings(pixel_stride=1),
                                  np.random.default_rng(4))
    mean_xy = posterior.positions_m[:, 0, :2].mean(axis=0)
    mean_yaw = float(posterior.yaws_rad[:, 0].mean())  # a turn from the guess's orientation
    assert np.hypot(*(mean_xy - centre[:2])) < 5e-4, mean_xy - centre[:2]
    assert abs(mean_yaw + 0.1) < 0.02, mean_yaw


def test_camera_info_is_read_as_image_geometry_reads_it():
    k = [500.0, 0.0, 319.5, 0.0, 505.0, 239.5, 0.0, 0.0, 1.0]
    p = [480.0, 0.0, 321.0, 0.0, 0.0, 490.0, 241.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    pose = ((0.0, 0.0, 1.0), I)
    rectified = camera_from_info({"width": 640, "height": 480, "k": k, "p": p, "d": [0.1, -0.05, 0.0, 0.0, 0.0]}, *pose)
    assert (rectified.fx, rectified.fy, rectified.cx, rectified.cy) == (480.0, 490.0, 321.0, 241.0)  # P, not K
    binned = camera_from_info({"width": 640, "height": 480, "k": k, "p": p, "binning_x": 2, "binning_y": 2}, *pose)
    assert (binned.width_px, binned.height_px, binned.fx, binned.cx) == (320, 240, 240.0, 160.5)
    roi = camera_from_info({"width": 640, "height": 480, "k": k, "d": [0.0] * 5,
                            "roi": {"x_offset": 100, "y_offset": 40, "width": 200, "height": 100}}, *pose)
    assert (roi.width_px, roi.height_px, roi.cx, roi.cy) == (200, 100, 219.5, 199.5)
    yaml_form = camera_from_info({"image_width": 640, "image_height": 480, "camera_matrix": {"data": k},
                                  "distortion_coefficients": {"data": [0.0] * 5}}, *pose)
    assert (yaml_form.fx, yaml_form.cx) == (500.0, 319.5)
    with pytest.raises(ConfigError, match=r"^camera_info.d: are not zero \(0.1, 0, 0, 0, 0\) and there is no "
                                          r"projection matrix: rectify the image"):
        camera_from_info({"width": 640, "height": 480, "k": k, "d": [0.1, 0, 0, 0, 0]}, *pose)
    with pytest.raises(ConfigError, match=r"^camera_info.p: must hold the 12 numbers of P"):
        camera_from_info({"width": 640, "height": 480, "k": k, "p": [1.0] * 9}, *pose)


@pytest.mark.slow
def test_a_mug_from_its_mesh_is_found_where_it_stands():
    """Depth perception of a mesh object: the image is the true mug's triangles (a handle on one side,
    the rest round) ray-cast here, by no code of the engine's, with 1 mm noise; the engine's
    likelihood casts the mug's convex parts, which stand up to a millimetre proud of the mesh. The
    detector's guess is 1.8 cm and 0.15 rad off: the posterior mean lands within 1.5 mm of the truth
    (0.7 mm measured) and its turn within 0.03 rad (0.009; the handle alone tells the turn)."""
    from ipe_ros.engine.scene import household
    from ipe_ros.engine.scene.meshes import MeshAccess, triangles_shape
    from tests.analytic_camera import triangles_entry

    vertices, faces = household.mug()
    shape = triangles_shape(vertices[faces].reshape(-1, 3), "mug", MeshAccess(roots=()))
    centre, yaw = np.array([0.02, -0.01, 0.0]), 0.6
    turn = np.array([[math.cos(yaw), -math.sin(yaw), 0.0], [math.sin(yaw), math.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    truth = np.fmin(analytic_depth(RAYS, EYE, ()), triangles_entry(RAYS, EYE, vertices[faces] @ turn.T + centre))
    measured = truth + 0.001 * np.random.default_rng(2).standard_normal(truth.shape)

    def mug_at(position, turn_rad):
        return Body(name="mug", shape=shape, position_m=tuple(position), friction=0.6, restitution=0.0,
                    orientation_xyzw=(0.0, 0.0, math.sin(turn_rad / 2), math.cos(turn_rad / 2)), mass_kg=0.3)

    guess = scene_of(mug_at(centre + [0.015, -0.01, 0.0], yaw + 0.15))
    # a short chain: where it ends up is the question here, not its calibration
    settings = D.DepthSettings(kept_states=16, burn_in_sweeps=4, locate_rounds=12)
    posterior = D.run_depth_chain(guess, (D.DepthObservation(CAMERA, measured),), settings, np.random.default_rng(3))
    mean_xy = posterior.positions_m[:, 0, :2].mean(axis=0)
    mean_turn = float(posterior.yaws_rad[:, 0].mean())  # from the guess's orientation
    assert np.hypot(*(mean_xy - centre[:2])) < 1.5e-3, mean_xy - centre[:2]
    assert abs(mean_turn + 0.15) < 0.03, mean_turn
