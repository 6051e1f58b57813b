"""Packed MOVi A–F datasets hold every feature of upstream's published MOVi datasets (issue #33).

``tests/data/upstream_movi_features.json`` is the table of upstream's feature specs (names,
dtypes, shapes, class names), written down from upstream's ``challenges/movi/movi_a.py`` …
``movi_f.py`` (``_info()``). Each of our schemas must cover every row with the same dtype and a
compatible shape; then tiny real MOVi-D (raycast) and MOVi-F (Blender, motion blur) scenes are
packed with ``kubric pack`` and read through ``kubric.datasets.load`` with the keys upstream's
reader indexes (``ex["instances"]["category"]``, ``ex["metadata"]["motion_blur"]``, ...).
"""

import json
import pathlib

import numpy as np
import pytest

from tests.test_every_recipe import _kubric

ROOT = pathlib.Path(__file__).resolve().parents[1]
TABLE = json.loads((ROOT / "tests" / "data" / "upstream_movi_features.json").read_text())
VARIANTS = sorted(TABLE["variants"])
#: upstream's dimension symbols → ours (a varying length, null, is our per-instance V)
DIM_NAMES = {"s": "T", "h": "H", "w": "W", None: "V"}


def upstream_features(variant: str) -> list:
    rows = TABLE["common"] + TABLE["variants"][variant]
    return [(row[0], row[1], tuple(row[2]), tuple(row[3]) if len(row) > 3 else ()) for row in rows]


def test_table_has_every_variant_and_no_duplicates():
    assert VARIANTS == ["movi_a", "movi_b", "movi_c", "movi_d", "movi_e", "movi_f"]
    for variant in VARIANTS:
        names = [row[0] for row in upstream_features(variant)]
        assert len(names) == len(set(names)), variant


@pytest.mark.parametrize("variant", VARIANTS)
def test_schema_covers_upstream_features(variant):
    from kubric.pipeline.recipe import schema_of
    schema = schema_of(variant)
    problems = []
    for name, dtype, shape, names in upstream_features(variant):
        if name not in schema:
            problems.append(f"{name}: missing")
            continue
        ours = schema[name]
        if ours.dtype != dtype:
            problems.append(f"{name}: dtype {ours.dtype} != upstream {dtype}")
        expected = tuple(d if isinstance(d, int) else DIM_NAMES[d] for d in shape)
        if tuple(ours.shape) != expected:
            problems.append(f"{name}: shape {ours.shape} != upstream {shape} = {expected}")
        if tuple(ours.names) != names:
            problems.append(f"{name}: class names {ours.names} != upstream {names}")
    assert not problems, f"{variant}: " + "; ".join(problems)


# ------------------------------------------------------------------ real packed scenes
#: KuBasic shapes given GSO categories (and one that is not a GSO category, one with none):
#: expected instances/category = the name if it is one of upstream's, else "None"
CATEGORIES = {"cube": "Toys", "sphere": "Shoe", "cylinder": "Bag", "cone": "Hat",
              "torus": "Furniture", "gear": "Consumer Goods", "teapot": "Bottles and Cans and Cups",
              "suzanne": "Action Figures", "spot": "Stuffed Toys"}
SMALL = ["resolution=24", "frame_end=2", "min_num_objects=3", "max_num_objects=4",
         "max_num_dynamic=2", "settle_frames=10"]
SEED = 3  # MOVi-D: a sphere (Shoe), a cube (Toys), a cone (Hat) and a torus (not GSO: "None")
SCENES = {
    "movi_d": SMALL + ["renderer=raycast"],
    "movi_f": SMALL + ["samples=1", "denoise=false", "max_motion_blur=2"],
}



@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    root = tmp_path_factory.mktemp("upstream_movi")
    objects = with_categories(asset_tools.ensure_kubasic(), CATEGORIES, root / "objects")
    out = {}
    for variant, options in SCENES.items():
        sets = [a for o in options + [f"objects_source={objects}"] for a in ("--set", o)]
        _kubric("worker", variant, "--seed", SEED, "--out", root / variant / "scenes", *sets)
        _kubric("pack", root / variant / "scenes", "--out", root / variant / "dataset",
                "--splits", "train=1")
        out[variant] = root / variant
    return out


def _lookup(example, name):
    """example["a"]["b"]... as upstream's reader indexes it (KeyError when a key is missing)."""
    node = example
    for key in ([name] if "/" not in name else
                ["events", "collisions", name.split("/", 2)[2]] if name.startswith("events/")
                else name.split("/")):
        node = node[key]
    return node


@pytest.mark.blender
@pytest.mark.slow
@pytest.mark.parametrize("variant", sorted(SCENES))
def test_packed_scene_reads_with_upstream_keys(packed, variant):
    import kubric.datasets as kd
    from kubric import file_io
    example = kd.load(packed[variant] / "dataset", "train")[0]
    meta = file_io.read_json(next((packed[variant] / "scenes").iterdir()) / "metadata.json")
    dims = {"s": meta["metadata"]["num_frames"], "h": meta["metadata"]["resolution"][1],
            "w": meta["metadata"]["resolution"][0]}
    n = int(example["metadata"]["num_instances"])
    assert n >= 1
    for name, dtype, shape, _ in upstream_features(variant):
        value = _lookup(example, name)
        if dtype == "str":
            assert all(isinstance(v, str) for v in (value if name.startswith("instances/")
                                                     else [value])), name
            continue
        per_element = value if name.startswith(("instances/", "events/")) else [value]
        if name.startswith("instances/"):
            assert len(per_element) == n, name
        for element in per_element:
            arr = np.asarray(element)
            assert arr.dtype == np.dtype(dtype), (name, arr.dtype, dtype)
            want = tuple(dims[d] if isinstance(d, str) else d for d in shape)
            assert len(arr.shape) == len(want) and all(
                w is None or w == a for w, a in zip(want, arr.shape, strict=True)), \
                (name, arr.shape, want)

    # values: category from each instance's asset id and the table above, upstream's names
    names = [row[3] for row in TABLE["variants"][variant] if row[0] == "instances/category"][0]
    seen = []
    for asset_id, label in zip(example["instances"]["asset_id"],
                               example["instances"]["category"], strict=True):
        given = CATEGORIES.get(asset_id)
        assert names[int(label)] == (given if given in names else "None"), asset_id
        seen.append(names[int(label)])
    if variant == "movi_d":  # both kinds of asset are in the scene
        assert "None" in seen and len(set(seen)) >= 3, seen


@pytest.mark.blender
@pytest.mark.slow
def test_motion_blur_is_the_shutter_blender_was_given(packed):
    import kubric.datasets as kd
    from kubric import file_io
    example = kd.load(packed["movi_f"] / "dataset", "train")[0]
    meta = file_io.read_json(next((packed["movi_f"] / "scenes").iterdir()) / "metadata.json")
    blur = float(example["metadata"]["motion_blur"])
    assert 0.0 < blur < 2.0  # U(0, max_motion_blur=2)
    assert blur == pytest.approx(meta["metadata"]["renderer"]["motion_blur"], abs=1e-6)
    assert meta["flags"]["max_motion_blur"] == 2.0
