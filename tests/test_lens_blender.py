"""The blender backend through a lens (a Cycles custom OSL camera, kubric.renderer.blender_lens)
against the raycast backend as the oracle (whose lens rays are checked against OpenCV in
tests/test_lens_movi.py): the same exact layers on a small scene with a moving object, a shifted
principal point and each lens model; and what it refuses."""

import numpy as np
import pytest
from scipy.ndimage import maximum_filter, minimum_filter

import kubric as kb
from kubric.core import camera_geometry as geo
from kubric.core import lenses
from kubric.renderer import base

pytestmark = pytest.mark.blender

W, H = 64, 48
LENSES = {"fisheye": lenses.Fisheye(0.2, -0.05, 0.01, -0.002),
          "opencv": lenses.BrownConrady(-0.3, 0.09, 0.002, -0.001, -0.01),
          # the radial map turns at r = 0.65 (ρ = 0.43): the image corners have no ray
          "barrel": lenses.BrownConrady(k1=-0.8)}
LAYERS = ("depth", "z", "segmentation", "forward_flow", "backward_flow", "normal",
          "object_coordinates", "uv")


def _scene(lens):
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=2)
    scene += kb.PerspectiveCamera(name="camera", position=(1, -8, 3), look_at=(0, 0, 0.5),
                                  lens=lens, shift_x=0.03, shift_y=-0.02)
    scene += kb.Cube(scale=(40, 40, 0.1), position=(0, 0, -0.1), background=True)
    cube = kb.Cube(scale=0.8, position=(0.5, 0, 0.8))
    scene += cube
    scene += kb.Sphere(scale=0.6, position=(-1.5, 1, 0.6))
    for f in range(4):
        cube.position = (0.5 + 0.2 * f, 0.1 * f, 0.8)
        cube.quaternion = kb.Quaternion(axis=(0, 0, 1), angle=0.1 * f)
        cube.keyframe_insert("position", f)
        cube.keyframe_insert("quaternion", f)
    return scene


@pytest.mark.parametrize("model", sorted(LENSES))
def test_blender_lens_layers_agree_with_raycast(model, tmp_path):
    scene = _scene(LENSES[model])
    ray = base.create("raycast", scene).render(return_layers=LAYERS)
    cycles = base.create("blender", scene, tmp_path, samples_per_pixel=4,
                         background_transparency=True).render(return_layers=LAYERS + ("rgba",))
    seg_r, seg_c = ray["segmentation"][..., 0], cycles["segmentation"][..., 0]
    assert (seg_r != seg_c).mean() < 0.002  # at most a few silhouette pixels
    single = maximum_filter(seg_r, size=(1, 3, 3)) == minimum_filter(seg_r, size=(1, 3, 3))
    interior = single & (seg_r == seg_c) & (seg_r > 0)
    assert interior.sum() > 3000
    for name in ("depth", "z"):
        rel = np.abs(ray[name] - cycles[name])[..., 0][interior] / ray[name][..., 0][interior]
        assert rel.max() < 5e-5, (name, rel.max())
    for name, tol in (("forward_flow", 5e-4), ("backward_flow", 5e-4), ("normal", 1e-4),
                      ("object_coordinates", 1e-4), ("uv", 1e-4)):
        err = np.abs(ray[name] - cycles[name])[interior].max()
        assert err < tol, (name, err)
    no_ray = ~np.isfinite(geo.pixel_rays(scene.camera, geo.pixel_centres(H, W))[1]).all(-1)
    assert (model == "barrel") == bool(no_ray.any())
    assert not cycles["segmentation"][:, no_ray].any()  # Cycles casts nothing there either
    moving = np.abs(ray["forward_flow"][interior]).max()
    assert moving > 1.0  # the flow is not trivially zero
    # RGB through the same lens: its coverage (alpha) is where the exact layers see a surface
    covered = cycles["rgba"][..., 3] > 127
    assert (covered == (seg_c > 0)).mean() > 0.98  # edges (and the image circle) blend


def test_blender_refuses_what_its_lens_camera_cannot_render(tmp_path):
    scene = _scene(LENSES["fisheye"])
    scene.camera.keyframe_insert("focal_length", 1)
    renderer = base.create("blender", scene, tmp_path)
    with pytest.raises(base.CapabilityError, match=r"camera 'camera' has a lens and keyframed "
                                                   r"\['focal_length'\]"):
        renderer.render(frames=[1], return_layers=("depth",))
