"""Every registered recipe, end to end through the one declared scene directory: a tiny scene is
rendered by the worker, written by ``write_scene`` (which reads it back as the packer will), holds
only files the scene directory declares, and packs with ``kubric pack --verify``.

A new built-in recipe must declare a schema (registration refuses it otherwise) and needs a row
in TINY below (the first test fails until it has one).
"""

import json
import pathlib
import subprocess
import sys
import types

import pytest

from kubric.io import scene_dir
from kubric.io.scene_writer import check_written
from kubric.pipeline import Recipe
from kubric.pipeline.recipe import load_builtin

ROOT = pathlib.Path(__file__).resolve().parents[1]
BASE = ["samples=1", "denoise=false"]
MOVI = BASE + ["resolution=24", "frame_end=2", "max_num_objects=3"]
MOVI_DEF = MOVI + ["min_num_objects=1", "max_num_dynamic=2"]
VIEWS = BASE + ["resolution=24x16", "num_views=3", "split_ratio=1,1,1"]
#: options that make a tiny but complete scene of each built-in recipe
TINY = {
    "movi_a": MOVI, "movi_b": MOVI, "movi_c": MOVI, "movi_d": MOVI_DEF, "movi_e": MOVI_DEF,
    "movi_f": MOVI_DEF,
    "klevr": VIEWS + ["min_num_objects=3", "max_num_objects=4"],
    "toybox": VIEWS + ["num_categories=2"],  # + objects=<a KuBasic copy with categories>
    "texture_nerf": VIEWS + ["num_objects=4", "texture_size=64", "band_range=-1,1.2"],
    "robust_nerf": VIEWS + ["num_impostors=1", "min_num_objects=2", "max_num_objects=3"],
    "multiview_matting": VIEWS + ["min_num_clutter=1", "max_num_clutter=2"],
    "nvs": VIEWS, "complex_brdf": VIEWS, "svr": VIEWS,
    "vbr": BASE + ["resolution=24", "num_frames=3"],
    "bench": [],  # no rendering: random images and labels (scale measurements)
    "pose_estimation": BASE + ["resolution=24", "frame_end=2", "max_num_people=1",
                               "min_num_clutter=0", "max_num_clutter=1",
                               "character_source=procedural", "motion_source=procedural"],
}
TOY_CATEGORIES = {"cube": "boxy", "sponge": "boxy", "sphere": "round", "cylinder": "round",
                  "torus": "round", "teapot": "kitchen"}
#: a recipe's own files beside its layers, which it declares to the writer (multi-view: NeRF
#: transforms, points)
RECIPE_FILES = {"transforms_train.json", "transforms_val.json", "transforms_test.json",
                "points.npz"}
#: files of a scene directory beside its layers
OTHER_FILES = {scene_dir.METADATA_FILE, scene_dir.EVENTS_FILE, scene_dir.DATA_RANGES_FILE,
               scene_dir.SCHEMA_FILE, scene_dir.SUCCESS_FILE} | RECIPE_FILES


def test_every_builtin_recipe_has_a_schema_and_a_tiny_row():
    recipes = load_builtin()
    assert sorted(TINY) == sorted(recipes), "add a TINY row for each new recipe"
    for name, cls in recipes.items():
        assert cls.schema is not None and cls.schema.name == name
        for variant in cls.variants:
            assert variant.name.startswith(name + "_")


def test_builtin_recipe_without_schema_is_refused_at_registration():
    def body(ns):
        ns["__module__"] = "kubric.recipes.probe"
        ns["generate"] = lambda self, seed, out_dir: None
    with pytest.raises(TypeError, match=r"recipe 'probe_no_schema' .* declares no schema"):
        types.new_class("Probe", (Recipe,), {"name": "probe_no_schema"}, body)
    from kubric.recipes import movi_schema

    def wrong(ns):
        body(ns)
        ns["schema"] = movi_schema.MOVI_A
    with pytest.raises(TypeError, match="declares schema 'movi_a': a recipe's schema carries"):
        types.new_class("Probe", (Recipe,), {"name": "probe_wrong_schema"}, wrong)


def _kubric(*args, timeout=600):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, (args, proc.stdout[-2000:], proc.stderr[-3000:])
    return proc


@pytest.fixture(scope="module")
def toys(tmp_path_factory):
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    return with_categories(asset_tools.ensure_kubasic(), TOY_CATEGORIES,
                           tmp_path_factory.mktemp("toys") / "toys")


@pytest.mark.blender
@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TINY))
def test_recipe_scene_is_declared_checked_and_packs(name, tmp_path, request):
    # only toybox asks for the module's toys: the other recipes' scenes share nothing, so two
    # test workers may take them apart (a module fixture groups its users on one worker)
    options = TINY[name] + ([f"objects={request.getfixturevalue('toys')}"]
                            if name == "toybox" else [])
    sets = [a for o in options for a in ("--set", o)]
    _kubric("worker", name, "--seed", 3, "--out", tmp_path / "scenes", *sets)
    scene = tmp_path / "scenes" / scene_dir.scene_name(3)
    assert scene_dir.is_complete(scene)
    from kubric.pipeline.recipe import get_recipe
    schema = get_recipe(name).schema
    check_written(schema, scene)  # what write_scene checked, again from the final directory
    templates = [fmt.template for fmt in schema.layer_formats.values()]
    stored = json.loads((scene / scene_dir.SCHEMA_FILE).read_text())
    assert stored["name"] == name and stored["features"] == schema.to_json()["features"]
    for path in scene.iterdir():
        if path.is_dir():  # vbr's LASR folder, written by the writer and declared to it
            assert name == "vbr" and path.name == scene_dir.LASR_DIR, path
            assert stored["files"] == [scene_dir.LASR_DIR]
            continue
        declared = path.name in OTHER_FILES or any(
            path.name == t.format(i) for t in templates for i in range(64))
        assert declared, f"{name}: {path.name} is not declared by its schema or the scene dir"
        assert path.name not in RECIPE_FILES or path.name in stored["files"], path
    _kubric("pack", tmp_path / "scenes", "--out", tmp_path / "dataset", "--splits", "train=1",
            "--verify", timeout=900)
    assert (tmp_path / "dataset").is_dir()
