"""Cycles' noise levers (kubric.renderer.blender_sampling): validated with one-line errors, recorded
in the renderer's settings and the quality label, applied to the RGB render — and the exact layers
are the same bytes with every lever on as with none (they do not depend on RGB sampling)."""

import numpy as np
import pytest

import kubric as kb
from kubric.recipes.render_quality import _oidn
from kubric.renderer.base import ALL_LAYERS

LEVERS_ON = {"path_guiding": "all", "clamp_direct": 0.05, "clamp_indirect": 0.02,
             "filter_glossy": 3.0, "adaptive_min_samples": 2,
             "denoising_input_passes": "RGB_ALBEDO", "total_bounces": 3, "diffuse_bounces": 1,
             "glossy_bounces": 2, "transmission_bounces": 3, "fast_gi": 1,
             "light_threshold": 0.1, "caustics": False, "min_light_bounces": 2,
             "scrambling_distance": 0.5, "tile_size": 16}


def _scene():
    """32×24 px, 2 frames: a glossy sphere moving over a diffuse floor, sun-lit, grey sky."""
    scene = kb.Scene(resolution=(32, 24), frame_start=1, frame_end=2,
                     ambient_illumination=kb.Color(0.3, 0.3, 0.3))
    scene += kb.Cube(scale=(3, 3, 0.1), position=(0, 0, -0.1),
                     material=kb.PrincipledBSDFMaterial(color=kb.Color(0.8, 0.7, 0.6)))
    ball = kb.Sphere(scale=0.5, position=(-0.3, 0, 0.5),
                     material=kb.PrincipledBSDFMaterial(color=kb.Color(0.9, 0.2, 0.2),
                                                        metallic=1.0, roughness=0.2))
    scene += ball
    ball.keyframe_insert("position", 1)
    ball.position = (0.3, 0.1, 0.5)
    ball.keyframe_insert("position", 2)
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=2)
    scene.camera = kb.PerspectiveCamera(position=(0, -3, 2), look_at=(0, 0, 0.3))
    return scene


@pytest.fixture(scope="module")
def renders():
    """One renderer, 4 samples: everything with the levers off, then again with all of them on
    (set live, as the benchmarks do), and the Cycles settings left after the second render."""
    from kubric.renderer.blender import Blender
    r = Blender(_scene(), samples_per_pixel=4, use_denoising=False, adaptive_sampling=True,
                adaptive_threshold=0.5)
    off = r.render(return_layers=ALL_LAYERS)
    settings_off = r.settings()
    for name, value in LEVERS_ON.items():
        setattr(r, name, value)
    on = r.render(return_layers=ALL_LAYERS)
    c = r.bpy_scene.cycles
    after = {"use_guiding": c.use_guiding, "clamp_indirect": c.sample_clamp_indirect,
             "blur_glossy": c.blur_glossy, "bounces": (c.max_bounces, c.diffuse_bounces,
                                                       c.glossy_bounces, c.transmission_bounces),
             "fast_gi": (c.use_fast_gi, c.fast_gi_method, c.ao_bounces_render),
             "caustics": (c.caustics_reflective, c.caustics_refractive),
             "guides": c.denoising_input_passes, "tile": (c.use_auto_tile, c.tile_size),
             "scrambling": (c.auto_scrambling_distance, c.scrambling_distance),
             "light_threshold": c.light_sampling_threshold,
             "min_light_bounces": c.min_light_bounces}
    return off, on, settings_off, r.settings(), after


@pytest.mark.blender
def test_exact_layers_are_byte_identical_with_every_lever_on(renders):
    off, on, *_ = renders
    exact = [k for k in off if k != "rgba"]
    assert {"segmentation", "depth", "forward_flow", "normal", "object_coordinates"} <= set(exact)
    for k in exact:
        assert off[k].tobytes() == on[k].tobytes(), k
    assert np.unique(off["segmentation"]).size >= 3  # floor, ball and sky are in view


@pytest.mark.blender
def test_the_levers_reach_the_rgb_render_and_the_metadata(renders):
    off, on, settings_off, settings_on, after = renders
    # clamping every light sample to a few hundredths can only take energy away: the lit floor
    # and ball darken (the sky, seen directly, is not a light sample and stays)
    ball_or_floor = off["segmentation"][..., 0] > 0
    lum_off = off["rgba"][..., :3][ball_or_floor].astype(float).mean()
    lum_on = on["rgba"][..., :3][ball_or_floor].astype(float).mean()
    assert lum_on < 0.5 * lum_off, (lum_on, lum_off)
    assert not set(LEVERS_ON) & set(settings_off)  # Blender's defaults are not recorded
    assert {k: settings_on[k] for k in LEVERS_ON} == LEVERS_ON
    # the renderer leaves Blender in its RGB configuration: the levers are Cycles' settings
    assert after == {"use_guiding": True, "clamp_indirect": pytest.approx(0.02),
                     "blur_glossy": 3.0, "bounces": (3, 1, 2, 3),
                     "fast_gi": (True, "REPLACE", 1), "caustics": (False, False),
                     "guides": "RGB_ALBEDO", "tile": (True, 16),
                     "scrambling": (False, 0.5), "light_threshold": pytest.approx(0.1),
                     "min_light_bounces": 2}


@pytest.mark.blender
@pytest.mark.parametrize("name, value, allowed", [
    ("path_guiding", "everywhere", "one of ['off', 'surface', 'volume', 'all']"),
    ("clamp_indirect", -1, "a number in [0, 1e+08]"),
    ("filter_glossy", 11, "a number in [0, 10]"),
    ("adaptive_min_samples", 2.5, "an integer in [0, 4096]"),
    ("denoising_input_passes", "NORMAL", "one of ['RGB', 'RGB_ALBEDO', 'RGB_ALBEDO_NORMAL']"),
    ("diffuse_bounces", -1, "an integer in [0, 1024]"),
    ("fast_gi", True, "an integer in [0, 1024]"),
    ("light_threshold", 2, "a number in [0, 1]"),
    ("caustics", "no", "True or False"),
    ("scrambling_distance", "fast", "'auto' or a number in [0, 1]"),
    ("tile_size", 4, "an integer in [8, 16384]"),
])
def test_a_bad_lever_is_one_line_naming_the_value_and_what_is_allowed(name, value, allowed):
    from kubric.renderer.blender import Blender
    with pytest.raises(ValueError) as err:
        Blender(kb.Scene(resolution=(8, 8)), **{name: value})
    message = str(err.value)
    assert "\n" not in message and name in message and repr(value) in message
    assert allowed in message


@pytest.mark.blender
def test_path_guiding_on_the_gpu_device_is_refused():
    from kubric.renderer.blender import Blender
    scene = kb.Scene(resolution=(8, 8), frame_start=1, frame_end=1)
    scene.camera = kb.PerspectiveCamera(position=(0, -3, 2), look_at=(0, 0, 0))
    r = Blender(scene, path_guiding="surface")
    r.device = "GPU"  # as constructed on a GPU machine; the check is the renderer's, not Cycles'
    with pytest.raises(ValueError, match=r"path_guiding='surface' needs device 'CPU'.*'GPU'"):
        r.render(return_layers=("rgba",))


def test_the_quality_label_and_renderer_arguments_name_each_lever():
    from dataclasses import replace

    from kubric.pipeline import get_recipe
    p = replace(_oidn(64, adaptive=0.2), adaptive_min_samples=16, path_guiding="surface",
                clamp_indirect=1.0, filter_glossy=3.0)
    assert p.label == ("≤64 spp adaptive 0.2 min 16 + OIDN HIGH/ACCURATE, guiding surface, "
                       "clamp 0/1, filter glossy 3")
    assert _oidn(64, adaptive=0.1).label == "≤64 spp adaptive 0.1 + OIDN HIGH/ACCURATE"
    assert p.levers() == {"path_guiding": "surface", "clamp_indirect": 1.0,
                          "filter_glossy": 3.0, "adaptive_min_samples": 16}
    recipe = get_recipe("movi_a").from_assignments([])
    recipe.base_profile = lambda: p
    kw = recipe.renderer_quality()
    assert kw["adaptive_threshold"] == 0.2 and kw["clamp_indirect"] == 1.0
    assert kw["path_guiding"] == "surface" and "clamp_direct" not in kw


@pytest.mark.blender
def test_a_lever_set_as_a_recipe_option_reaches_the_renderer_and_the_metadata():
    """``--set`` levers override the profile's fields, become renderer arguments (Blender's
    constructor validates them again) and are recorded in metadata; unset, nothing is recorded."""
    from kubric.pipeline import get_recipe
    from kubric.renderer.blender import Blender
    from kubric.renderer.blender_sampling import BLENDER_DEFAULTS
    recipe = get_recipe("movi_c").from_assignments(
        ["fast_gi=1", "total_bounces=4", "caustics=false", "scrambling_distance=auto",
         "denoising_input_passes=RGB_ALBEDO", "clamp_indirect=1"])
    kw = recipe.renderer_settings()
    assert {k: kw[k] for k in ("fast_gi", "total_bounces", "caustics", "scrambling_distance",
                               "denoising_input_passes", "clamp_indirect")} == {
        "fast_gi": 1, "total_bounces": 4, "caustics": False, "scrambling_distance": "auto",
        "denoising_input_passes": "RGB_ALBEDO", "clamp_indirect": 1.0}
    assert kw["adaptive_threshold"] == 0.1  # the calibrated default's other fields stay
    meta = recipe.render_metadata(Blender(kb.Scene(resolution=(8, 8)), **kw))
    assert meta["fast_gi"] == 1 and meta["caustics"] is False and meta["total_bounces"] == 4
    assert meta["quality_setting"] == (
        "≤64 spp adaptive 0.1 + OIDN HIGH/ACCURATE, clamp 0/1, OIDN guides albedo, bounces "
        "4/4/4/12, fast GI 1, no caustics, scrambling auto")
    plain = get_recipe("movi_c").from_assignments([])
    meta = plain.render_metadata(Blender(kb.Scene(resolution=(8, 8)),
                                         **plain.renderer_settings()))
    assert not set(BLENDER_DEFAULTS) & set(meta)
    assert meta["quality_setting"] == "≤64 spp adaptive 0.1 + OIDN HIGH/ACCURATE"


@pytest.mark.parametrize("assignment, allowed", [
    ("fast_gi=-1", "int ≥ 0 ≤ 1024"),
    ("scrambling_distance=2", "'auto' or a number in [0, 1]"),
    ("denoising_input_passes=NORMAL", "one of RGB, RGB_ALBEDO, RGB_ALBEDO_NORMAL"),
    ("caustics=maybe", "bool"),
])
def test_a_bad_lever_option_is_one_line(assignment, allowed):
    from kubric.pipeline import OptionError, get_recipe
    with pytest.raises(OptionError) as err:
        get_recipe("movi_a").from_assignments([assignment])
    message = str(err.value)
    assert "\n" not in message and assignment.split("=")[0] in message and allowed in message


def test_a_lever_option_needs_a_backend_with_quality_profiles():
    from kubric.pipeline import OptionError, get_recipe
    with pytest.raises(OptionError, match=r"renderer=raycast cannot .*\(fast_gi=1\)"):
        get_recipe("movi_a").from_assignments(["renderer=raycast", "fast_gi=1"])
