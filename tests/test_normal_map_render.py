"""A normal map shows in a Cycles render (32 px, 4 samples): a flat white face under one
directional light is evenly lit with a flat normal map, and split into bright and dark stripes
with a map whose stripes tilt the normal 35° one way and the other — as Lambert's law says."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import kubric as kb
from kubric.core.pbr_materials import ImageMaterial

pytestmark = pytest.mark.blender
SIZE = 32
TILT = np.radians(35.0)
INTENSITY = 3.0  # the sun's irradiance (W/m²)
#: the light's direction (towards the light): azimuth 45°, elevation 30°, so that a normal tilted
#: along either face axis (whichever the UVs' tangent is) turns towards it or away from it
LIGHT = np.array([np.cos(np.radians(30)) * np.cos(np.radians(45)),
                  np.cos(np.radians(30)) * np.sin(np.radians(45)), np.sin(np.radians(30))])


def _normal_png(path, tilts):
    """A 16×16 tangent-space normal map (OpenGL, +y up): columns in stripes of the given tilts
    (radians) towards +u."""
    cols = np.repeat(np.asarray(tilts, np.float64), 16 // len(tilts))
    n = np.stack([np.sin(cols), np.zeros_like(cols), np.cos(cols)], -1)  # (16, 3)
    rgb = np.round((n * 0.5 + 0.5) * 255).astype(np.uint8)
    Image.fromarray(np.broadcast_to(rgb, (16, 16, 3)).copy()).save(path)
    return str(path)


@pytest.fixture(scope="module")
def renders(tmp_path_factory):
    folder = tmp_path_factory.mktemp("normal_map")
    Image.fromarray(np.full((4, 4, 3), 255, np.uint8)).save(folder / "white.png")
    maps = {"flat": _normal_png(folder / "flat.png", [0.0]),
            "stripes": _normal_png(folder / "stripes.png", [TILT, -TILT, TILT, -TILT])}
    out = {}
    for name, normal in maps.items():
        scene = kb.Scene(resolution=(SIZE, SIZE))
        scene.background = kb.get_color((0.0, 0.0, 0.0))
        scene.ambient_illumination = kb.get_color((0.0, 0.0, 0.0))
        scene.camera = kb.PerspectiveCamera(position=(0, 0, 6), look_at=(0, 0, 0))
        scene += kb.DirectionalLight(position=tuple(LIGHT * 5), look_at=(0, 0, 0),
                                     intensity=INTENSITY)
        # a cube scaled uniformly, its top face at z = 0: a tangent-space normal map turns with
        # the object's normal matrix, so a thin (non-uniformly scaled) slab would flatten it
        scene += kb.Cube(name="slab", scale=(1.5, 1.5, 1.5), position=(0, 0, -1.5),
                         material=ImageMaterial(
            base_color=str(folder / "white.png"), normal_map=normal, roughness=1.0,
            uv_scale=1.0, material_id=name))
        layers = kb.renderer.create("blender", scene, samples_per_pixel=4,
                                    use_denoising=False).render(return_layers=("rgba",
                                                                               "segmentation"))
        seg = layers["segmentation"][0, ..., 0] > 0
        inner = seg.copy()  # the slab without its anti-aliased rim
        inner[1:-1, 1:-1] &= seg[:-2, 1:-1] & seg[2:, 1:-1] & seg[1:-1, :-2] & seg[1:-1, 2:]
        out[name] = layers["rgba"][0, ..., :3].astype(np.float64).mean(-1)[inner]
    return out


def srgb(radiance):
    """8-bit sRGB of a linear value (the rgba layer's encoding)."""
    v = np.clip(radiance, 0, 1)
    return 255 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def test_a_striped_normal_map_shades_a_flat_face_as_lamberts_law_says(renders):
    flat, stripes = renders["flat"], renders["stripes"]
    assert flat.size > 300 and stripes.size == flat.size
    # Lambert: a white face under a sun of irradiance E reflects radiance E·(n·l)/π
    flat_want = srgb(INTENSITY * LIGHT[2] / np.pi)
    assert abs(np.median(flat) - flat_want) < 5 and np.ptp(np.percentile(flat, [5, 95])) < 8
    # the stripes tilt n by ±35° along an axis of the face (u or v; the light is at 45° to both)
    lit = [LIGHT[2] * np.cos(TILT) + s * LIGHT[0] * np.sin(TILT) for s in (1, -1)]
    bright_want, dark_want = (srgb(INTENSITY * n_l / np.pi) for n_l in lit)
    split = (bright_want + dark_want) / 2
    bright, dark = stripes[stripes > split], stripes[stripes <= split]
    assert 0.3 < bright.size / stripes.size < 0.7  # both stripes cover the face
    assert abs(np.median(bright) - bright_want) < 8, (np.median(bright), bright_want)
    assert abs(np.median(dark) - dark_want) < 8, (np.median(dark), dark_want)
