"""MOVi-A end to end at tiny settings (must-show of the recipes issue).

Three worker processes: seed 1 twice (determinism) and seed 2 (a different scene). Checks every
file and field of the output contract, flow / depth against the object poses, boxes against the
labels.
"""

import concurrent.futures
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric import file_io
from kubric.core.camera_geometry import CAMERA_TO_OPENCV

pytestmark = pytest.mark.blender

ROOT = pathlib.Path(__file__).resolve().parents[1]
OPTIONS = ["resolution=48x32", "frame_end=4", "samples=4", "denoise=false",
           "min_num_objects=4", "max_num_objects=5"]
T, W, H = 4, 48, 32
#: MOVi-E (moving camera, settled static objects), small mesh collection
E_OPTIONS = ["resolution=48x32", "frame_end=4", "samples=2", "denoise=false",
             "min_num_objects=3", "max_num_objects=4", "settle_frames=20", "collection_limit=8"]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("movi")
    from kubric.pipeline import get_recipe
    get_recipe("movi_a").from_assignments(OPTIONS).prepare()  # build assets once
    get_recipe("movi_e").from_assignments(E_OPTIONS).prepare()
    jobs = [("movi_a", "a", 1, OPTIONS), ("movi_a", "b", 1, OPTIONS),
            ("movi_a", "a", 2, OPTIONS), ("movi_e", "e", 1, E_OPTIONS)]

    def run(job):
        recipe, out, seed, options = job
        cmd = [sys.executable, "-m", "kubric", "worker", recipe, "--seed", str(seed),
               "--out", str(root / out)]
        for o in options:
            cmd += ["--set", o]
        return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)

    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        for proc in pool.map(run, jobs):
            assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return root


def _read(scene):
    return (file_io.read_json(scene / "metadata.json"), file_io.read_json(scene / "events.json"),
            file_io.read_image_dict(scene))


def test_files_fields_shapes_and_dtypes(scenes):
    scene = scenes / "a" / "scene_00000001"
    assert (scene / "_SUCCESS").exists()
    for name in ("rgba", "depth", "segmentation", "forward_flow", "backward_flow", "normal",
                 "object_coordinates"):
        ext = "tiff" if name == "depth" else "png"
        assert sorted(p.name for p in scene.glob(f"{name}_*.{ext}")) == \
            [f"{name}_{i:05d}.{ext}" for i in range(T)], name
    meta, events, layers = _read(scene)
    ranges = file_io.read_json(scene / "data_ranges.json")
    assert {"forward_flow", "backward_flow"} <= set(ranges)
    expect = {"rgba": (4, np.uint8), "depth": (1, np.float32), "segmentation": (1, np.uint32),
              "forward_flow": (2, np.float32), "backward_flow": (2, np.float32),
              "normal": (3, np.float32), "object_coordinates": (3, np.float32)}
    for name, (c, dtype) in expect.items():
        assert layers[name].shape == (T, H, W, c) and layers[name].dtype == dtype, name
    assert meta["flags"]["seed"] == 1 and meta["flags"]["recipe"] == "movi_a"
    m = meta["metadata"]
    assert m["resolution"] == [W, H] and m["num_frames"] == T and m["seed"] == 1
    assert m["frame_rate"] == 12 and m["step_rate"] == 240
    assert m["renderer"]["view_transform"] == "Standard" and m["renderer"]["samples_per_pixel"] == 4
    for key in ("gravity", "background", "num_instances", "versions"):
        assert key in m, key
    cam = meta["camera"]
    assert cam["focal_length"] == 35 and cam["sensor_width"] == 32
    assert np.shape(cam["positions"]) == (T, 3) and np.shape(cam["quaternions"]) == (T, 4)
    assert np.shape(cam["K"]) == (3, 3) and np.shape(cam["R"]) == (4, 4)
    assert np.shape(cam["matrices_world"]) == (T, 4, 4)
    assert np.shape(cam["intrinsics_pixels"]) == (3, 3) and "conventions" in cam
    assert cam["field_of_view"] == pytest.approx(2 * np.arctan(16 / 35))
    insts = meta["instances"]
    assert len(insts) == m["num_instances"] >= 1
    totals = [int(np.sum(i["visibility"])) for i in insts]
    assert totals == sorted(totals, reverse=True) and totals[-1] > 0
    labels = layers["segmentation"][..., 0]
    assert labels.max() == len(insts)
    for k, inst in enumerate(insts, start=1):
        for key, shape in (("positions", (T, 3)), ("quaternions", (T, 4)),
                           ("velocities", (T, 3)), ("angular_velocities", (T, 3)),
                           ("image_positions", (T, 2)), ("bboxes_3d", (T, 8, 3)),
                           ("visibility", (T,))):
            assert np.shape(inst[key]) == shape, key
        for key in ("asset_id", "mass", "friction", "restitution", "shape", "size",
                    "size_label", "material", "color", "color_label"):
            assert key in inst, key
        assert inst["shape"] in ("cube", "cylinder", "sphere")
        assert inst["size"] in (0.7, 1.4) and inst["material"] in ("metal", "rubber")
        np.testing.assert_array_equal(inst["visibility"],
                                      [(labels[t] == k).sum() for t in range(T)])
        # bboxes contain every labelled pixel of their instance
        assert len(inst["bboxes"]) == len(inst["bbox_frames"])
        for box, t in zip(inst["bboxes"], inst["bbox_frames"], strict=True):
            ys, xs = np.nonzero(labels[t] == k)
            ymin, xmin, ymax, xmax = box
            assert ys.min() / H >= ymin - 1e-6 and (ys.max() + 1) / H <= ymax + 1e-6
            assert xs.min() / W >= xmin - 1e-6 and (xs.max() + 1) / W <= xmax + 1e-6
    for c in events["collisions"]:
        assert set(c) >= {"instances", "frame", "force", "position", "contact_normal",
                          "image_position"}
        assert all(-1 <= i < len(insts) for i in c["instances"])


def _world_from_object_coords(inst, t, oc):
    """Surface points from object coordinates in [0,1]³ and the pose at frame t (bboxes_3d)."""
    c = np.asarray(inst["bboxes_3d"][t], dtype=np.float64)
    return c[0] + oc[:, :1] * (c[4] - c[0]) + oc[:, 1:2] * (c[2] - c[0]) + \
        oc[:, 2:3] * (c[1] - c[0])


def _project(cam, t, points):
    m = np.linalg.inv(np.asarray(cam["matrices_world"][t], dtype=np.float64))
    p = (points @ m[:3, :3].T + m[:3, 3]) @ CAMERA_TO_OPENCV.T
    xy = p @ np.asarray(cam["intrinsics_pixels"], dtype=np.float64).T
    return xy[:, :2] / xy[:, 2:], np.linalg.norm(points - np.asarray(cam["positions"][t]), axis=1)


@pytest.mark.parametrize("scene", ["a/scene_00000001", "e/scene_00000001"])
def test_flow_and_depth_agree_with_object_poses(scenes, scene):
    meta, _, layers = _read(scenes / scene)
    cam, insts = meta["camera"], meta["instances"]
    labels = layers["segmentation"][..., 0]
    moving_camera = np.ptp(np.asarray(cam["positions"]), axis=0).max() > 1e-3
    assert moving_camera == scene.startswith("e")
    checked = 0
    for t in range(T - 1):
        for k, inst in enumerate(insts, start=1):
            mask = labels[t] == k
            interior = mask.copy()  # away from label edges
            interior[1:-1, 1:-1] &= mask[:-2, 1:-1] & mask[2:, 1:-1] & mask[1:-1, :-2] & \
                mask[1:-1, 2:]
            rows, cols = np.nonzero(interior)
            if rows.size == 0:
                continue
            oc = layers["object_coordinates"][t, rows, cols].astype(np.float64)
            here = _world_from_object_coords(inst, t, oc)
            xy_t, dist_t = _project(cam, t, here)
            centres = np.stack([cols + 0.5, rows + 0.5], axis=1)
            np.testing.assert_allclose(xy_t, centres, atol=0.05)
            np.testing.assert_allclose(layers["depth"][t, rows, cols, 0], dist_t, rtol=1e-3)
            xy_next, _ = _project(cam, t + 1, _world_from_object_coords(inst, t + 1, oc))
            flow = layers["forward_flow"][t, rows, cols].astype(np.float64)  # (drow, dcol)
            followed = centres + flow[:, ::-1]
            err = np.abs(followed - xy_next).max()
            assert err < 0.1, (t, k, err)
            checked += rows.size
    assert checked > 20


def test_same_seed_same_scene_other_seed_differs(scenes):
    a, b = scenes / "a" / "scene_00000001", scenes / "b" / "scene_00000001"
    for name in ("metadata.json", "events.json"):
        assert (a / name).read_text() == (b / name).read_text(), name
    rgb_a = file_io.read_layer(a, "rgba").astype(np.int32)
    rgb_b = file_io.read_layer(b, "rgba").astype(np.int32)
    assert np.abs(rgb_a - rgb_b).mean() < 1.0
    np.testing.assert_array_equal(file_io.read_segmentation(a), file_io.read_segmentation(b))
    other = json.loads((scenes / "a" / "scene_00000002" / "metadata.json").read_text())
    assert other["flags"]["seed"] == 2
    assert other["camera"]["positions"] != json.loads((a / "metadata.json").read_text())[
        "camera"]["positions"]


def test_inspect_real_scene(scenes):
    scene = scenes / "e" / "scene_00000001"
    proc = subprocess.run([sys.executable, "-m", "kubric", "inspect", str(scene), "--sheet",
                           str(scenes / "sheet.gif")], cwd=ROOT, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert f"frames: {T} (1..{T})" in proc.stdout and "instances:" in proc.stdout
    from PIL import Image
    sheet = Image.open(scenes / "sheet.gif")
    from kubric.pipeline.inspect import GUTTER, HEADER, tile_scale
    k = tile_scale(W)  # labelled: names above, frame indices beside, small tiles enlarged
    assert sheet.n_frames == T and sheet.size == (GUTTER + 5 * W * k, HEADER + H * k)


def test_every_written_file_and_field_is_documented(scenes):
    from kubric import docgen
    for scene in (scenes / "a" / "scene_00000001", scenes / "e" / "scene_00000001"):
        assert docgen.undocumented_scene_fields(scene) == [], scene


def test_movi_e_scene_packs_under_its_schema(scenes):
    """The C–F schema reads a real MOVi-E scene and TFDS serialises the example."""
    from kubric.datasets import tfds_io
    from kubric.io.scene_reader import SceneReader
    from kubric.pipeline.recipe import schema_of as get_schema
    schema = get_schema("movi_e")
    reader = SceneReader(scenes / "e" / "scene_00000001", schema)
    example = reader.example()
    meta = file_io.read_json(scenes / "e" / "scene_00000001" / "metadata.json")
    assert example["background"] == meta["metadata"]["background"]
    assert example["instances/is_dynamic"].dtype == np.bool_
    assert list(example["instances/is_dynamic"]) == [i["is_dynamic"] for i in meta["instances"]]
    assert example["camera/matrices_world"].shape == (T, 4, 4)
    features = tfds_io.tfds_features(schema, reader.dims)
    assert len(tfds_io.serialize(features, tfds_io.nested_example(schema, example))) > 1000
