"""Multi-view datasets end to end: `kubric generate` klevr, svr, texture_nerf and complex_brdf at
tiny settings →
`kubric pack --verify` → the `multiview`, `svr` and `nerf_rays` tasks, every value checked
against the scene directories read independently (PNG / TIFF files, metadata.json, the NeRF
transforms files, the asset source's manifest). PyTorch adapter, no TensorFlow, one-line errors.
"""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric.datasets import DatasetError, load
from kubric.datasets.exports import nerf as nerf_export
from kubric.datasets.multiview_tasks import BLENDER_TO_OPENCV
from kubric.io import png_io, tiff_io

pytestmark = pytest.mark.blender

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ["resolution=24x16", "samples=1", "denoise=false", "num_views=4", "split_ratio=2,1,1"]
RUNS = {
    "klevr": (3, TINY + ["min_num_objects=3", "max_num_objects=4"]),
    "svr": (4, TINY + ["object_categories=boxy,round,kitchen"]),
    "texture_nerf": (2, TINY + ["num_objects=6", "texture_size=64", "band_range=-1,1.2"]),
    "complex_brdf": (2, TINY),
}
CATEGORIES = {"cube": "boxy", "sponge": "boxy", "sphere": "round", "cylinder": "round",
              "torus": "round", "teapot": "kitchen"}
VIEWS, H, W = 4, 16, 24


def kubric_cli(*args):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    """{recipe: (scenes dir, dataset dir)}; svr draws from a KuBasic copy with categories."""
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    root = tmp_path_factory.mktemp("mvdata")
    source = with_categories(asset_tools.ensure_kubasic(), CATEGORIES, root / "toys")
    out = {}
    for recipe, (count, options) in RUNS.items():
        if recipe == "svr":
            options = options + [f"objects_source={source}"]
        scenes, dataset = root / f"{recipe}_scenes", root / recipe
        gen = ["generate", recipe, "--out", scenes, "--scenes", count, "--workers", 2,
               "--no-progress"]
        for option in options:
            gen += ["--set", option]
        proc = kubric_cli(*gen)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        proc = kubric_cli("pack", scenes, "--out", dataset, "--splits", "train=1", "--verify",
                          "--no-progress")
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
        assert f"verified: every example equals its scene directory ({count} examples)" in \
            proc.stdout
        out[recipe] = (scenes, dataset)
    proc = kubric_cli("pack", out["klevr"][0], "--out", root / "klevr_points", "--schema",
                      "klevr_points", "--splits", "train=1", "--verify", "--no-progress")
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    out["klevr_points"] = (out["klevr"][0], root / "klevr_points")
    out["manifest"] = json.loads((source / "manifest.json").read_text())
    return out


def read_stack(scene, template, reader=png_io.read_png):
    return np.stack([reader(scene / template.format(i)) for i in range(VIEWS)])


def read_labels(scene, template):
    return read_stack(scene, template, png_io.read_palette_png)[..., 0]


def transforms(scene):
    """{view: (split, frame entry, file)} from the NeRF transforms files."""
    out = {}
    for split in nerf_export.SPLITS:
        data = json.loads((scene / f"transforms_{split}.json").read_text())
        for entry in data["frames"]:
            out[entry["view"]] = (split, entry, data)
    return out


def surface_points(depth, entry, data):
    """World points of every pixel, from the transforms file's rays and the depth TIFF."""
    origins, directions = nerf_export.pixel_rays_from_transforms(data, entry)
    return origins + depth[..., None].astype(np.float64) * directions


def test_multiview_task_equals_the_klevr_scene_directories(packed):
    scenes, dataset = packed["klevr"]
    source = load(dataset, "train", task="multiview")
    assert len(source) == 3
    for index, name in enumerate(source.scenes):
        scene, item = scenes / name, source[index]
        meta = json.loads((scene / "metadata.json").read_text())
        views = transforms(scene)
        assert item["scene_name"] == name and list(item["views"]) == list(range(VIEWS))
        assert list(item["split"]) == [nerf_export.SPLITS.index(views[v][0]) for v in range(VIEWS)]
        # images and layers: bit-exact
        assert np.array_equal(item["images"], read_stack(scene, "rgba_{:05d}.png")[..., :3])
        depth = read_stack(scene, "depth_{:05d}.tiff", tiff_io.read_tiff)[..., 0]
        assert item["depth"].dtype == np.float32 and np.array_equal(item["depth"], depth)
        assert np.array_equal(item["segmentation"], read_labels(scene, "segmentation_{:05d}.png"))
        semantic = read_labels(scene, "semantic_{:05d}.png")
        assert np.array_equal(item["semantic_segmentation"], semantic) and semantic.max() > 0
        assert item["semantic_classes"] == meta["metadata"]["semantic_classes"]
        # cameras: equal to metadata.json and to the transforms files
        k = np.array(meta["camera"]["intrinsics_pixels"], np.float32)
        assert np.array_equal(item["intrinsics_pixels"], k)
        assert np.array_equal(item["camera_to_world"],
                              np.array(meta["camera"]["matrices_world"], np.float32))
        for v in range(VIEWS):
            _, entry, data = views[v]
            assert np.array_equal(item["camera_to_world"][v],
                                  np.array(entry["transform_matrix"], np.float32))
            assert np.allclose(k, [[data["fl_x"], 0, data["cx"]], [0, data["fl_y"], data["cy"]],
                                   [0, 0, 1]])
            # world_to_camera (OpenCV) + intrinsics send every surface point back to its pixel
            hit = depth[v] < meta["metadata"]["background_depth"]
            points = surface_points(depth[v], entry, data)[hit]
            cam = points @ item["world_to_camera"][v][:3, :3].T.astype(np.float64) \
                + item["world_to_camera"][v][:3, 3]
            assert np.all(cam[:, 2] > 0)
            pixels = cam @ k.T.astype(np.float64)
            rows, cols = np.nonzero(hit)
            assert np.max(np.abs(pixels[:, 0] / pixels[:, 2] - (cols + 0.5))) < 2e-3
            assert np.max(np.abs(pixels[:, 1] / pixels[:, 2] - (rows + 0.5))) < 2e-3
        assert np.allclose(item["world_to_camera"],
                           BLENDER_TO_OPENCV @ np.linalg.inv(item["camera_to_world"]), atol=1e-5)
    # `frames` gives one item per view of a multi-view dataset
    frames = load(dataset, "train", task="frames")
    assert len(frames) == 3 * VIEWS
    frame = frames[VIEWS + 2]
    assert frame["video_name"] == source.scenes[1] and frame["frame"] == 2
    assert np.array_equal(frame["image"], source[1]["images"][2])
    assert np.array_equal(frame["camera_to_world"], source[1]["camera_to_world"][2])
    # one split's views, in view order, and chosen layers
    train = load(dataset, "train", task="multiview", view_split="val",
                 layers=("normal",))[0]
    scene = scenes / source.scenes[0]
    val_views = [v for v, (s, _, _) in transforms(scene).items() if s == "val"]
    assert list(train["views"]) == val_views and set(train["split"]) == {1}
    assert np.array_equal(train["images"], read_stack(scene, "rgba_{:05d}.png")[val_views, ..., :3])
    assert "depth" not in train and train["normal"].shape == (len(val_views), H, W, 3)
    normal = png_io.read_png(scene / f"normal_{val_views[0]:05d}.png")
    assert np.max(np.abs(train["normal"][0] - (normal / 65535.0 * 2.0 - 1.0))) < 1e-7


def test_klevr_points_schema_packs_the_point_cloud(packed):
    scenes, dataset = packed["klevr_points"]
    source = load(dataset, "train")
    for index, name in enumerate(source.scenes):
        points = source[index]["points"]
        with np.load(scenes / name / "points.npz") as stored:
            assert set(points) == set(stored.files)
            for key in stored.files:
                assert points[key].dtype == stored[key].dtype, key
                assert np.array_equal(points[key], stored[key]), key
        assert len(points["xyz"]) == VIEWS * H * W  # the dome fills every pixel


def test_svr_task_image_category_camera_pose(packed):
    scenes, dataset = packed["svr"]
    manifest = packed["manifest"]["assets"]
    source = load(dataset, "train", task="svr")
    assert len(source) == 4 * VIEWS
    names = source.schema["instances/category"].names
    seen = set()
    for index in range(len(source)):
        item = source[index]
        scene = scenes / item["scene_name"]
        view = int(item["view"])
        assert source.scenes[index // VIEWS] == item["scene_name"] and view == index % VIEWS
        meta = json.loads((scene / "metadata.json").read_text())
        rgba = png_io.read_png(scene / f"rgba_{view:05d}.png")
        assert item["image"].dtype == np.uint8 and np.array_equal(item["image"], rgba)
        assert (item["image"][..., 3] == 0).any() and (item["image"][..., 3] == 255).any()
        (instance,) = meta["instances"]
        assert item["asset_id"] == instance["asset_id"]
        category = manifest[item["asset_id"]]["metadata"]["category"]
        assert item["category"] == category == CATEGORIES[item["asset_id"]]
        assert names[item["category_id"]] == category
        seen.add(category)
        camera = meta["camera"]
        assert np.array_equal(item["intrinsics_pixels"],
                              np.array(camera["intrinsics_pixels"], np.float32))
        assert np.array_equal(item["camera_to_world"],
                              np.array(camera["matrices_world"][view], np.float32))
        assert np.array_equal(item["object_position"],
                              np.array(instance["positions"][view], np.float32))
        assert np.array_equal(item["object_quaternion"],
                              np.array(instance["quaternions"][view], np.float32))
        split = transforms(scene)[view][0]
        assert nerf_export.SPLITS[item["split"]] == split
    # the ids index the sorted categories of the packed scenes, stored in the dataset for TFDS too
    assert list(names) == sorted(seen) and len(seen) >= 2
    assert (dataset / "instances-category.labels.txt").read_text().split() == list(names)


def test_nerf_rays_on_multiview_scenes_equal_the_transforms_files(packed):
    """nerf_rays of a packed texture_nerf scene = iter_views of its transforms files."""
    scenes, dataset = packed["texture_nerf"]
    rays = load(dataset, "train", task="nerf_rays")
    assert len(rays) == 2 * VIEWS
    for index in range(len(rays)):
        item = rays[index]
        scene = scenes / item["video_name"]
        view = int(item["frame"])
        split = transforms(scene)[view][0]
        (ref,) = [v for v in nerf_export.iter_views(scene, split) if v["view"] == view]
        assert np.array_equal(item["depth"], ref["depth"])
        assert np.array_equal(np.rint(item["rgb"] * 255).astype(np.uint8), ref["rgb"])
        assert np.allclose(item["ray_origins"], ref["origins"], atol=1e-5)
        assert np.allclose(item["ray_directions"], ref["directions"], atol=1e-5)
    # the recipe's own layers are packed exactly
    example = load(dataset, "train")[0]
    scene = scenes / example["metadata"]["video_name"]
    assert np.array_equal(example["bands"][..., 0], read_labels(scene, "band_{:05d}.png"))
    assert np.array_equal(example["cutoff_frequencies"],
                          read_stack(scene, "cutoff_{:05d}.tiff", tiff_io.read_tiff))
    meta = json.loads((scene / "metadata.json").read_text())
    assert np.array_equal(example["metadata"]["bands"],
                          np.array(meta["metadata"]["bands"], np.float32))


def test_complex_brdf_example_equals_its_metadata(packed):
    scenes, dataset = packed["complex_brdf"]
    source = load(dataset, "train")
    for index, name in enumerate(source.scenes):
        example = source[index]
        meta = json.loads((scenes / name / "metadata.json").read_text())
        (instance,) = meta["instances"]
        assert ("metal", "rubber")[example["instances"]["material"][0]] == instance["material"]
        assert np.array_equal(example["instances"]["color"][0],
                              np.array(instance["color"], np.float32))
        assert np.array_equal(example["metadata"]["lights"],
                              np.array(meta["metadata"]["lights"], np.float32))
        assert np.array_equal(example["views"]["split"],
                              [nerf_export.SPLITS.index(v["split"]) for v in meta["metadata"]["views"]])
        assert example["metadata"]["background"] == "black"


def test_torch_and_grain_adapters_for_the_new_tasks(packed):
    import torch.utils.data

    from kubric.datasets.adapters import to_torch, torch_collate
    svr = load(packed["svr"][1], "train", task="svr")
    loader = torch.utils.data.DataLoader(to_torch(svr), batch_size=VIEWS, num_workers=2,
                                         collate_fn=torch_collate,
                                         multiprocessing_context="spawn")
    batches = list(loader)
    assert len(batches) == 4
    for b, batch in enumerate(batches):
        assert tuple(batch["image"].shape) == (VIEWS, H, W, 4)
        assert batch["category_id"].dtype == torch.int64
        for v in range(VIEWS):
            ref = svr[b * VIEWS + v]
            assert np.array_equal(batch["image"][v].numpy(), ref["image"])
            assert batch["category"][v] == ref["category"]
    multiview = load(packed["klevr"][1], "train", task="multiview")
    batch = next(iter(torch.utils.data.DataLoader(to_torch(multiview), batch_size=3,
                                                  collate_fn=torch_collate)))
    assert tuple(batch["images"].shape) == (3, VIEWS, H, W, 3)
    assert tuple(batch["world_to_camera"].shape) == (3, VIEWS, 4, 4)
    assert np.array_equal(batch["depth"][2].numpy(), multiview[2]["depth"])
    assert isinstance(batch["semantic_classes"], list)
    from kubric.datasets.adapters import to_grain
    grain_batch = to_grain(svr, batch_size=VIEWS)[1]
    assert grain_batch["image"].shape == (VIEWS, H, W, 4)
    assert np.array_equal(grain_batch["image"][2], svr[VIEWS + 2]["image"])


def test_no_tensorflow_for_the_new_tasks(packed):
    klevr, svr = str(packed["klevr"][1]), str(packed["svr"][1])
    code = (
        "import sys, kubric.datasets as kd, tensorflow_datasets as tfds\n"
        f"kd.load({klevr!r}, 'train', task='multiview')[0]\n"
        f"kd.load({svr!r}, 'train', task='svr').__getitems__([0, 5])\n"
        f"kd.load({svr!r}, 'train', task='nerf_rays')[3]\n"
        f"ex = tfds.builder_from_directory({klevr!r}).as_data_source('train')[0]\n"
        "assert 'background' in [c.decode() for c in ex['metadata']['semantic_classes']]\n"
        "assert 'tensorflow' not in sys.modules, [m for m in sys.modules if 'tensorflow.' in m]\n"
        "print('no tensorflow')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, cwd=ROOT)
    assert proc.returncode == 0 and "no tensorflow" in proc.stdout, proc.stderr[-2000:]


def test_a_task_the_schema_cannot_serve_is_one_line(packed):
    klevr, svr = packed["klevr"][1], packed["svr"][1]
    cases = [
        (klevr, "svr", "task 'svr' cannot read", "it needs ['alpha']; this dataset serves the "
         "tasks all, frames, multiview, nerf_rays, video"),
        (svr, "point_tracks", "task 'point_tracks' cannot read", "serves the tasks all, frames, "
         "multiview, nerf_rays, svr, video"),
    ]
    for dataset, task, start, end in cases:
        with pytest.raises(DatasetError) as err:
            load(dataset, "train", task=task)
        message = str(err.value)
        assert "\n" not in message and message.startswith(start) and message.endswith(end)
    with pytest.raises(DatasetError, match=r"^task 'multiview': this klevr dataset has no "
                       r"layers \['alpha'\]; it has \['depth', "):
        load(klevr, "train", task="multiview", layers=("alpha",))
    with pytest.raises(DatasetError, match=r"view_split 'training' is not one of"):
        load(klevr, "train", task="multiview", view_split="training")


def test_datasets_info_and_schema_describe_multiview(packed):
    proc = kubric_cli("datasets", "info", packed["svr"][1])
    assert proc.returncode == 0, proc.stderr
    lines = [" ".join(line.split()) for line in proc.stdout.splitlines()]
    assert f"views T={VIEWS}, resolution H×W={H}×{W}" in proc.stdout
    assert "loader tasks: all, frames, multiview, nerf_rays, svr, video" in lines
    assert "instances/category class label[2] (N,) class_label" in lines
    assert "depth float32 (4, 16, 24, 1) zlib m" in lines
    for recipe in ("klevr", "toybox", "texture_nerf", "robust_nerf", "multiview_matting", "nvs",
                   "complex_brdf", "svr"):
        proc = kubric_cli("datasets", "schema", recipe)
        assert proc.returncode == 0 and f"### `{recipe}`" in proc.stdout, proc.stderr
    assert "| `semantic_segmentations` |" in kubric_cli("datasets", "schema", "klevr").stdout


def test_docs_snippets_run(packed):
    """The `multiview` and `svr` snippets of docs/datasets.md run on the packed datasets."""
    text = (ROOT / "docs" / "datasets.md").read_text()
    blocks = {}
    for title in ("### `multiview`", "### `svr`"):
        section = text.split(title, 1)[1]
        blocks[title] = section.split("```python\n", 1)[1].split("```", 1)[0]
    scope = {}
    code = blocks["### `multiview`"].replace('"klevr_dataset"', repr(str(packed["klevr"][1])))
    exec(compile(code, "docs/datasets.md multiview", "exec"), scope)
    assert scope["item"]["images"].shape == (2, H, W, 3)  # the train views of split_ratio 2,1,1
    code = blocks["### `svr`"].replace('"svr_dataset"', repr(str(packed["svr"][1])))
    exec(compile(code, "docs/datasets.md svr", "exec"), scope)
    batch = next(iter(scope["loader"]))
    assert tuple(batch["image"].shape) == (4 * VIEWS, H, W, 4)

