"""Lens models (kubric.core.lenses) and the camera geometry through them, checked against OpenCV
itself (cv2.projectPoints, cv2.fisheye.projectPoints, cv2.undistortPoints)."""

import math

import numpy as np
import pytest

import kubric as kb
from kubric.core import camera_geometry as geo
from kubric.core import lenses

cv2 = pytest.importorskip("cv2")

BROWN = lenses.BrownConrady(k1=-0.28, k2=0.09, p1=0.0012, p2=-0.0008, k3=-0.012, k4=0.02,
                            k5=-0.004, k6=0.001)
FISHEYE = lenses.Fisheye(k1=0.04, k2=-0.012, k3=0.003, k4=-0.0004)
K = np.array([[410.0, 0.0, 160.3], [0.0, 410.0, 119.6], [0.0, 0.0, 1.0]])


def _cv_project(lens, points, k=K, rvec=None, tvec=None):
    """OpenCV's pixel positions of (N, 3) points (OpenCV frame after rvec / tvec)."""
    rvec = np.zeros(3) if rvec is None else rvec
    tvec = np.zeros(3) if tvec is None else tvec
    coeffs = np.asarray(lens.coefficients, np.float64)
    if isinstance(lens, lenses.Fisheye):
        out, _ = cv2.fisheye.projectPoints(points[:, None], rvec, tvec, k, coeffs)
    else:
        out, _ = cv2.projectPoints(points, rvec, tvec, k, coeffs)
    return out[:, 0]


def _points_in_domain(lens, rng, n=2000):
    """Random OpenCV-frame points in front of the camera inside the lens's domain."""
    edge = min(lens.domain_radius(), 3.0) * 0.98
    r = edge * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    z = rng.uniform(0.3, 20.0, n)
    return np.stack([r * np.cos(phi) * z, r * np.sin(phi) * z, z], -1)


@pytest.mark.parametrize("lens", [BROWN, FISHEYE], ids=["opencv", "fisheye"])
def test_project_matches_opencv(lens):
    points = _points_in_domain(lens, np.random.RandomState(1))
    xy_d = lens.project(points)
    assert np.isfinite(xy_d).all()
    ours = xy_d * [K[0, 0], K[1, 1]] + K[:2, 2]
    assert np.abs(ours - _cv_project(lens, points)).max() < 1e-6


@pytest.mark.parametrize("lens", [BROWN, FISHEYE], ids=["opencv", "fisheye"])
def test_undistort_inverts_opencv_projection(lens):
    points = _points_in_domain(lens, np.random.RandomState(2))
    pix = _cv_project(lens, points)
    xy_d = (pix - K[:2, 2]) / [K[0, 0], K[1, 1]]
    ab = lens.undistort(xy_d)
    truth = points[:, :2] / points[:, 2:]
    assert np.isfinite(ab).all()
    assert np.abs((ab - truth) * K[0, 0]).max() < 1e-6  # in pixels


def test_undistort_agrees_with_cv2_undistort_points():
    rng = np.random.RandomState(3)
    pix = rng.uniform([0, 0], [320, 240], (500, 2))
    ours = BROWN.undistort((pix - K[:2, 2]) / [K[0, 0], K[1, 1]])
    theirs = cv2.undistortPointsIter(pix[:, None], K, np.asarray(BROWN.coefficients), None,
                                     None, (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                            200, 1e-15))[:, 0]
    assert np.abs((ours - theirs) * K[0, 0]).max() < 1e-6
    fish = cv2.fisheye.undistortPoints(pix[:, None], K, np.asarray(FISHEYE.coefficients),
                                       criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS,
                                                 200, 1e-15))[:, 0]
    ours = FISHEYE.undistort((pix - K[:2, 2]) / [K[0, 0], K[1, 1]])
    assert np.abs((ours - fish) * K[0, 0]).max() < 1e-6


def test_domain_edges_are_where_the_radial_map_turns():
    k1 = -0.2  # ρ = r + k1 r³ turns at r = sqrt(-1 / (3 k1))
    brown = lenses.BrownConrady(k1=k1)
    assert brown.domain_radius() == pytest.approx(math.sqrt(-1 / (3 * k1)), rel=1e-9)
    fish = lenses.Fisheye(k1=-0.3)  # θd = θ + k1 θ³ turns at θ = sqrt(-1 / (3 k1)) < π/2
    assert fish.max_angle == pytest.approx(math.sqrt(-1 / (3 * -0.3)), rel=1e-9)
    assert lenses.Fisheye().max_angle == pytest.approx(math.pi / 2)
    # beyond the edge: no image position; beyond the edge's image: no ray
    edge = brown.domain_radius()
    out = brown.distort([[edge * 1.01, 0.0], [edge * 0.99, 0.0]])
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()
    top = float(brown.radial(np.array([edge]))[0])
    back = brown.undistort([[top * 1.01, 0.0], [top * 0.99, 0.0]])
    assert np.isnan(back[0]).all() and np.isfinite(back[1]).all()
    assert np.isnan(brown.project([[0.0, 0.0, -1.0]])).all()  # behind the camera


def test_lens_records_and_bad_values():
    assert BROWN.record() == {"model": "opencv", "coefficients": list(BROWN.coefficients)}
    assert lenses.from_record("opencv", BROWN.coefficients) == BROWN
    assert lenses.from_record("fisheye", FISHEYE.coefficients) == FISHEYE
    assert lenses.from_record("opencv", [0.1, 0, 0, 0]) == lenses.BrownConrady(k1=0.1)
    assert lenses.from_record("none") is lenses.PINHOLE
    with pytest.raises(ValueError, match="unknown lens model 'kb'.*allowed"):
        lenses.from_record("kb", [])
    with pytest.raises(ValueError, match="4, 5 or 8 values"):
        lenses.from_record("opencv", [0.1, 0.2])
    with pytest.raises(ValueError, match="4 finite coefficients"):
        lenses.Fisheye(k1=float("nan"))
    with pytest.raises(TypeError, match="PerspectiveCamera.lens must be"):
        kb.PerspectiveCamera(lens="fisheye")


def _camera_scene(lens):
    scene = kb.Scene(resolution=(320, 240))
    cam = kb.PerspectiveCamera(name="camera", focal_length=24.0, sensor_width=32.0, shift_x=0.02,
                               shift_y=-0.03, lens=lens, position=(3.0, -4.0, 2.5))
    scene += cam
    cam.look_at((0.2, 0.1, 0.3))
    return scene, cam


def _opencv_pose(cam):
    """(rvec, tvec) of the world → OpenCV camera transform."""
    m = geo.world_to_camera(cam)
    rot = geo.CAMERA_TO_OPENCV @ m[:3, :3]
    return cv2.Rodrigues(rot)[0][:, 0], geo.CAMERA_TO_OPENCV @ m[:3, 3]


@pytest.mark.parametrize("lens", [BROWN, FISHEYE], ids=["opencv", "fisheye"])
def test_camera_projection_is_opencvs(lens):
    scene, cam = _camera_scene(lens)
    rng = np.random.RandomState(4)
    world = rng.uniform(-1.5, 1.5, (3000, 3))
    xy, depth = geo.project_to_pixels(cam, world)
    rvec, tvec = _opencv_pose(cam)
    theirs = _cv_project(lens, world, cam.intrinsics_pixels, rvec, tvec)
    ok = np.isfinite(xy).all(1)
    assert ok.mean() > 0.9
    assert np.abs(xy[ok] - theirs[ok]).max() < 1e-6
    uvs = cam.project_point(world)
    assert np.abs(uvs[ok, :2] * [320, 240] - theirs[ok]).max() < 1e-6
    assert (uvs[ok, 2] == 1).all() and (uvs[~ok, 2] == -1).all()
    # the pixel ray through the projection passes through the point: unproject inverts it
    back = geo.unproject_pixels(cam, xy[ok], depth[ok])
    assert np.abs(back - world[ok]).max() < 1e-9


def test_pinhole_lens_is_todays_pinhole():
    _, plain = _camera_scene(None)
    _, explicit = _camera_scene(lenses.PINHOLE)
    _, almost = _camera_scene(lenses.BrownConrady())  # zero coefficients: the same camera
    world = np.random.RandomState(5).uniform(-1, 1, (100, 3))
    a, b, c = (geo.project_to_pixels(cam, world)[0] for cam in (plain, explicit, almost))
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() < 1e-9
    pixels = geo.pixel_centres(240, 320)
    assert np.abs(geo.pixel_rays(plain, pixels)[1] - geo.pixel_rays(almost, pixels)[1]).max() \
        < 1e-12


def test_depth_to_z_through_the_lens():
    _, cam = _camera_scene(FISHEYE)
    pixels = geo.pixel_centres(240, 320)
    _, dirs = geo.pixel_rays(cam, pixels)
    depth = np.random.RandomState(6).uniform(1, 5, (240, 320))
    points = geo.unproject_pixels(cam, pixels, depth)
    m = geo.world_to_camera(cam)
    z = -(points @ m[2, :3] + m[2, 3])
    assert np.abs(geo.depth_to_z(cam, depth) - z).max() < 1e-4  # float32 result


def test_dataset_rays_of_a_recorded_lens_are_the_cameras():
    """The nerf_rays task's rays from the recorded numbers (intrinsics, pose, distortion) equal
    the camera's own pixel rays."""
    from kubric.annotations.metadata import get_camera_info
    from kubric.datasets import tasks

    for lens in (BROWN, FISHEYE, None):
        _, cam = _camera_scene(lens)
        info = get_camera_info(cam, frames=[0])
        recorded = {k: np.asarray(v, np.float32) if k != "distortion_model" else v.encode()
                    for k, v in info.items() if k in ("intrinsics_pixels", "distortion_model",
                                                      "distortion_coefficients")}
        origins, dirs = tasks.pixel_rays(recorded["intrinsics_pixels"], info["matrices_world"][0],
                                         240, 320, lenses.from_camera_record(recorded))
        _, truth = geo.pixel_rays(cam, geo.pixel_centres(240, 320))
        assert np.abs(dirs - truth).max() < 1e-6


@pytest.mark.parametrize("lens", [BROWN, FISHEYE], ids=["opencv", "fisheye"])
def test_character_keypoints_are_opencvs_projection(lens):
    """The keypoint annotation of a walking (procedural) person seen by a moving lens camera:
    keypoints_2d = cv2.projectPoints / cv2.fisheye.projectPoints of keypoints_3d (< 1e-3 px)."""
    from character_fixtures import walking_scene

    from kubric.annotations.keypoints import character_keypoints

    scene, person = walking_scene(frames=3)
    scene.camera.lens = lens
    frames = [1, 2, 3]
    depth = np.full((3, 64, 64, 1), geo.BACKGROUND_DEPTH, np.float32)  # occlusion is not tested
    seg = np.zeros((3, 64, 64, 1), np.uint32)
    out = character_keypoints(scene.camera, frames, depth, seg, scene.assets, person)
    for t, f in enumerate(frames):
        with scene.camera.at_frame(f):
            rvec, tvec = _opencv_pose(scene.camera)
            k = scene.camera.intrinsics_pixels
        theirs = _cv_project(lens, out["keypoints_3d"][t].astype(np.float64), k, rvec, tvec)
        assert np.abs(out["keypoints_2d"][t] - theirs).max() < 1e-3
