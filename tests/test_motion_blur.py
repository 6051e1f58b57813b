"""MOVi-F's motion blur really blurs the RGB render, centred on the frame time (so the exact
layers and point tracks, taken at the frame time, sit at the centre of the blur)."""

import numpy as np
import pytest

import kubric as kb

pytestmark = pytest.mark.blender

W, H = 96, 24


def _render(blur):
    from kubric.renderer.blender import Blender
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3)
    scene.camera = kb.OrthographicCamera(position=(0, 0, 10), orthographic_scale=W / 10)
    cube = kb.Cube(scale=0.5, material=kb.FlatMaterial(color=kb.Color(1, 1, 1)))
    scene += cube
    for f in (1, 2, 3):  # 2 m = 20 px per frame to the right
        cube.position = (-2.0 + 2.0 * (f - 1), 0.0, 0.0)
        cube.keyframe_insert("position", f)
    r = Blender(scene, samples_per_pixel=64, use_denoising=False, motion_blur=blur)
    return r.render(frames=[2], return_layers=("rgba", "segmentation"))


def _linear(srgb):
    v = srgb.astype(float) / 255
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_motion_blur_smears_rgb_centred_on_the_frame():
    sharp, blurred = _render(0.0), _render(1.0)
    a, b = (_linear(x["rgba"][0, H // 2, :, 0]) for x in (sharp, blurred))
    # the sharp cube is 10 px wide; with a 1-frame shutter it smears over 10 + 20 px
    assert ((a > 0.05) & (a < 0.95)).sum() <= 4  # the 1.5 px pixel filter at both edges
    assert ((b > 0.05) & (b < 0.95)).sum() >= 15
    assert (b > 0.05).sum() >= 26
    # same energy, same centroid: the shutter is centred on the frame time
    x = np.arange(W) + 0.5
    assert abs(a.sum() - b.sum()) < 0.1 * a.sum()
    assert abs((a * x).sum() / a.sum() - (b * x).sum() / b.sum()) < 0.5
    # the exact layers are not blurred
    np.testing.assert_array_equal(sharp["segmentation"], blurred["segmentation"])
