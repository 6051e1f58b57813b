"""The ``quality`` option: profiles resolve to renderer settings, overrides win, and the exact
layers are byte-identical under every profile (the render-cost issue's must-show), while RGB is
not."""

import concurrent.futures
import json

import numpy as np
import pytest
from collection_fixtures import run_worker

from kubric.pipeline import OptionError, get_recipe
from kubric.recipes.render_quality import CALIBRATED_DEFAULTS, PROFILES

EXACT = ("depth", "segmentation", "forward_flow", "backward_flow", "normal",
         "object_coordinates", "uv")


@pytest.mark.parametrize("recipe", ["movi_a", "movi_e", "klevr", "vbr", "svr"])
def test_profiles_resolve_to_renderer_settings(recipe):
    for name, profile in PROFILES.items():
        if name == "default":  # the recipe's calibrated setting (test_render_calibration.py)
            profile = CALIBRATED_DEFAULTS[recipe]
        r = get_recipe(recipe).from_assignments([f"quality={name}"])
        expected = {"samples_per_pixel": profile.samples, "use_denoising": profile.denoise,
                    "denoising_quality": profile.denoising_quality,
                    "denoising_prefilter": profile.denoising_prefilter}
        if profile.adaptive_threshold:
            expected.update(adaptive_sampling=True, adaptive_threshold=profile.adaptive_threshold)
        if name in ("fast", "draft"):  # cheap scenes: the allocator tuning is 2 % of their cost
            expected["keep_freed_memory"] = True
        assert r.renderer_quality() == expected
        settings = r.renderer_settings(motion_blur=0.0)
        assert settings == {**r.renderer_quality(), "motion_blur": 0.0}
    default = get_recipe(recipe).from_assignments([])
    assert default.quality == "default"
    assert default.renderer_quality()["samples_per_pixel"] == CALIBRATED_DEFAULTS[recipe].samples


def test_samples_and_denoise_override_the_profile():
    r = get_recipe("movi_a").from_assignments(["quality=draft", "samples=12", "denoise=false"])
    kw = r.renderer_quality()
    assert kw["samples_per_pixel"] == 12 and kw["use_denoising"] is False
    assert kw["denoising_quality"] == PROFILES["draft"].denoising_quality  # the rest stays
    assert r.renderer_settings()["samples_per_pixel"] == 12


def test_bad_quality_is_one_line_naming_the_choices():
    with pytest.raises(OptionError) as err:
        get_recipe("movi_a").from_assignments(["quality=ultra"])
    message = str(err.value)
    assert "\n" not in message and "ultra" in message
    assert all(name in message for name in PROFILES)


@pytest.mark.blender
def test_exact_layers_identical_across_profiles(tmp_path):
    get_recipe("movi_a").from_assignments([]).prepare()  # build KuBasic once
    qualities = ("draft", "final")
    options = ("resolution=40x32", "frame_end=3", "max_num_objects=4")
    with concurrent.futures.ThreadPoolExecutor(2) as pool:  # run_worker fails the test on error
        list(pool.map(lambda q: run_worker("movi_a", 2, tmp_path / q, (*options, f"quality={q}")),
                      qualities))
    scenes = {q: tmp_path / q / "scene_00000002" for q in qualities}
    files = {q: sorted(f.name for f in s.iterdir()) for q, s in scenes.items()}
    assert files["draft"] == files["final"]
    exact = [n for n in files["draft"] if n.rsplit("_", 1)[0] in EXACT]
    assert len(exact) == 3 * len(EXACT)
    for name in exact + ["data_ranges.json", "events.json"]:
        assert (scenes["draft"] / name).read_bytes() == (scenes["final"] / name).read_bytes(), name
    meta = {q: json.loads((s / "metadata.json").read_text()) for q, s in scenes.items()}
    assert meta["draft"]["instances"] == meta["final"]["instances"]
    assert meta["draft"]["camera"] == meta["final"]["camera"]
    for q in qualities:
        renderer = meta[q]["metadata"]["renderer"]
        assert renderer["quality"] == q
        assert renderer["samples_per_pixel"] == PROFILES[q].samples
        assert renderer["denoising_quality"] == PROFILES[q].denoising_quality
        assert renderer["quality_setting"] == PROFILES[q].label
        assert meta[q]["flags"]["quality"] == q
    from PIL import Image
    rgb = {q: np.stack([np.asarray(Image.open(s / f"rgba_{i:05d}.png"), np.int16)
                        for i in range(3)]) for q, s in scenes.items()}
    diff = np.abs(rgb["draft"] - rgb["final"])[..., :3]
    assert diff.max() > 0  # the profiles really render differently ...
    assert diff.mean() < 8  # ... the same scene
