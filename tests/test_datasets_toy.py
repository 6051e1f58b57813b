"""The schema drives the writer: a toy recipe declares a layer and a metadata field in its schema
only, and both flow to the scene directory, the packed dataset, the loader and `kubric inspect`
with no other edit anywhere."""

import numpy as np
import pytest

from kubric.datasets import DatasetError, load, pack, register_task
from kubric.io.layers import LayerFormat
from kubric.io.scene_writer import write_scene
from kubric.io.schema import Feature, Schema, register_schema
from kubric.pipeline import Recipe
from kubric.pipeline.inspect import inspect_scene
from kubric.pipeline.worker import run_scene

T, H, W = 3, 6, 5
TOY = register_schema(Schema("test_toy_layers", (
    Feature("metadata/video_name", "str", (), "scene_name", "text"),
    Feature("metadata/seed", "int64", (), "meta:seed"),
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png"),
    Feature("albedo", "uint16", ("T", "H", "W", 3), "layer:albedo", "png",
            doc="the toy layer: reflectance in [0, 1] · 65535"),
    Feature("instances/weight", "float32", (), "instance:weight", unit="kg"),
    Feature("target_points", "float32", ("P", "T", 2), "npz:toy_points.npz:target_points",
            doc="a per-scene file the recipe writes (like tracks.npz)"),
), layers={"albedo": LayerFormat("albedo_{:05d}.png", 3, "unit")}))


def toy_layers(seed):
    rng = np.random.RandomState(seed)
    rgba = rng.randint(0, 256, size=(T, H, W, 4)).astype(np.uint8)
    albedo = rng.rand(T, H, W, 3).astype(np.float32)
    weights = rng.rand(int(rng.randint(0, 4))).astype(np.float32)
    tracks = rng.rand(int(rng.randint(1, 5)), T, 2).astype(np.float32)
    return rgba, albedo, weights, tracks


class ToyLayers(Recipe, name="test_toy_layers"):
    """A recipe whose schema adds the layer `albedo` and the instance field `weight`."""

    schema = TOY

    def generate(self, seed, out_dir):
        rgba, albedo, weights, tracks = toy_layers(seed)
        metadata = {"flags": self.flags(seed),
                    "metadata": {"resolution": [W, H], "num_frames": T, "seed": seed},
                    "instances": [{"weight": w} for w in weights]}
        write_scene(self.schema, out_dir, {"rgba": rgba, "albedo": albedo}, metadata,
                    files={"toy_points.npz": {"target_points": tracks}})


def test_toy_layer_flows_from_schema_to_loader(tmp_path):
    scenes = tmp_path / "scenes"
    for seed in range(4):
        run_scene(ToyLayers(), seed, scenes)
    assert (scenes / "scene_00000001" / "albedo_00002.png").is_file()
    assert "albedo" in inspect_scene(scenes / "scene_00000001", tmp_path / "sheet.png")
    result = pack(scenes, tmp_path / "toy", splits="train=1", progress=False, verify=True)
    assert result.counts == {"train": 4}
    source = load(tmp_path / "toy", "train")
    for index, scene in enumerate(source.scenes):
        seed = int(scene.split("_")[1])
        rgba, albedo, weights, tracks = toy_layers(seed)
        example = source[index]
        assert example["metadata"]["seed"] == seed
        assert np.array_equal(example["video"], rgba[..., :3])
        assert example["albedo"].dtype == np.uint16
        assert np.array_equal(example["albedo"], np.rint(albedo.astype(np.float64) * 65535))
        assert np.array_equal(example["instances"]["weight"], weights)
        assert np.array_equal(example["target_points"], tracks)
        assert np.array_equal(load(tmp_path / "toy", "train", task="toy_tracks")[index]["tracks"],
                              tracks[:, ::2])
    with pytest.raises(DatasetError, match=r"task 'nerf_rays' cannot read .* it needs \['depth', "
                       r"'camera/intrinsics_pixels', 'camera/matrices_world'\]; this dataset "
                       r"serves the tasks all, toy_tracks, video$"):
        load(tmp_path / "toy", "train", task="nerf_rays")


@register_task("toy_tracks", features=("target_points", "video"))
def toy_tracks(example, frame):
    """A recipe's own task: every other frame of its tracks."""
    return {"tracks": example["target_points"][:, ::2], "video": example["video"][::2]}
