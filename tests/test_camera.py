"""The camera model follows ROS's camera_info convention (image_geometry, OpenCV): pixel (u, v)'s centre
at image coordinates (u, v), its ray ((u - cx) / fx, (v - cy) / fy, 1). Checked against depth written
here from that formula alone (no code shared with the engine's renderer, rays or rasteriser), and
against pybullet's renderer. Tolerances stated per test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipe_ros.engine import Box, ConfigError, Floor, Scene
from ipe_ros.engine.vision import depth as D
from ipe_ros.engine.vision.camera import PinholeCamera, camera_from_info
from ipe_ros.engine.vision.tinyrenderer import depth_with_pybullet

I = (0.0, 0.0, 0.0, 1.0)


def optical_orientation(eye, target, roll_rad=0.0) -> tuple[float, float, float, float]:
    """xyzw of an optical frame (z forward, x right, y down) at ``eye`` looking at ``target``, turned
    ``roll_rad`` about its view axis: written out here, not taken from the engine."""
    z = np.subtract(target, eye) / np.linalg.norm(np.subtract(target, eye))
    x = np.cross(z, (0.0, 0.0, 1.0))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    x, y = c * x + s * y, -s * x + c * y
    m = np.stack([x, y, z], axis=1)  # columns: the optical axes in the scene frame
    w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
    q = np.array([(m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w), w])
    return tuple(float(v) for v in q / np.linalg.norm(q))


def pixel_rays(fx, fy, cx, cy, width, height, orientation_xyzw) -> np.ndarray:
    """(height, width, 3) scene-frame rays ((u - cx) / fx, (v - cy) / fy, 1) of every pixel."""
    x, y, z, w = orientation_xyzw
    rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    local = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u, float)], axis=-1)
    return local @ rotation.T


def analytic_depth(rays, eye, boxes) -> np.ndarray:
    """Depth along the optical axis of the floor z = 0 and of upright boxes (centre, yaw, half sizes)
    by ray casting (slab test); NaN where a ray meets nothing."""
    eye = np.asarray(eye, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        floor_t = -eye[2] / rays[..., 2]
    depth = np.where(floor_t > 0, floor_t, np.inf)
    for centre, yaw, half in boxes:
        c, s = math.cos(yaw), math.sin(yaw)
        to_box = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # scene -> box frame
        origin, direction = to_box @ (eye - np.asarray(centre)), rays @ to_box.T
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-np.asarray(half) - origin) / direction, (np.asarray(half) - origin) / direction
        near, far = np.minimum(t1, t2).max(axis=-1), np.maximum(t1, t2).min(axis=-1)
        hit = (near <= far) & (near > 0)
        depth = np.where(hit & (near < depth), near, depth)
    return np.where(np.isfinite(depth), depth, np.nan)


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
    within 0.3 mm of the truth from the analytic image (a half-pixel convention error shifts it by
    ~1.2 mm), its yaw within 0.02 rad (the posterior's SD of yaw is 4-8 mrad here)."""
    truth = analytic_depth(RAYS, EYE, BOXES[:1])
    (centre, yaw, half), = BOXES[:1]
    guess = scene_of(box("b0", (centre[0] + 0.02, centre[1] - 0.015, centre[2]), yaw + 0.1, 2 * np.asarray(half)))
    posterior = D.run_depth_chain(guess, (D.DepthObservation(CAMERA, truth),), D.DepthSettings(pixel_stride=1),
                                  np.random.default_rng(4))
    mean_xy = posterior.positions_m[:, 0, :2].mean(axis=0)
    mean_yaw = float(posterior.yaws_rad[:, 0].mean())  # a turn from the guess's orientation
    assert np.hypot(*(mean_xy - centre[:2])) < 3e-4, mean_xy - centre[:2]
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
