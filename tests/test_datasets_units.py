"""``kubric.datasets.load(..., units=...)`` on a real packed scene (MOVi-A rendered by the raycast
backend with bpy blocked, then ``kubric pack``):

* ``units="physical"``: flow in pixels, depth in metres, unit normals, object coordinates in the
  object's box frame — against the scene directory's own files (``read_image_dict``) to within
  the quantisation step, and against the scene's geometry (object coordinates of the surface
  point unprojected from depth; flow of that point carried to the next frame by the object's
  box and projected);
* ``units="raw"`` (the default): upstream's layout, the quantisation of the scene files (and the
  PNG samples themselves), unchanged by this switch.
"""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric.datasets import DatasetError, load, to_grain
from kubric.datasets.tasks import pixel_rays
from kubric.io import png_io
from kubric.io.layers import read_image_dict

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = ROOT / "tests" / "no_bpy"
T, S = 3, 48  # frames, resolution (S × S)


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    root = tmp_path_factory.mktemp("units")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    for args in (["worker", "movi_a", "--seed", "5", "--out", root / "scenes", "--set",
                  f"resolution={S}", "--set", f"frame_end={T}", "--set", "renderer=raycast",
                  "--set", "max_num_objects=4"],
                 ["pack", root / "scenes", "--out", root / "ds", "--splits", "train=1",
                  "--no-progress"]):
        proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                              env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene = root / "scenes" / "scene_00000005"
    return scene, root / "ds", read_image_dict(scene)


def _step(value_range):
    return (float(value_range[1]) - float(value_range[0])) / 65535


def test_physical_units_equal_the_scene_files(packed):
    scene, ds, layers = packed
    ranges = json.loads((scene / "data_ranges.json").read_text())
    ex = load(ds, "train", units="physical")[0]
    for name in ("forward_flow", "backward_flow"):  # pixels, over the scene's range
        assert ex[name].dtype == np.float32 and ex[name].shape == (T, S, S, 2)
        step = _step((ranges[name]["min"], ranges[name]["max"]))
        assert np.max(np.abs(ex[name] - layers[name])) <= step / 2 + 1e-5, name
        assert np.abs(ex[name]).max() > 0.5  # things move: not all zeros
    depth = layers["depth"]
    step = _step((depth.min(), depth.max()))
    assert ex["depth"].dtype == np.float32
    assert np.max(np.abs(ex["depth"] - depth)) <= step / 2 + 1e-5  # metres
    normal = ex["normal"]
    assert normal.dtype == np.float32 and np.max(np.abs(normal - layers["normal"])) <= 1e-6
    assert np.max(np.abs(np.linalg.norm(normal, axis=-1) - 1)) < 1e-4  # unit vectors
    coords = ex["object_coordinates"]
    assert coords.dtype == np.float32 and 0 <= coords.min() and coords.max() <= 1
    assert np.max(np.abs(coords - layers["object_coordinates"])) <= 1e-6
    # RGB and labels stay as stored; the ranges are kept
    assert ex["video"].dtype == np.uint8 and np.array_equal(ex["video"], layers["rgba"][..., :3])
    assert np.array_equal(ex["segmentations"], layers["segmentation"])
    raw = load(ds, "train")[0]
    assert np.array_equal(ex["metadata"]["depth_range"], raw["metadata"]["depth_range"])


def _box_axes(corners):
    """Origin and the three edge vectors of a box from its 8 corners (x, y, z) ∈ {min, max}³."""
    c = np.asarray(corners, np.float64)
    return c[0], np.stack([c[4] - c[0], c[2] - c[0], c[1] - c[0]])


def test_physical_object_coordinates_and_flow_match_the_geometry(packed):
    """Each instance pixel's object coordinate is where its surface point (unprojected from the
    physical depth) lies in the object's box; carried by the box to the next frame and
    projected, that point is where the physical forward flow says (pixels)."""
    scene, ds, _ = packed
    meta = json.loads((scene / "metadata.json").read_text())
    ex = load(ds, "train", units="physical")[0]
    camera = meta["camera"]
    k = np.asarray(camera["intrinsics_pixels"], np.float64)
    rows, cols = np.mgrid[0:S, 0:S]
    checked = 0
    for t in range(T - 1):
        origins, dirs = pixel_rays(k, np.asarray(camera["matrices_world"][t]), S, S)
        points = origins + dirs * ex["depth"][t]
        labels = ex["segmentations"][t, ..., 0]
        for n, inst in enumerate(meta["instances"]):
            mask = labels == n + 1
            if mask.sum() < 4:
                continue
            origin, axes = _box_axes(inst["bboxes_3d"][t])
            local = np.linalg.solve(axes.T, (points[mask] - origin).T).T
            assert np.max(np.abs(local - ex["object_coordinates"][t][mask])) < 1e-3
            origin, axes = _box_axes(inst["bboxes_3d"][t + 1])
            world = origin + ex["object_coordinates"][t][mask] @ axes
            to_cam = np.linalg.inv(np.asarray(camera["matrices_world"][t + 1]))
            cam = (world @ to_cam[:3, :3].T + to_cam[:3, 3]) * (1, -1, -1)  # OpenCV axes
            pix = cam @ k.T
            col, row = pix[:, 0] / pix[:, 2], pix[:, 1] / pix[:, 2]
            flow = ex["forward_flow"][t][mask]
            assert np.max(np.abs(row - (rows[mask] + 0.5) - flow[:, 0])) < 5e-3
            assert np.max(np.abs(col - (cols[mask] + 0.5) - flow[:, 1])) < 5e-3
            checked += 1
    assert checked >= 2


def test_raw_units_are_upstream_layout_unchanged(packed):
    """The default is raw: the packed uint16 samples are the quantisation of the scene's files
    (flow over data_ranges.json's range, depth over its finite range, normals over [−1, 1],
    object coordinates over [0, 1]) — and the PNG samples as stored."""
    scene, ds, layers = packed
    ranges = json.loads((scene / "data_ranges.json").read_text())
    ex = load(ds, "train")[0]
    assert flat_equal(ex, load(ds, "train", units="raw")[0])
    for name in ("forward_flow", "backward_flow"):
        r = ranges[name]
        assert ex[name].dtype == np.uint16
        assert np.array_equal(ex[name], png_io.scale_to_uint16(layers[name], r["min"], r["max"]))
        assert np.array_equal(ex[name][1], png_io.read_png(scene / f"{name}_00001.png")[..., :2])
    depth = layers["depth"]
    assert np.array_equal(ex["depth"], png_io.scale_to_uint16(depth, depth.min(), depth.max()))
    assert np.array_equal(ex["normal"], png_io.scale_to_uint16(layers["normal"], -1, 1))
    assert np.array_equal(ex["normal"][2], png_io.read_png(scene / "normal_00002.png"))
    assert np.array_equal(ex["object_coordinates"],
                          png_io.scale_to_uint16(layers["object_coordinates"], 0, 1))


def flat_equal(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(flat_equal(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(flat_equal(x, y) for x, y in zip(a, b, strict=True))
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and np.array_equal(a, b)


def test_physical_units_behind_tasks_and_adapters(packed, tmp_path):
    _, ds, layers = packed
    from kubric.datasets.task_registry import TASKS, register_task

    @register_task("test_flow_only", features=("forward_flow",))
    def flow_only(example, frame):
        return example["forward_flow"]
    try:  # a task reading only the flow still gets pixels: its range is decoded with it
        flow = load(ds, "train", task="test_flow_only", units="physical")[0]
        assert flow.dtype == np.float32 and np.allclose(flow, layers["forward_flow"], atol=1e-2)
        assert load(ds, "train", task="test_flow_only")[0].dtype == np.uint16
    finally:
        del TASKS["test_flow_only"]
    rays = load(ds, "train", task="nerf_rays", units="physical")[1]
    assert np.allclose(rays["depth"], load(ds, "train", task="nerf_rays")[1]["depth"])
    item = to_grain(load(ds, "train", units="physical"))[0]
    assert item["normal"].dtype == np.float32
    with pytest.raises(DatasetError, match=r"units 'metric' is not one of \('raw', 'physical'\)"):
        load(ds, "train", units="metric")
