"""Keyframes at non-integer frames, as upstream's ``examples/animation.py`` inserts them
(``camera.keyframe_insert("position", 1.0)``; issue #33).

A key may sit at any finite frame; an integral float is that integer frame. Rendered frames are
whole, so a fractional key shows only through interpolation: each scene below is rendered twice,
once keyed at fractional / float frames, once keyed at the rendered integer frames with the
values interpolated by hand (linear: v0 + (f − f0) / (f1 − f0) · (v1 − v0)). Both renderings
must agree (raycast: exactly; Blender: same labels, depth to float noise).
"""

import numpy as np
import pytest

import kubric as kb

#: the cube's keys (fractional) and the camera's (floats, as animation.py: frames 1.0 and 60.0)
CUBE_KEYS = {0.5: (-1.0, 0.0, 0.0), 2.5: (1.0, 0.0, 0.0)}
CAMERA_KEYS = {1.0: (-1.0, 0.0, 6.0), 60.0: (1.0, 0.0, 6.0)}
FRAMES = (0, 1, 2, 3, 4)  # animation.py renders frame_start − 1 .. frame_end + 1


def by_hand(keys: dict, frame: float) -> np.ndarray:
    """Linear interpolation between the two keys around ``frame``; held outside them."""
    (f0, v0), (f1, v1) = sorted(keys.items())
    t = min(max((frame - f0) / (f1 - f0), 0.0), 1.0)
    return (1 - t) * np.asarray(v0) + t * np.asarray(v1)


def test_float_frames_are_keys_integral_floats_are_the_integer_frame():
    cube = kb.Cube(name="c")
    cube.position = (1, 2, 3)
    cube.keyframe_insert("position", 1.0)
    cube.position = (3, 2, 1)
    cube.keyframe_insert("position", 1)  # the same key as 1.0
    cube.position = (5, 5, 5)
    cube.keyframe_insert("position", np.float32(2.5))
    assert sorted(cube.keyframes["position"]) == [1, 2.5]
    assert all(type(f) in (int, float) for f in cube.keyframes["position"])
    np.testing.assert_allclose(cube.get_value_at("position", 1), (3, 2, 1))
    np.testing.assert_allclose(cube.get_value_at("position", 2.0),
                               (3 + (5 - 3) / 1.5, 2 + 3 / 1.5, 1 + 4 / 1.5), rtol=1e-6)
    cube.keyframe_delete("position", 2.5)
    cube.keyframe_delete("position", 1.0)
    assert not cube.keyframes["position"]
    for bad, error, match in ((float("nan"), ValueError, "must be finite, got nan"),
                              (float("inf"), ValueError, "must be finite"),
                              (True, TypeError, "must be a number"),
                              ("1", TypeError, "must be a number .* got '1'")):
        with pytest.raises(error, match=match):
            cube.keyframe_insert("position", bad)


def _scene():
    """The scene: camera above, a cube on a floor, a light (keys added by :func:`_key`)."""
    scene = kb.Scene(resolution=(48, 32), frame_start=1, frame_end=3)
    camera = kb.PerspectiveCamera(name="camera", focal_length=35)
    scene += camera
    scene += kb.DirectionalLight(position=(0, 0, 5), look_at=(0, 0, 0), intensity=3)
    cube = kb.Cube(name="cube", scale=0.4)
    scene += cube
    scene += kb.Cube(name="floor", scale=(4, 4, 0.1), position=(0, 0, -0.6))
    return scene, camera, cube


def _key(camera, cube, fractional: bool) -> None:
    """Keyed as animation.py does (fractional / float frames) or at the rendered integer frames
    with the values interpolated by hand."""
    frames = CAMERA_KEYS if fractional else {f: by_hand(CAMERA_KEYS, f) for f in FRAMES}
    for frame, position in frames.items():
        camera.position = position
        camera.look_at(np.asarray(camera.position) * (1, 1, 0))  # straight down
        camera.keyframe_insert("position", frame)
        camera.keyframe_insert("quaternion", frame)
    cube_keys = CUBE_KEYS if fractional else {f: by_hand(CUBE_KEYS, f) for f in FRAMES}
    for frame, position in cube_keys.items():
        cube.position = position
        cube.keyframe_insert("position", frame)


def _check(scene, cube, keyed, by_hand_keyed, depth_tolerance):
    np.testing.assert_array_equal(keyed["segmentation"], by_hand_keyed["segmentation"])
    np.testing.assert_allclose(keyed["depth"], by_hand_keyed["depth"], atol=depth_tolerance)
    # the cube moves across the image relative to the camera (frames 0 and 1: cube −1 → −0.5,
    # camera −1 → −1): its label's mean column changes from frame to frame
    label = keyed["segmentation"][..., 0] == scene.assets.index(cube) + 1
    cols = [np.nonzero(label[i])[1].mean() for i in range(len(FRAMES))]
    assert all(label[i].any() for i in range(len(FRAMES)))
    assert len({round(c, 3) for c in cols}) >= 3, cols


def test_fractional_keys_render_as_their_interpolation_raycast():
    out = []
    for fractional in (True, False):
        scene, camera, cube = _scene()
        _key(camera, cube, fractional)
        renderer = kb.renderer.create("raycast", scene)
        out.append(renderer.render(frames=list(FRAMES), return_layers=("segmentation", "depth")))
    _check(scene, cube, *out, depth_tolerance=1e-5)


@pytest.mark.blender
def test_animation_py_flow_renders_fractional_keys_in_blender(tmp_path):
    """animation.py's order: the renderer exists before the keys are inserted (each key reaches
    Blender as it is made), float frames, frames frame_start − 1 .. frame_end + 1 rendered."""
    from kubric.renderer.blender import Blender
    out = []
    for fractional in (True, False):
        scene, camera, cube = _scene()
        renderer = Blender(scene, tmp_path / str(fractional), samples_per_pixel=1,
                           use_denoising=False)
        _key(camera, cube, fractional)
        out.append(renderer.render(frames=list(FRAMES), return_layers=("segmentation", "depth")))
    _check(scene, cube, *out, depth_tolerance=1e-4)
