"""The schema kinds the multi-view datasets added, on a toy recipe (no rendering): text lists,
channel slices ``layer:rgba[3:4]``, float32 layers stored exactly (zlib), per-view split indices,
class-label names collected from the scenes when packing; and their one-line errors."""

import numpy as np
import pytest

from kubric.datasets import DatasetError, load, pack
from kubric.datasets.packer import read_class_names, resolve_names
from kubric.io import png_io, tiff_io
from kubric.io.scene_writer import write_scene
from kubric.io.schema import NAMES_FROM_SCENES, Feature, Schema, SchemaError, register_schema
from kubric.pipeline import Recipe
from kubric.pipeline.worker import run_scene

T, H, W = 3, 5, 4
SPLITS = ["train", "val", "test"]
CATEGORIES = ["mug", "chair", "bowl", "lamp"]
TOY = register_schema(Schema("test_toy_kinds", (
    Feature("metadata/video_name", "str", (), "scene_name", "text"),
    Feature("metadata/classes", "str", ("C",), "meta:classes", "text"),
    Feature("views/split", "uint8", ("T",), "meta:views", convert="split_index"),
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png"),
    Feature("alpha", "uint8", ("T", "H", "W", 1), "layer:rgba[3:4]", "png"),
    Feature("depth", "float32", ("T", "H", "W", 1), "layer:depth", "zlib", unit="m"),
    Feature("instances/category", "int64", (), "instance:category", "class_label",
            names=NAMES_FROM_SCENES),
)))


def toy_scene(seed):
    rng = np.random.RandomState(seed)
    rgba = rng.randint(0, 256, size=(T, H, W, 4)).astype(np.uint8)
    depth = rng.uniform(0.5, 50.0, size=(T, H, W, 1)).astype(np.float32)
    categories = [CATEGORIES[(seed + k) % 3] for k in range(seed % 3)]  # never "lamp"
    classes = ["background"] + CATEGORIES[: 1 + seed % 3]
    views = [{"split": SPLITS[(seed + v) % 3]} for v in range(T)]
    return rgba, depth, categories, classes, views


class ToyKinds(Recipe, name="test_toy_kinds"):
    """Writes the toy scenes of :data:`TOY`."""

    schema = TOY

    def generate(self, seed, out_dir):
        rgba, depth, categories, classes, views = toy_scene(seed)
        metadata = {"flags": self.flags(seed),
                    "metadata": {"resolution": [W, H], "num_frames": T, "seed": seed,
                                 "classes": classes, "views": views},
                    "instances": [{"category": c} for c in categories]}
        write_scene(self.schema, out_dir, {"rgba": rgba, "depth": depth}, metadata)


def test_new_kinds_flow_from_scene_to_loader(tmp_path):
    scenes = tmp_path / "scenes"
    for seed in range(5):
        run_scene(ToyKinds(), seed, scenes)
    result = pack(scenes, tmp_path / "toy", splits="train=1", progress=False, verify=True)
    assert result.counts == {"train": 5}
    source = load(tmp_path / "toy", "train")
    names = source.schema["instances/category"].names
    assert names == ("bowl", "chair", "mug")  # sorted values found, "lamp" never used
    for index, scene in enumerate(source.scenes):
        seed = int(scene.split("_")[1])
        rgba, depth, categories, classes, views = toy_scene(seed)
        example = source[index]
        assert example["metadata"]["classes"] == classes
        assert list(example["views"]["split"]) == [SPLITS.index(v["split"]) for v in views]
        assert np.array_equal(example["video"], rgba[..., :3])
        assert np.array_equal(example["alpha"], rgba[..., 3:4])
        assert example["depth"].dtype == np.float32 and np.array_equal(example["depth"], depth)
        assert [names[i] for i in example["instances"]["category"]] == categories
        stored = tiff_io.read_tiff(scenes / scene / "depth_00001.tiff")
        assert np.array_equal(example["depth"][1], stored)
        assert np.array_equal(png_io.read_png(scenes / scene / "rgba_00002.png")[..., 3:],
                              example["alpha"][2])


def test_bad_declarations_and_values_are_one_line(tmp_path):
    with pytest.raises(SchemaError, match=r"feature 'x': layer source 'rgba\[3\]' must be NAME"):
        Feature("x", "uint8", ("T", "H", "W", 1), "layer:rgba[3]", "png")
    with pytest.raises(SchemaError, match=r"feature 'x': text features have shape \(\) or one"):
        Feature("x", "str", (2, 3), "meta:x", "text")
    with pytest.raises(SchemaError, match=r"no features \['nope'\]"):
        TOY.with_names({"nope": ["a"]})
    # a scene naming a split that is not train / val / test is reported and skipped
    scenes = tmp_path / "scenes"
    for seed in range(3):
        run_scene(ToyKinds(), seed, scenes)
    meta_path = scenes / "scene_00000001" / "metadata.json"
    meta_path.write_text(meta_path.read_text().replace('"val"', '"holdout"'))
    result = pack(scenes, tmp_path / "toy", splits="train=1", progress=False)
    assert result.counts == {"train": 2}
    ((path, reason),) = result.corrupt
    assert path.endswith("scene_00000001") and "split_index: splits ['holdout']" in reason
    # names cannot be collected when no scene holds a value (scene 0 has no instances)
    with pytest.raises(DatasetError, match=r"no complete scene holds a value of "
                       r"\['instances/category'\]"):
        resolve_names(TOY, [scenes / "scene_00000000"])


def test_given_class_names_keep_ids_stable_across_datasets(tmp_path):
    """A second dataset packed with the first one's labels file shares its category ids, even
    when its scenes hold fewer categories."""
    first, second = tmp_path / "first", tmp_path / "second"
    for seed in range(5):
        run_scene(ToyKinds(), seed, first)
    for seed in (6, 9):  # seed % 3 == 0: no instances; 7 would add two categories
        run_scene(ToyKinds(), seed, second)
    run_scene(ToyKinds(), 10, second)  # one instance: CATEGORIES[10 % 3] = "chair"
    pack(first, tmp_path / "a", splits="train=1", progress=False)
    labels = tmp_path / "a" / "instances-category.labels.txt"
    assert labels.read_text().split() == ["bowl", "chair", "mug"]
    given = read_class_names([f"instances/category={labels}"])
    pack(second, tmp_path / "b", splits="train=1", progress=False, class_names=given,
         verify=True)
    source = load(tmp_path / "b", "train")
    assert source.schema["instances/category"].names == ("bowl", "chair", "mug")
    (with_instance,) = [i for i, s in enumerate(source.scenes) if s.endswith("10")]
    assert list(source[with_instance]["instances"]["category"]) == [1]
    # collected from these scenes alone, "chair" would have been id 0
    assert resolve_names(TOY, [second / "scene_00000010"])["instances/category"].names == \
        ("chair",)
    with pytest.raises(DatasetError, match=r"the scenes hold 'instances/category' values "
                       r"\['bowl', 'chair', 'mug'\], which the given class names \['lamp'\] lack"):
        pack(first, tmp_path / "c", splits="train=1", progress=False,
             class_names={"instances/category": ["lamp"]})
    with pytest.raises(DatasetError, match=r"class names given for \['video'\], which are not"):
        pack(first, tmp_path / "c", splits="train=1", progress=False,
             class_names={"video": ["x"]})
    with pytest.raises(DatasetError, match=r"--class-names 'instances/category' is not "
                       r"FEATURE=FILE"):
        read_class_names(["instances/category"])
    assert not (tmp_path / "c").exists()

