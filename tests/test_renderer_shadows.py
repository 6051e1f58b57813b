"""Shadow-catching FlatMaterials: unoccluded floor shows its colour; objects shadow it."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

import kubric as kb
from kubric.renderer.blender_shadows import upward_irradiance

HDRI = (Path(sys.prefix) / "lib/python3.11/site-packages/bpy/5.0/datafiles/studiolights/world"
        / "city.exr")


@pytest.mark.parametrize("height", [64, 63])
def test_upward_irradiance_integrates_the_upper_hemisphere(height):
    uniform = np.ones((height, 2 * height, 3))
    np.testing.assert_allclose(upward_irradiance(uniform), math.pi, rtol=1e-12)
    lower = uniform.copy()
    lower[height // 2 + 1:] = 0.0  # only the lower hemisphere (row 0 = bottom) is lit
    assert upward_irradiance(lower).max() < 0.1
    # a thin bright band at elevation e contributes L · sin(e) · (solid angle of the band)
    band = np.zeros((height, 2 * height, 3))
    row = int(0.8 * height)
    band[row] = 5.0
    lo, hi = ((row / height) - 0.5) * math.pi, (((row + 1) / height) - 0.5) * math.pi
    expected = 5.0 * 2 * math.pi * 0.5 * (math.sin(hi) ** 2 - math.sin(lo) ** 2)
    np.testing.assert_allclose(upward_irradiance(band), expected, rtol=1e-12)
    with pytest.raises(ValueError, match="must be"):
        upward_irradiance(np.ones((4, 8)))


def _to_linear(rgba):
    x = rgba[..., :3].astype(np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _floor_scene(ambient, floor_color, catch):
    scene = kb.Scene(resolution=(64, 64), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0, 0, 10), look_at=(0, 0, 0))
    scene.ambient_illumination = ambient
    scene.background = kb.Color(0, 0, 0)
    floor = kb.FlatMaterial(color=floor_color, catch_shadows=catch, indirect_visibility=False)
    scene += kb.Cube(name="floor", scale=(6, 6, 0.1), position=(0, 0, -0.1), material=floor)
    scene += kb.Cube(name="block", scale=0.5, position=(0, 0, 0.5),
                     material=kb.PrincipledBSDFMaterial(color="gray", roughness=1.0))
    return scene


def _render(scene, spp):
    from kubric.renderer.blender import Blender
    renderer = Blender(scene, samples_per_pixel=spp, use_denoising=False)
    layers = renderer.render(return_layers=("rgba", "segmentation"))
    seg = layers["segmentation"][0, ..., 0]
    labels = {a.name: i for i, a in enumerate(scene.assets, start=1)}
    return _to_linear(layers["rgba"][0]), np.select(
        [seg == labels["floor"], seg == labels["block"]], [1, 2], 0)


def _rings(seg):
    """(floor pixels far from the block, floor pixels within 1 px of it)."""
    from scipy import ndimage
    block = seg == 2
    near = ndimage.binary_dilation(block, iterations=1) & ~block
    far = ~ndimage.binary_dilation(block, iterations=12) & (seg == 1)
    return far, near


@pytest.mark.blender
def test_shadow_catcher_shows_its_colour_unoccluded_and_a_contact_shadow():
    scene = _floor_scene(kb.Color(0.5, 0.5, 0.5), kb.Color(0.6, 0.3, 0.15), catch=True)
    rgb, seg = _render(scene, spp=16)
    far, near = _rings(seg)
    assert far.sum() > 500 and near.sum() > 20
    # unoccluded: the floor's own colour (albedo colour·π/E under E = π·0.5) within noise
    np.testing.assert_allclose(rgb[far].mean(axis=0), (0.6, 0.3, 0.15), rtol=0.03)
    # next to the 1 m block up to half the sky is hidden: a contact shadow (the grey block
    # also bounces some light back)
    assert rgb[near].mean() < 0.9 * rgb[far].mean()
    # without catch_shadows the floor is its flat colour everywhere, shadow-free
    flat, seg = _render(_floor_scene(kb.Color(0.5, 0.5, 0.5), kb.Color(0.6, 0.3, 0.15),
                                     catch=False), spp=1)
    far, near = _rings(seg)
    np.testing.assert_allclose(flat[near].mean(axis=0), (0.6, 0.3, 0.15), atol=0.01)


@pytest.mark.blender
def test_shadow_catcher_under_an_hdri_matches_the_unlit_floor():
    hdri = kb.Texture(filename=str(HDRI), mapping="environment", rotation=(0, 0, 1.0))
    rgb, seg = _render(_floor_scene(hdri, kb.Color(0.5, 0.5, 0.5), catch=True), spp=32)
    far, near = _rings(seg)
    # the irradiance integral of the HDRI's upper hemisphere normalises the albedo: far from the
    # block the floor shows 0.5 (sampling noise of the HDRI light averages out over the pixels)
    np.testing.assert_allclose(rgb[far].mean(), 0.5, rtol=0.06)
    # the HDRI's light is directional: one side of the block is in clear shadow
    assert np.percentile(rgb[near].mean(axis=1), 25) < 0.8 * rgb[far].mean()


@pytest.mark.blender
def test_shadow_catcher_needs_usable_ambient_light():
    from kubric.renderer.blender import Blender
    scene = _floor_scene(kb.Color(0.5, 0.0, 0.5), kb.Color(0.6, 0.6, 0.6), catch=True)
    with pytest.raises(ValueError, match="lights every colour channel"):
        Blender(scene, samples_per_pixel=1).render(return_layers=("rgba",))
    tilted = kb.Texture(filename=str(HDRI), mapping="environment", rotation=(0.3, 0, 0))
    scene = _floor_scene(tilted, kb.Color(0.6, 0.6, 0.6), catch=True)
    with pytest.raises(ValueError, match="rotated about z only"):
        Blender(scene, samples_per_pixel=1).render(return_layers=("rgba",))


@pytest.mark.blender
def test_flat_colour_keys_drive_the_shadow_catcher_too():
    from kubric.renderer.blender import Blender, _action_fcurves
    scene = _floor_scene(kb.Color(0.5, 0.5, 0.5), kb.Color(0.6, 0.6, 0.6), catch=True)
    renderer = Blender(scene, samples_per_pixel=1)
    floor = next(a for a in scene.assets if a.name == "floor").material
    floor.color = kb.Color(1, 0, 0)
    floor.keyframe_insert("color", 1)
    floor.color = kb.Color(0, 0, 1)
    floor.keyframe_insert("color", 3)
    tree = floor.linked_objects[renderer].node_tree
    paths = {fc.data_path for fc in _action_fcurves(tree.animation_data.action)}
    assert any('"Emission"' in p for p in paths) and any('"catch_scale"' in p for p in paths)

    def keyed_frames():
        return sorted({int(k.co[0]) for fc in _action_fcurves(tree.animation_data.action)
                       for k in fc.keyframe_points})
    assert keyed_frames() == [1, 3]
    floor.keyframe_delete("color", 3)
    assert keyed_frames() == [1]
