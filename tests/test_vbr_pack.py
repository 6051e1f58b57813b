"""vbr scenes end to end through the dataset tools: `kubric worker vbr` (a rigid and an
articulated object, 32², 3 frames, 1 sample) → `kubric inspect` (schema recognised) → `kubric
pack --verify` → `kubric.datasets.load` (the `video` task and full examples) and `kubric view`;
every value checked against the scene directories read independently (PNG / TIFF files,
metadata.json)."""

from __future__ import annotations

import dataclasses
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from collection_fixtures import run_worker
from PIL import Image

from kubric.datasets import load
from kubric.io import png_io, tiff_io
from kubric.io.schema import Feature, SchemaError

pytestmark = pytest.mark.blender  # every test reads scenes the module fixture renders

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ("resolution=32", "num_frames=3", "samples=1", "denoise=false")
T, H, W = 3, 32, 32
SCENES = {"rigid": (5, ("object_type=rigid", "shape=torus")),
          "articulated": (3, ("object_type=articulated", "articulated_model=r2d2",
                              "camera=follow"))}


def kubric_cli(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc.stdout


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    """{"scenes": scenes dir, "dataset": dataset dir, "rigid" / "articulated": scene name,
    "inspect": {kind: kubric inspect's report}}."""
    root = tmp_path_factory.mktemp("vbrpack")
    scenes = root / "scenes"
    out = {"scenes": scenes, "dataset": root / "dataset", "inspect": {}}
    for kind, (seed, options) in SCENES.items():
        run_worker("vbr", seed, scenes, TINY + options)
        out[kind] = f"scene_{seed:08d}"
        out["inspect"][kind] = kubric_cli("inspect", scenes / out[kind], "--sheet",
                                          root / f"{kind}.png")
    stdout = kubric_cli("pack", scenes, "--out", out["dataset"], "--splits", "train=1",
                        "--verify", "--no-progress")
    assert "verified: every example equals its scene directory (2 examples)" in stdout
    return out


def read_frames(scene: pathlib.Path, template: str, reader) -> np.ndarray:
    return np.stack([reader(scene / template.format(i)) for i in range(T)])


def test_inspect_recognises_the_vbr_schema(packed):
    from kubric.pipeline.recipe import schema_of as get_schema
    count = len(get_schema("vbr").features)
    for report in packed["inspect"].values():
        assert f"schema vbr (from schema.json): {count} features, every source present" in report


def test_video_task_frames_bit_exact(packed):
    scenes = packed["scenes"]
    source = load(packed["dataset"], "train", task="video")
    assert sorted(source.scenes) == sorted([packed["rigid"], packed["articulated"]])
    for index, name in enumerate(source.scenes):
        item = source[index]
        rgba = read_frames(scenes / name, "rgba_{:05d}.png", lambda p: np.asarray(Image.open(p)))
        assert item["video_name"] == name
        assert item["video"].shape == (T, H, W, 3) and item["video"].dtype == np.uint8
        assert np.array_equal(item["video"], rgba[..., :3])
        assert len(np.unique(item["video"].reshape(-1, 3), axis=0)) > 10  # a real render
    # per-frame tasks: one item per frame, the same pixels, the exact depth
    frames = load(packed["dataset"], "train", task="frames")
    rays = load(packed["dataset"], "train", task="nerf_rays")
    assert len(frames) == len(rays) == 2 * T
    name, frame = source.scenes[1], 2
    video = source[1]["video"]
    depth = tiff_io.read_tiff(scenes / name / f"depth_{frame:05d}.tiff")[..., 0]
    item, ray = frames[T + frame], rays[T + frame]
    assert item["video_name"] == ray["video_name"] == name and item["frame"] == frame
    assert np.array_equal(item["image"], video[frame]) and np.array_equal(ray["depth"], depth)


def test_examples_equal_the_scene_directories(packed):
    scenes = packed["scenes"]
    source = load(packed["dataset"], "train")
    for index, name in enumerate(source.scenes):
        scene, ex = scenes / name, source[index]
        meta = json.loads((scene / "metadata.json").read_text())
        n = meta["metadata"]["num_instances"]
        # segmentation: one label per instance (part), 0 = background
        seg = read_frames(scene, "segmentation_{:05d}.png", lambda p: np.asarray(Image.open(p)))
        assert np.array_equal(ex["segmentations"][..., 0], seg)
        assert ex["segmentations"].dtype == np.uint8 and 0 < seg.max() <= n
        for k, inst in enumerate(meta["instances"]):
            assert [int((seg[t] == k + 1).sum()) for t in range(T)] == inst["visibility"]
        # depth: the float32 TIFF samples; flows: the raw uint16 PNG samples and their ranges
        depth = read_frames(scene, "depth_{:05d}.tiff", tiff_io.read_tiff)
        assert ex["depth"].dtype == np.float32 and np.array_equal(ex["depth"], depth)
        assert np.all(depth[seg == 0] == meta["metadata"]["background_depth"])
        assert np.all(depth[seg > 0] < 100)
        ranges = json.loads((scene / "data_ranges.json").read_text())
        for flow in ("forward_flow", "backward_flow"):
            raw = read_frames(scene, flow + "_{:05d}.png", png_io.read_png)  # (Δrow, Δcol, 0)
            assert ex[flow].dtype == np.uint16 and np.array_equal(ex[flow], raw[..., :2])
            assert list(ex["metadata"][f"{flow}_range"]) == [
                np.float32(ranges[flow]["min"]), np.float32(ranges[flow]["max"])]
        # camera per frame, equal to metadata.json
        cam = meta["camera"]
        for key in ("matrices_world", "positions", "quaternions", "intrinsics_pixels"):
            assert np.array_equal(ex["camera"][key], np.asarray(cam[key], np.float32)), key
        assert ex["camera"]["matrices_world"].shape == (T, 4, 4)
        # scene facts
        md = ex["metadata"]
        assert md["video_name"] == name and md["num_frames"] == T and md["num_instances"] == n
        assert source.schema["metadata/object_type"].names[md["object_type"]] == \
            meta["metadata"]["object_type"]
        assert md["object_model"] == meta["metadata"]["object_model"]
        assert md["background"] == meta["metadata"]["background"]
        # instances: poses and boxes as written
        insts = ex["instances"]
        assert np.array_equal(insts["positions"], np.asarray(
            [i["positions"] for i in meta["instances"]], np.float32))
        for k, inst in enumerate(meta["instances"]):
            assert insts["bboxes"][k].shape == (len(inst["bbox_frames"]), 4)
            assert list(insts["bbox_frames"][k]) == inst["bbox_frames"]


def test_link_structure(packed):
    """Rigid: one instance, no links. Articulated: the base (root link) and one instance per
    other URDF link, each naming its link and its base's asset id."""
    source = load(packed["dataset"], "train")
    by_name = {name: source[i] for i, name in enumerate(source.scenes)}
    rigid = by_name[packed["rigid"]]["instances"]
    assert list(rigid["articulated_link"]) == [""] and list(rigid["articulated_base"]) == [""]
    art = by_name[packed["articulated"]]["instances"]
    meta = json.loads((packed["scenes"] / packed["articulated"] / "metadata.json").read_text())
    bases = [k for k, link in enumerate(art["articulated_link"]) if link == ""]
    assert len(bases) == 1 and art["articulated_base"][bases[0]] == ""
    base_id = art["asset_id"][bases[0]]
    links = [link for link in art["articulated_link"] if link]
    assert sorted(links) == meta["instances"][bases[0]]["articulated_links"]
    assert len(links) == len(art["asset_id"]) - 1 >= 5
    assert all(b == base_id for k, b in enumerate(art["articulated_base"]) if k != bases[0])
    # several parts are visible with labels of their own
    seg = by_name[packed["articulated"]]["segmentations"]
    assert len(np.unique(seg[seg > 0])) >= 3


def test_viewer_shows_vbr_scenes(packed):
    from viewer_helpers import get_json, request, serving

    scene = packed["scenes"] / packed["articulated"]
    meta = json.loads((scene / "metadata.json").read_text())
    seg = np.asarray(Image.open(scene / "segmentation_00001.png"))
    row, col = (int(v[0]) for v in np.nonzero(seg))
    with serving(packed["scenes"]) as (address, _):
        status, listing = get_json(address, "/api/scenes")
        assert status == 200
        rows = {r["name"]: r for r in listing["scenes"]}
        assert set(rows) == {packed["rigid"], packed["articulated"]}
        for r in rows.values():
            assert r["recipe"] == "vbr" and r["error"] is None and r["num_frames"] == T
            assert {"rgba", "depth", "segmentation", "forward_flow",
                    "backward_flow"} <= set(r["layers"])
        name = packed["articulated"]
        for layer in ("rgba", "segmentation", "depth", "forward_flow"):
            status, ctype, body = request(address, f"/api/frame/{name}/{layer}/1.png")
            assert status == 200 and ctype == "image/png" and body[:4] == b"\x89PNG"
        status, probe = get_json(address, f"/api/probe/{name}/1?row={row}&col={col}")
        assert status == 200 and probe["label"] == seg[row, col]
        assert probe["asset_id"] == meta["instances"][seg[row, col] - 1]["asset_id"]


def test_missing_link_fields_need_the_default(packed):
    """The rigid scene has no articulated_link: only the feature's default lets it pack."""
    from kubric.io.scene_reader import SceneError, SceneReader
    from kubric.pipeline.recipe import schema_of as get_schema
    schema = get_schema("vbr")
    strict = dataclasses.replace(schema["instances/articulated_link"], default=None)
    bare = schema.extend("vbr_strict", (strict,), drop=("instances/articulated_link",))
    with pytest.raises(SceneError, match="no field 'articulated_link'"):
        SceneReader(packed["scenes"] / packed["rigid"], bare).example()
    with pytest.raises(SchemaError, match="default"):
        Feature("metadata/x", "str", (), "meta:x", "text", default="")
    with pytest.raises(SchemaError, match="default 3 is not a value of dtype str"):
        Feature("instances/x", "str", (), "instance:x", "text", default=3)


def test_an_instance_never_visible_packs_with_empty_boxes(packed, tmp_path):
    """A part seen in no frame (V = 0): its boxes are (0, 4) in the scene reader and the loader
    alike, so --verify holds (a copy of the articulated scene with one link hidden)."""
    import shutil

    from kubric.datasets import pack
    from kubric.io.scene_reader import SceneReader
    from kubric.pipeline.recipe import schema_of as get_schema
    scene = tmp_path / "scenes" / packed["articulated"]
    shutil.copytree(packed["scenes"] / packed["articulated"], scene)
    meta = json.loads((scene / "metadata.json").read_text())
    meta["instances"][-1].update(bboxes=[], bbox_frames=[], visibility=[0] * T)
    (scene / "metadata.json").write_text(json.dumps(meta))
    boxes = SceneReader(scene, get_schema("vbr")).example(["instances/bboxes"])
    assert boxes["instances/bboxes"][-1].shape == (0, 4)
    result = pack(tmp_path / "scenes", tmp_path / "dataset", splits="train=1", progress=False,
                  verify=True)
    assert result.counts == {"train": 1} and not result.corrupt
    ex = load(tmp_path / "dataset", "train")[0]
    assert ex["instances"]["bboxes"][-1].shape == (0, 4)
    assert list(ex["instances"]["bbox_frames"][-1]) == []
    with pytest.raises(SchemaError, match="default True is not a value of dtype int32"):
        Feature("instances/x", "int32", (), "instance:x", default=True)
    assert Feature("instances/x", "float32", (), "instance:x", default=0).default == 0
