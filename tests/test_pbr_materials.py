"""Procedural PBR materials: sampling, plain-data description, the raycast base colour and the
Blender node trees on real renders (32 px, 4 samples)."""

from __future__ import annotations

import numpy as np
import pytest

import kubric as kb
from kubric.annotations.materials_parts import material_table
from kubric.core.pbr_materials import PATTERNS, ProceduralMaterial, sample_procedural_material
from kubric.renderer.base import CapabilityError, capabilities

SIZE = 32


def _slab_scene(material):
    """A flat box seen from straight above, filling most of the image; uniform white light."""
    scene = kb.Scene(resolution=(SIZE, SIZE))
    scene.ambient_illumination = kb.get_color((1.0, 1.0, 1.0))
    scene.background = kb.get_color((0.0, 0.0, 0.0))
    scene.camera = kb.PerspectiveCamera(position=(0.3, 0.2, 6), look_at=(0.3, 0.2, 0))
    scene += kb.Cube(name="slab", scale=(1.5, 1.5, 0.1), material=material)
    return scene


def _slab(scene):
    return next(a for a in scene.assets if a.name == "slab")


def _black_white(pattern, scale):
    return ProceduralMaterial(pattern=pattern, color_a="white", color_b="black", scale=scale,
                              roughness_a=1.0, roughness_b=1.0, offset=(0.1, 0.2, 0.3))


def _top_face(scene):
    """(pixels seeing the slab's top face (H, W), their generated x, y (H·W, 2)), derived here
    from the geometry alone: each pixel-centre ray meets the plane z = 0.1."""
    from kubric.core import camera_geometry as geo
    origins, dirs = geo.pixel_centre_rays(scene.camera, frame=0, resolution=scene.resolution)
    t = (0.1 - origins[:, 2]) / dirs[:, 2]
    hit = origins + dirs * t[:, None]
    inside = (np.abs(hit[:, 0]) <= 1.5) & (np.abs(hit[:, 1]) <= 1.5)
    return inside.reshape(SIZE, SIZE), (hit[:, :2] / 1.5 + 1) / 2  # [0, 1] over the box


def _checker_truth(scene):
    """(top-face pixels, which of them lie on black checker cells)."""
    inside, gen = _top_face(scene)
    mat = _slab(scene).material
    cells = np.floor((gen + np.asarray(mat.offset)[:2]) * mat.scale).astype(int)
    z_odd = int(np.floor((1.0 + mat.offset[2]) * mat.scale)) % 2 == 1
    black = ((cells[:, 0] % 2 == cells[:, 1] % 2) == z_odd)
    return inside, black.reshape(SIZE, SIZE)


def _interior(mask, labels):
    """Pixels of ``mask`` whose 4 neighbours have the same label (no anti-aliased edge)."""
    out = mask.copy()
    out[[0, -1], :] = out[:, [0, -1]] = False
    c = labels[1:-1, 1:-1]
    same = ((c == labels[:-2, 1:-1]) & (c == labels[2:, 1:-1]) & (c == labels[1:-1, :-2])
            & (c == labels[1:-1, 2:]))
    out[1:-1, 1:-1] &= same
    return out


def test_sampling_is_deterministic_and_described_as_plain_data():
    a = sample_procedural_material(np.random.RandomState(7)).describe()
    b = sample_procedural_material(np.random.RandomState(7)).describe()
    assert a == b and a["type"] == "ProceduralMaterial" and a["pattern"] in PATTERNS
    others = [sample_procedural_material(np.random.RandomState(s)).describe() for s in range(12)]
    assert len({o["pattern"] for o in others}) >= 3 and len({str(o) for o in others}) == 12
    only = {sample_procedural_material(np.random.RandomState(s), patterns=("brick",)).pattern
            for s in range(5)}
    assert only == {"brick"}
    with pytest.raises(ValueError, match=r"patterns \['marble'\]: give one or more of"):
        sample_procedural_material(np.random.RandomState(0), patterns=("marble",))
    with pytest.raises(ValueError, match="must be one of"):
        ProceduralMaterial(pattern="marble")


def test_material_table_records_each_procedural_material():
    scene = _slab_scene(_black_white("checker", 4))
    other = kb.Sphere(material=_black_white("brick", 2))
    scene += other
    table, ids = material_table(scene.assets)
    assert [t["pattern"] for t in table] == ["checker", "brick"]
    assert table[0]["color_a"] == [1.0, 1.0, 1.0] and table[0]["scale"] == 4.0


def test_raycast_checker_matches_the_geometry_and_refuses_noise():
    scene = _slab_scene(_black_white("checker", 4))
    rgba = kb.renderer.create("raycast", scene).render(return_layers=("rgba",))["rgba"][0]
    inside, black = _checker_truth(scene)
    lum = rgba[..., :3].mean(-1)
    assert inside.sum() > 500
    np.testing.assert_array_equal(lum[inside] < 128, black[inside])
    _slab(scene).material = _black_white("noise", 3)
    with pytest.raises(CapabilityError, match="renderer=raycast cannot render noise procedural "
                       "materials .*slab's material pattern=noise.*backends that can: blender"):
        kb.renderer.create("raycast", scene).render(return_layers=("rgba",))
    assert set(capabilities("blender").procedural_patterns) == set(PATTERNS)


@pytest.fixture(scope="module")
def blender_renders(tmp_path_factory):
    """Blender renders (32 px, 4 samples) of the slab: plain, checker, brick, noise, voronoi and
    an image set (a 2×2 black / white base colour, a flat normal map, a displacement map)."""
    from PIL import Image

    from kubric.core.pbr_materials import ImageMaterial
    folder = tmp_path_factory.mktemp("image_set")
    cells = np.kron(np.array([[255, 0], [0, 255]], np.uint8), np.ones((8, 8), np.uint8))
    Image.fromarray(np.stack([cells] * 3, -1)).save(folder / "base.png")
    Image.fromarray(np.full((16, 16, 3), (128, 128, 255), np.uint8)).save(folder / "normal.png")
    Image.fromarray(cells).save(folder / "height.png")
    image = ImageMaterial(base_color=str(folder / "base.png"),
                          normal_map=str(folder / "normal.png"),
                          displacement_map=str(folder / "height.png"), roughness=1.0,
                          uv_scale=2.0, material_id="cells", license="CC0-1.0")
    looks = {"image": image, "plain": kb.PrincipledBSDFMaterial(color="white", roughness=1.0),
             "checker": _black_white("checker", 4), "brick": _black_white("brick", 2),
             "noise": _black_white("noise", 3), "voronoi": _black_white("voronoi", 3)}
    out = {}
    for name, material in looks.items():
        scene = _slab_scene(material)
        renderer = kb.renderer.create("blender", scene, samples_per_pixel=4, use_denoising=False)
        out[name] = (scene, renderer.render(return_layers=("rgba", "segmentation")))
    return out


@pytest.mark.blender
def test_blender_procedural_textures_vary_where_the_plain_slab_does_not(blender_renders):
    def spread(name):  # over the top face, its anti-aliased rim left out
        scene, layers = blender_renders[name]
        inside, _ = _top_face(scene)
        return layers["rgba"][0, ..., :3].mean(-1)[_interior(inside, inside.astype(int))].std()

    plain = spread("plain")  # path-tracing noise of 4 samples only
    assert plain < 8.0
    for name in ("checker", "brick", "noise", "voronoi", "image"):
        assert spread(name) > 3 * plain, (name, spread(name), plain)


@pytest.mark.blender
def test_blender_checker_cells_are_where_the_geometry_puts_them(blender_renders):
    scene, layers = blender_renders["checker"]
    inside, black = _checker_truth(scene)
    lum = layers["rgba"][0, ..., :3].mean(-1)
    inner = _interior(inside, black.astype(int) + 2 * inside)
    assert inner.sum() > 150
    np.testing.assert_array_equal(lum[inner] < 128, black[inner])


# ---------------------------------------------------------------------------------- recipes
def _movi_c_scene(out_dir, *extra):
    from collection_fixtures import run_worker
    run_worker("movi_c", 5, out_dir, ("renderer=raycast", "resolution=32", "frame_end=2",
                                      "min_num_objects=3", "max_num_objects=3",
                                      "collection_limit=8", *extra))
    scene = next(out_dir.glob("scene_*"))
    import json
    return scene, json.loads((scene / "metadata.json").read_text())


def test_movi_c_procedural_materials_are_recorded_deterministic_and_opt_in(tmp_path):
    opts = ("material_source=procedural", "material_patterns=checker,brick,wave")
    scene_a, a = _movi_c_scene(tmp_path / "a", *opts)
    _, b = _movi_c_scene(tmp_path / "b", *opts)
    _, plain = _movi_c_scene(tmp_path / "plain")
    materials = [inst["material"] for inst in a["instances"]]
    from kubric.docgen import undocumented_scene_fields
    assert undocumented_scene_fields(scene_a) == []
    assert materials == [inst["material"] for inst in b["instances"]]
    assert all(m["type"] == "ProceduralMaterial" and m["pattern"] in ("checker", "brick", "wave")
               for m in materials)
    assert a["metadata"]["floor_material"]["type"] == "ProceduralMaterial"
    # the HDRI dome stays out of the lighting, as the recipe's own dome is; objects are not
    assert a["metadata"]["floor_material"]["indirect_visibility"] is False
    assert all(m["indirect_visibility"] is True for m in materials)
    assert not any("material" in inst for inst in plain["instances"])
    assert "material_source" not in plain["flags"] and "floor_material" not in plain["metadata"]
    # the materials come from their own rng: every trajectory is the plain scene's
    key = {inst["asset_id"]: inst["positions"] for inst in plain["instances"]}
    assert {inst["asset_id"]: inst["positions"] for inst in a["instances"]} == key


def test_recipes_refuse_patterns_their_renderer_does_not_show():
    from kubric.pipeline import OptionError, get_recipe

    for recipe in ("movi_c", "movi_e"):
        with pytest.raises(OptionError, match=f"{recipe}: renderer=raycast cannot render noise "
                           "procedural materials .material_patterns=noise,checker.; backends "
                           "that can: blender"):
            get_recipe(recipe).from_assignments([
                "renderer=raycast", "material_source=procedural",
                "material_patterns=noise,checker"]).check()
    with pytest.raises(OptionError, match="material_source.*procedural or an existing material "
                       "source folder"):
        get_recipe("movi_c").from_assignments(["material_source=/no/such/folder"])


def test_toybox_gives_objects_and_floor_procedural_materials(tmp_path):
    import json

    from collection_fixtures import run_worker

    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    toys = with_categories(asset_tools.ensure_kubasic(), {"cube": "box", "sphere": "ball"},
                           tmp_path / "toys")
    run_worker("toybox", 2, tmp_path / "out", (
        "renderer=raycast", "resolution=32", "num_views=3", "split_ratio=1,1,1",
        "num_categories=2", f"objects={toys}", "material_source=procedural",
        "material_patterns=checker"))
    meta = json.loads(next((tmp_path / "out").glob("scene_*/metadata.json")).read_text())
    assert meta["instances"]
    assert {inst["material"]["pattern"] for inst in meta["instances"]} == {"checker"}
    assert meta["metadata"]["floor_material"]["pattern"] == "checker"
