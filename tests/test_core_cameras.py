"""Camera geometry: intrinsics, projection, unprojection, depth conventions."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import kubric as kb
from kubric.core import camera_geometry as geo


def _scene_with(camera, resolution=(64, 48)):
    scene = kb.Scene(resolution=resolution)
    scene += camera
    return scene


def test_field_of_view_28mm_on_36mm_sensor():
    cam = kb.PerspectiveCamera(focal_length=28, sensor_width=36)
    assert cam.field_of_view == pytest.approx(1.1427, abs=1e-4)
    cam.field_of_view = 1.0
    assert cam.focal_length == pytest.approx(36 / (2 * np.tan(0.5)))


def test_normalised_intrinsics_upstream_form():
    cam = kb.PerspectiveCamera(focal_length=35, sensor_width=32)
    _scene_with(cam, (256, 128))
    sh = 32 * 128 / 256
    np.testing.assert_allclose(cam.intrinsics,
                               [[35 / 32, 0, -0.5], [0, -35 / sh, -0.5], [0, 0, -1]])
    k = cam.intrinsics_pixels
    np.testing.assert_allclose(k, [[35 / 32 * 256, 0, 128], [0, 35 / 32 * 256, 64], [0, 0, 1]])


def test_project_point_centre_corner_and_behind():
    cam = kb.PerspectiveCamera(position=(0, 0, 0), look_at=(0, 1, 0), focal_length=18,
                               sensor_width=36)  # looks along +Y: right = +X, up = +Z; 90° fov
    _scene_with(cam, (100, 100))
    np.testing.assert_allclose(cam.project_point([0, 5, 0]), [0.5, 0.5, 1], atol=1e-6)
    # a point at 45° to the right and 45° up is at the top-right corner (v is down)
    np.testing.assert_allclose(cam.project_point([5, 5, 5]), [1.0, 0.0, 1], atol=1e-6)
    assert cam.project_point([0, -5, 0])[2] == -1


def test_orthographic_projection_and_shift():
    cam = kb.OrthographicCamera(position=(0, 0, 10), look_at=(0, 0, 0), orthographic_scale=4)
    _scene_with(cam, (40, 20))
    # looking straight down, look_at falls back to camera x = world −X, camera y = world −Y
    np.testing.assert_allclose(cam.project_point([1, 0.5, 0]), [0.25, 0.75, 1], atol=1e-6)
    xy, depth = geo.project_to_pixels(cam, [[1, 0.5, 0]])
    assert depth[0] == pytest.approx(10)
    shifted = kb.PerspectiveCamera(look_at=(0, 0, -1), shift_x=0.1, shift_y=0.05)
    _scene_with(shifted, (100, 50))
    u, v, _ = shifted.project_point([0, 0, -3])
    assert (u, v) == (pytest.approx(0.4), pytest.approx(0.6))


def test_z_to_depth_and_back():
    cam = kb.PerspectiveCamera(focal_length=35, sensor_width=32)
    _scene_with(cam, (8, 6))
    z = np.full((2, 6, 8, 1), 3.0, dtype=np.float32)
    depth = cam.z_to_depth(z)
    assert depth.shape == z.shape
    # the corner pixel centre's ray: offsets in normalised units
    fx = 35 / 32
    dx, dy = (0.5 / 8 - 0.5) / fx, (0.5 / 6 - 0.5) / (fx * 8 / 6)
    assert depth[0, 0, 0, 0] == pytest.approx(3 * np.sqrt(1 + dx**2 + dy**2), rel=1e-6)
    np.testing.assert_allclose(cam.depth_to_z(depth), z, rtol=1e-6)


def test_per_frame_matrices_follow_keyframes():
    cam = kb.PerspectiveCamera(position=(0, 0, 0))
    cam.keyframe_insert("position", 0)
    cam.position = (2, 0, 0)
    cam.keyframe_insert("position", 2)
    mats = geo.camera_to_world_matrices(cam, [0, 1, 2])
    np.testing.assert_allclose(mats[:, 0, 3], [0, 1, 2])
    w2c = geo.world_to_camera(cam, 1)
    np.testing.assert_allclose(w2c @ mats[1], np.eye(4), atol=1e-6)


finite = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), width=st.integers(8, 640), height=st.integers(8, 480),
       focal=st.floats(10, 100), shift=st.tuples(finite, finite))
def test_project_unproject_round_trip_per_frame(seed, width, height, focal, shift):
    rng = np.random.RandomState(seed)
    cam = kb.PerspectiveCamera(focal_length=focal, sensor_width=36,
                               shift_x=0.2 * shift[0], shift_y=0.2 * shift[1])
    _scene_with(cam, (width, height))
    for frame in range(3):  # a different pose per frame
        cam.position = rng.uniform(-5, 5, 3)
        cam.quaternion = kb.randomness.random_rotation(rng=rng)
        cam.keyframe_insert("position", frame)
        cam.keyframe_insert("quaternion", frame)
    points = rng.uniform(-10, 10, (50, 3))
    for frame in range(3):
        xy, depth = geo.project_to_pixels(cam, points, frame)
        back = geo.unproject_pixels(cam, xy, depth, frame)
        in_front = geo.project_points(cam, points, frame)[:, 2] > 0
        np.testing.assert_allclose(back[in_front], points[in_front], atol=1e-5)
        # pixel intrinsics + world→camera give the same pixels (OpenCV convention)
        k = geo.pixel_intrinsics(cam)
        w2c = geo.CAMERA_TO_OPENCV @ geo.world_to_camera(cam, frame)[:3]
        cv = (points @ w2c[:, :3].T + w2c[:, 3]) @ k.T
        np.testing.assert_allclose(cv[in_front, :2] / cv[in_front, 2:],
                                   xy[in_front], rtol=1e-6, atol=1e-4)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), scale=st.floats(0.5, 20))
def test_orthographic_round_trip(seed, scale):
    rng = np.random.RandomState(seed)
    cam = kb.OrthographicCamera(orthographic_scale=scale, position=rng.uniform(-5, 5, 3),
                                quaternion=kb.randomness.random_rotation(rng=rng))
    _scene_with(cam, (30, 20))
    points = rng.uniform(-10, 10, (20, 3))
    xy, depth = geo.project_to_pixels(cam, points)
    np.testing.assert_allclose(geo.unproject_pixels(cam, xy, depth), points, atol=1e-5)


def test_camera_without_scene_needs_resolution():
    cam = kb.PerspectiveCamera()
    with pytest.raises(ValueError, match="is in no scene: pass resolution"):
        cam.intrinsics  # noqa: B018
    assert geo.normalised_intrinsics(cam, (10, 10)).shape == (3, 3)
