"""Ground truth inside one exposure (kubric.annotations.exposure), checked against independent
derivations: the defocus layer against the thin-lens formula written out here from the raycast
depth; the exposure coverage against raycast renders of a time-scaled copy of the scene."""

import numpy as np
import pytest

import kubric as kb
from kubric.annotations.exposure import (
    COVERAGE_FIELDS,
    coverage_archive,
    coverage_fractions,
    defocus,
    shutter_offsets,
)

pytest.importorskip("embreex")

W, H = 64, 48


def _lens_scene():
    scene = kb.Scene(resolution=(W, H), frame_start=0, frame_end=0)
    scene += kb.Cube(name="floor", scale=(8, 8, 0.1), position=(0, 0, -0.1), static=True)
    scene += kb.Sphere(name="ball", scale=0.6, position=(0.5, 1.0, 0.6))
    scene += kb.Cube(name="box", scale=0.4, position=(-1.2, -1.5, 0.4))
    scene.camera = kb.PerspectiveCamera(position=(2.0, -6.0, 3.0), look_at=(0, 0, 0.5),
                                        focal_length=28.0, sensor_width=32.0, shift_x=0.05,
                                        use_dof=False, aperture_fstop=2.0, focus_distance=6.5)
    return scene


def test_defocus_is_the_thin_lens_formula_from_depth():
    scene = _lens_scene()
    depth = kb.renderer.create("raycast", scene).render(return_layers=("depth", "z"))
    cam = scene.camera
    # z from the depth layer by hand: the pixel-centre ray in camera axes is
    # ((x - cx) / fx, -(y - cy) / fy, -1) with fx = f / sw · W px and cx = (0.5 - shift_x) · W
    fx = 28.0 / 32.0 * W
    cx, cy = (0.5 - 0.05) * W, 0.5 * H
    cols, rows = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    ray_length = np.sqrt(((cols - cx) / fx) ** 2 + ((rows - cy) / fx) ** 2 + 1.0)
    background = depth["depth"][0, ..., 0] == 10000.0  # z = depth = 10000 m there
    z = np.where(background, 10000.0, depth["depth"][0, ..., 0].astype(np.float64) / ray_length)
    # Cycles' thin lens: aperture diameter f / N (m), circle of confusion (tangent units)
    # A · |1/z − 1/s|, times the focal length in pixels
    expected = (0.028 / 2.0) * np.abs(1.0 / z - 1.0 / 6.5) * fx
    got = defocus(cam, depth["z"])[0, ..., 0]
    assert got.shape == (H, W) and got.dtype == np.float32
    assert expected.max() > 0.1 and expected.min() < 0.005  # in and out of focus both
    sharp = expected < 0.01
    np.testing.assert_array_less(np.abs(got - expected)[~sharp], 1e-4 * expected[~sharp])
    np.testing.assert_array_less(np.abs(got - expected)[sharp], 1e-6)
    assert background.any() and (~background).sum() > 1000


def test_defocus_refuses_what_has_no_thin_lens():
    scene = _lens_scene()
    with pytest.raises(ValueError, match="must be finite and > 0"):
        defocus(scene.camera, np.zeros((1, H, W, 1)))
    scene.camera = kb.OrthographicCamera(position=(0, 0, 10))
    with pytest.raises(ValueError, match="not a perspective camera"):
        defocus(scene.camera, np.ones((1, H, W, 1)))


def _moving_scene(scale):
    """A sphere and a cube crossing in front of a fixed camera; keyframes at whole frames 0..4,
    times ``scale`` (the same motion, ``scale`` times slower in frame numbers)."""
    scene = kb.Scene(resolution=(W, H), frame_start=0, frame_end=4 * scale)
    scene += kb.Cube(name="floor", scale=(8, 8, 0.1), position=(0, 0, -0.1), static=True)
    ball, box = kb.Sphere(name="ball", scale=0.5), kb.Cube(name="box", scale=0.35)
    scene += ball
    scene += box
    for f in range(5):
        ball.position = (-2.0 + 1.1 * f, 0.3, 0.5)
        box.position = (1.5 - 0.5 * f, -0.6 + 0.2 * f, 0.35)
        box.quaternion = kb.Quaternion(axis=(0, 0, 1), angle=0.4 * f)
        for obj in (ball, box):
            obj.keyframe_insert("position", f * scale)
        box.keyframe_insert("quaternion", f * scale)
    scene.camera = kb.PerspectiveCamera(position=(0, -7, 4), look_at=(0, 0, 0.3))
    return scene, (ball, box)


def test_coverage_is_the_fraction_of_subframe_renders_showing_each_instance():
    from kubric.renderer.raycast_subframes import shutter_segmentation
    shutter, k, frames = 0.8, 8, [1, 2, 3]
    scene, objs = _moving_scene(1)
    archive = coverage_archive(shutter_segmentation(scene, frames, shutter, k), shutter)
    assert sorted(key for key, *_ in COVERAGE_FIELDS) == sorted(
        set(archive) - {"format_version", "num_samples", "shutter", "offsets"})
    # reference: the same motion keyed M times slower, rendered by the raycast backend's own
    # render() at whole frames: M + 1 evenly spaced instants over each open shutter
    m = 40
    slow, slow_objs = _moving_scene(m)
    assert (shutter * m).is_integer()  # the ticks are whole frames of the slow copy
    renderer = kb.renderer.create("raycast", slow)
    for i, f in enumerate(frames):
        ticks = [int(f * m - shutter * m / 2 + j) for j in range(int(shutter * m) + 1)]
        ref = renderer.render(frames=ticks, return_layers=("segmentation",))["segmentation"]
        for obj, slow_obj in zip(objs, slow_objs, strict=True):
            label = scene.assets.index(obj) + 1
            assert slow.assets.index(slow_obj) + 1 == label
            want = (ref[..., 0] == label).mean(axis=0)
            got = coverage_fractions(archive, label, (len(frames), H, W))[i]
            # K midpoints and M + 1 ticks each estimate the covered time of a pixel within
            # 1/K and 1/(M + 1) per entry or exit of the instance (one of each here)
            assert np.abs(got - want).max() <= 1.0 / k + 2.0 / (m + 1) + 1e-6
            blurred = (want > 0) & (want < 1)
            assert blurred.sum() > 20  # the motion really spreads it over the exposure
    # every pixel's fractions sum to 1 over its labels (background included)
    total = np.zeros((len(frames), H, W))
    np.add.at(total, (archive["frame"], archive["y"], archive["x"]), archive["count"] / k)
    np.testing.assert_allclose(total, 1.0)


def test_shutter_offsets_are_the_midpoints_of_a_centred_shutter():
    np.testing.assert_allclose(shutter_offsets(1.0, 4), [-0.375, -0.125, 0.125, 0.375])
    np.testing.assert_allclose(shutter_offsets(0.0, 3), 0.0)
    with pytest.raises(ValueError, match="integer ≥ 1"):
        shutter_offsets(1.0, 0)
    with pytest.raises(ValueError, match="≥ 0 frames"):
        shutter_offsets(-1.0, 2)


def test_exposure_flow_is_the_motion_of_the_seen_point_from_shutter_open_to_close():
    from kubric.renderer.raycast_subframes import exposure_flow
    shutter, velocity = 0.6, np.array([0.5, 0.2, 0.1])  # m per frame
    scene = kb.Scene(resolution=(W, H), frame_start=0, frame_end=3)
    box = kb.Cube(name="box", scale=0.7, position=(0, 0, 0.7))
    scene += box
    for f in range(4):
        box.position = np.array([-0.8, 0.0, 0.7]) + velocity * f
        box.keyframe_insert("position", f)
    scene.camera = kb.PerspectiveCamera(position=(1.0, -6.0, 3.0), look_at=(0, 0, 0.5))
    flow = exposure_flow(scene, [1, 2], shutter)
    depth = kb.renderer.create("raycast", scene).render(frames=[1, 2],
                                                        return_layers=("depth",))["depth"]
    # by hand: the point seen at a pixel centre at frame f moves by ± velocity · s / 2 (a pure
    # translation); project both ends with the pinhole K and the (fixed) camera pose
    k = scene.camera.intrinsics_pixels
    cam_to_world = scene.camera.matrix_world
    rot, centre = cam_to_world[:3, :3], cam_to_world[:3, 3]
    cols, rows = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    local = np.stack([(cols - k[0, 2]) / k[0, 0], -(rows - k[1, 2]) / k[1, 1], -np.ones_like(cols)],
                     -1)
    dirs = local / np.linalg.norm(local, axis=-1, keepdims=True) @ rot.T

    def pixel(points):
        cam = (points - centre) @ rot  # camera axes: x right, y up, −z forward
        return np.stack([k[1, 1] * -cam[..., 1] / -cam[..., 2] + k[1, 2],
                         k[0, 0] * cam[..., 0] / -cam[..., 2] + k[0, 2]], -1)  # (row, col)

    for i in range(2):
        on_box = depth[i, ..., 0] < 100
        seen = centre + dirs * depth[i, ..., :1].astype(np.float64)
        want = pixel(seen + velocity * shutter / 2) - pixel(seen - velocity * shutter / 2)
        assert on_box.sum() > 200 and np.abs(want[on_box]).max() > 1.0
        np.testing.assert_allclose(flow[i][on_box], want[on_box], atol=1e-4)
        assert (flow[i][~on_box] == 0).all()


def test_exposure_options_refuse_what_they_cannot_do():
    from kubric.pipeline import OptionError
    from kubric.pipeline.recipe import get_recipe
    with pytest.raises(OptionError, match="coverage_samples=4 needs a shutter"):
        get_recipe("movi_e")(coverage_samples=4)
    with pytest.raises(OptionError, match="renderer=raycast cannot render depth of field"):
        get_recipe("movi_f")(renderer="raycast", dof=True, max_motion_blur=0.0)
    with pytest.raises(OptionError, match="min_fstop=8.0 must be ≤ max_fstop=2.0"):
        get_recipe("movi_e")(dof=True, min_fstop=8.0, max_fstop=2.0)
