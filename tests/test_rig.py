"""Camera rigs on real output: a tiny stereo MOVi-A scene rendered by the raycast backend (bpy
blocked), read back from its scene directory and checked independently of the rig code:

* disparity = f·B / Z at every hit pixel (relative error < 1e-4), with Z the z-depth derived
  here from the raycast depth layer (distance along OpenCV's pixel ray) and B the distance
  between the two camera centres of metadata.json; 0 on the background;
* the right camera's tracks are the left tracks' surface points: ``cv2.projectPoints`` with the
  left camera's extrinsics composed with the rig's mount lands on the written right positions
  (< 1e-3 px), and where a right track is visible the right segmentation shows its instance;
* the packed dataset round trip: the per-camera features equal the scene's files, the stereo
  task gives left, right and disparity, multicamera_video a camera axis;
* the rig model (mounts, ring geometry) and the one-line refusals.
"""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import kubric as kb
from kubric import file_io
from kubric.annotations.track_files import read_tracks
from kubric.core import camera_geometry as geo
from kubric.core import rig as rigs
from kubric.pipeline import OptionError, get_recipe

cv2 = pytest.importorskip("cv2")

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
W, H, BASELINE = 32, 24, 0.4
TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def _worker(root, seed, *options):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", str(seed), "--out",
           str(root), "--set", "renderer=raycast", "--set", f"resolution={W}x{H}"]
    for o in options:
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return root / f"scene_{seed:08d}"


@pytest.fixture(scope="module")
def stereo(tmp_path_factory):
    root = tmp_path_factory.mktemp("stereo")
    scene = _worker(root, 5, "frame_end=3", "cameras=stereo", f"baseline={BASELINE}",
                    "max_num_objects=5", "tracks=120", "track_stride=2",
                    "track_max_fraction=0.5")
    meta = json.loads((scene / "metadata.json").read_text())
    return root, scene, meta, file_io.read_image_dict(scene)


def _right_layers(scene):
    from kubric.io.stored_schema import stored_schema
    formats = stored_schema(scene).layers
    return {name[len("right_"):]: file_io.read_layer(scene, name, formats=formats)
            for name in formats if name.startswith("right_")}


def test_disparity_is_f_b_over_z(stereo):
    _, _, meta, layers = stereo
    cam, right = meta["camera"], meta["camera"]["rig"]["views"]["right"]
    k = np.asarray(cam["intrinsics_pixels"])
    baseline = np.linalg.norm(np.asarray(cam["positions"]) - np.asarray(right["positions"]),
                              axis=1)
    assert np.allclose(baseline, BASELINE, rtol=1e-5)
    xs, ys = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    ray = np.stack([(xs - k[0, 2]) / k[0, 0], (ys - k[1, 2]) / k[1, 1], np.ones_like(xs)], -1)
    depth, disparity = layers["depth"][..., 0], layers["disparity"][..., 0]
    hit = depth < geo.BACKGROUND_DEPTH * 0.999
    z = depth / np.linalg.norm(ray, axis=-1)
    expected = k[0, 0] * baseline[:, None, None] / z
    assert hit.mean() > 0.5 and np.all(disparity[~hit] == 0)
    rel = np.abs(disparity[hit] - expected[hit]) / expected[hit]
    assert rel.max() < 1e-4, rel.max()


def test_right_tracks_are_the_left_points_through_the_mount(stereo):
    _, scene, meta, _ = stereo
    left, right = read_tracks(scene), dict(np.load(scene / "tracks_right.npz"))
    assert np.array_equal(left["points_world"], right["points_world"])
    mount = np.asarray(meta["camera"]["rig"]["mounts"]["right"])  # camera → rig, Blender axes
    mount_cv = TO_CV @ mount @ TO_CV
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    for t in range(len(left["frames"])):
        ext_left = np.asarray(meta["camera"]["extrinsics_opencv"][t])
        ext_right = np.linalg.inv(mount_cv) @ ext_left
        rvec = cv2.Rodrigues(ext_right[:3, :3])[0]
        xy = cv2.projectPoints(left["points_world"][:, t].astype(np.float64), rvec,
                               ext_right[:3, 3], k, np.zeros(5))[0][:, 0]
        assert np.abs(xy - right["target_points"][:, t]).max() < 1e-3
    # where a right track is seen, the right camera's relabelled segmentation shows its instance
    seg = _right_layers(scene)["segmentation"][..., 0]
    seen = ~right["occluded"]
    assert seen.mean() > 0.3 and (right["occluded"] != left["occluded"]).any()
    n, t = np.nonzero(seen)
    x, y = right["target_points"][n, t].T
    labels = seg[t, np.floor(y).astype(int), np.floor(x).astype(int)]
    assert np.mean(labels == right["instance_id"][n]) > 0.95


def test_right_camera_metadata_is_the_mounted_camera(stereo):
    _, scene, meta, _ = stereo
    rig = meta["camera"]["rig"]
    assert rig["kind"] == "stereo" and rig["cameras"] == ["left", "right"]
    left, right = np.asarray(meta["camera"]["matrices_world"]), \
        np.asarray(rig["views"]["right"]["matrices_world"])
    assert np.allclose(np.linalg.inv(left) @ right, np.asarray(rig["mounts"]["right"]),
                       atol=1e-5)
    for inst in meta["instances"]:
        view = inst["cameras"]["right"]
        assert len(view["visibility"]) == meta["metadata"]["num_frames"]
        assert len(view["bboxes"]) == len(view["bbox_frames"])
    total = [sum(i["visibility"]) + sum(i["cameras"]["right"]["visibility"])
             for i in meta["instances"]]
    assert total == sorted(total, reverse=True)


def test_pack_round_trip_per_camera(stereo, tmp_path):
    from kubric.datasets import load, pack
    root, scene, _, layers = stereo
    pack(root, tmp_path / "ds", splits={"train": 1})
    example = load(tmp_path / "ds", "train")[0]
    right = _right_layers(scene)
    assert np.array_equal(example["cameras"]["right"]["video"], right["rgba"][..., :3])
    assert np.array_equal(example["cameras"]["right"]["segmentations"], right["segmentation"])
    assert np.array_equal(example["disparity"], layers["disparity"])
    item = load(tmp_path / "ds", "train", task="stereo")[1]
    assert np.array_equal(item["left"], layers["rgba"][1, ..., :3])
    assert np.array_equal(item["right"], right["rgba"][1, ..., :3])
    assert np.array_equal(item["disparity"], layers["disparity"][1, ..., 0])
    assert np.isclose(item["baseline"], BASELINE)
    video = load(tmp_path / "ds", "train", task="multicamera_video")[0]
    assert video["video"].shape == (2, 3, H, W, 3) and video["camera_names"] == ["left", "right"]
    assert np.array_equal(video["video"][1], example["cameras"]["right"]["video"])
    rig = example["camera"]["rig"]
    assert np.allclose(rig["extrinsics_opencv"][1],
                       example["cameras"]["right"]["camera"]["extrinsics_opencv"])
    assert np.allclose(rig["matrices_world"][0] @ rig["mounts"][1], rig["matrices_world"][1],
                       atol=1e-5)


def test_ring_rig_geometry():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=2)
    camera = kb.PerspectiveCamera(position=(0, -6, 3), look_at=(0, 0, 0))
    scene.camera = camera
    rig = rigs.ring(camera, 4, float(np.linalg.norm((0, -6, 3))), frame=1)
    cams = rig.build(scene)
    assert scene.camera is camera and list(cams) == ["cam0", "cam1", "cam2", "cam3"]
    for c in cams.values():  # each on the circle, looking at the origin
        m = geo.camera_to_world(c, 2)
        assert np.isclose(np.linalg.norm(m[:2, 3]), 6) and np.isclose(m[2, 3], 3)
        xy, _ = geo.project_to_pixels(c, np.zeros(3), 2)
        assert np.allclose(xy, (W / 2, H / 2), atol=1e-6)
    assert np.allclose(geo.camera_to_world(cams["cam2"], 1)[:2, 3], (0, 6), atol=1e-5)


def test_moving_rig_keeps_its_mount():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3)
    camera = kb.PerspectiveCamera()
    for f in range(0, 5):
        camera.position = (0.5 * f, -6, 3)
        camera.look_at((0, 0, 0))
        camera.keyframe_insert("position", f)
        camera.keyframe_insert("quaternion", f)
    scene.camera = camera
    cams = rigs.stereo(camera, 0.3).build(scene)
    for f in range(0, 5):
        rel = np.linalg.inv(geo.camera_to_world(camera, f)) @ geo.camera_to_world(
            cams["right"], f)
        assert np.allclose(rel, rigs.translation(0.3), atol=1e-6)


@pytest.mark.parametrize("options, text", [
    ({"cameras": "stereo", "lens": "opencv"}, "lens=opencv"),
    ({"cameras": "stereo", "rolling_shutter": 0.5, "renderer": "raycast"}, "rolling_shutter"),
    ({"cameras": "ring", "rolling_shutter": 0.5, "renderer": "raycast"},
     "cameras=ring does not combine with rolling_shutter=0.5"),
    ({"cameras": "trio"}, "trio"),
])
def test_refusals(options, text):
    with pytest.raises(OptionError, match=text):
        get_recipe("movi_a")(**options).check()


def test_coverage_samples_are_refused_with_a_rig():
    with pytest.raises(OptionError, match="cameras=stereo does not combine with "
                                          "coverage_samples=4"):
        get_recipe("movi_f")(cameras="stereo", coverage_samples=4).check()


def test_bad_rigs():
    camera = kb.PerspectiveCamera()
    with pytest.raises(ValueError, match="baseline"):
        rigs.stereo(camera, 0.0)
    with pytest.raises(ValueError, match="rigid"):
        rigs.CameraRig(camera, {"b": np.diag([1.0, 1.0, -1.0, 1.0])})
    with pytest.raises(ValueError, match="distinct"):
        rigs.CameraRig(camera, {"Right": np.eye(4)})


@pytest.mark.blender
def test_blender_renders_each_camera_as_the_raycast_oracle(stereo, tmp_path):
    """The same stereo scene with the blender backend (it renders each camera by swapping the
    active camera): the right camera's exact layers and the disparity equal raycast's."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "5", "--out",
           str(tmp_path)]
    for o in (f"resolution={W}x{H}", "frame_end=3", "cameras=stereo", f"baseline={BASELINE}",
              "max_num_objects=5", "renderer=blender", "samples=2", "denoise=false"):
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    _, scene, _, layers = stereo
    blender = tmp_path / "scene_00000005"
    mine, oracle = _right_layers(blender), _right_layers(scene)
    assert np.allclose(mine["depth"], oracle["depth"], rtol=1e-5)
    assert np.array_equal(mine["segmentation"], oracle["segmentation"])
    assert np.allclose(file_io.read_layer(blender, "disparity"), layers["disparity"],
                       rtol=1e-4, atol=1e-5)
    assert np.abs(mine["rgba"].astype(int) - file_io.read_layer(blender, "rgba")).mean() > 1


def test_ring_scene_every_camera_every_layer(tmp_path):
    """movi_a cameras=ring through a fisheye lens: three cameras around the origin (MOVi-A's
    camera looks at it), each with its own exact and opt-in layers; each camera's visible
    segmentation lies inside its amodal masks, the origin projects to every camera's image
    centre, and cv2.fisheye.projectPoints of the tracks' points with each camera's recorded
    extrinsics gives its written track positions (< 1e-3 px)."""
    from kubric.io.bitmask import unpack_masks
    from kubric.io.stored_schema import stored_schema
    scene = _worker(tmp_path, 2, "frame_end=2", "cameras=ring", "num_cameras=3",
                    "max_num_objects=4", "extra_layers=amodal,scene_flow_camera",
                    "lens=fisheye", "lens_coefficients=0.2,-0.05,0.01,-0.002", "tracks=40",
                    "track_stride=2", "track_max_fraction=0.5")
    meta = json.loads((scene / "metadata.json").read_text())
    rig = meta["camera"]["rig"]
    assert rig["cameras"] == ["cam0", "cam1", "cam2"]
    formats = stored_schema(scene).layers
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    n = len(meta["instances"])
    for name in rig["cameras"]:
        cam = meta["camera"] if name == "cam0" else rig["views"][name]
        ext = np.asarray(cam["extrinsics_opencv"])
        centre = k @ ext[:, :3, 3].T  # the origin in each frame's OpenCV camera
        assert np.allclose((centre[:2] / centre[2]).T, (W / 2, H / 2), atol=1e-3)
        prefix = "" if name == "cam0" else f"{name}_"
        seg = file_io.read_layer(scene, f"{prefix}segmentation", formats=formats)[..., 0]
        assert seg.max() > 0
        amodal = unpack_masks(file_io.read_layer(scene, f"{prefix}amodal_segmentation",
                                                 formats=formats, raw=True), n)
        for label in range(1, n + 1):
            assert not np.any((seg == label) & ~amodal[:, label - 1])
            inst = meta["instances"][label - 1]
            own = inst if name == "cam0" else inst["cameras"][name]
            assert own["amodal_area"] == amodal[:, label - 1].sum(axis=(1, 2)).tolist()
        assert file_io.read_layer(scene, f"{prefix}forward_scene_flow_camera",
                                  formats=formats).shape == (2, H, W, 3)
        # each camera's tracks: the reference's points through OpenCV's own fisheye model
        tracks = read_tracks(scene) if name == "cam0" else dict(np.load(scene /
                                                                         f"tracks_{name}.npz"))
        coeffs = np.asarray(cam["distortion_coefficients"])[:4]
        for t in range(2):
            points = tracks["points_world"][:, t].astype(np.float64)[:, None]
            rvec = cv2.Rodrigues(ext[t, :3, :3])[0]
            xy = cv2.fisheye.projectPoints(points, rvec, ext[t, :3, 3], k, coeffs)[0][:, 0]
            front = tracks["occlusion_reason"][:, t] & 1 == 0
            assert front.sum() > 10
            assert np.abs(xy[front] - tracks["target_points"][front, t]).max() < 1e-3
    distances = [np.linalg.norm(np.asarray(v["positions"])[0]) for v in rig["views"].values()]
    assert np.allclose(distances, np.linalg.norm(meta["camera"]["positions"][0]), rtol=1e-5)
    # kubric export coco: camera cam2's KINS amodal masks are its own amodal layer's, and its
    # images carry its fisheye coefficients
    from pycocotools import mask as mask_utils

    from kubric.datasets.exports import exporter
    exporter("coco")(scene, tmp_path / "coco.json", progress=False)
    coco = json.loads((tmp_path / "coco.json").read_text())
    amodal = unpack_masks(file_io.read_layer(scene, "cam2_amodal_segmentation", formats=formats,
                                             raw=True), n)
    images = {i["id"]: i for i in coco["images"] if i["camera"] == "cam2"}
    assert len(images) == 2 and all(np.allclose(i["distortion_coefficients"],
                                                rig["views"]["cam2"]["distortion_coefficients"])
                                    for i in images.values())
    anns = [a for a in coco["annotations"] if a["image_id"] in images]
    assert anns
    for a in anns:
        mask = mask_utils.decode(a["a_segm"]).astype(bool)
        assert np.array_equal(mask, amodal[images[a["image_id"]]["frame"], a["instance"]])


@pytest.mark.blender
def test_pose_estimation_keypoints_per_camera(tmp_path):
    """pose_estimation cameras=stereo: each person's right-camera keypoints are OpenCV's
    projection of the same 3D keypoints with the right camera's recorded extrinsics."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "kubric", "worker", "pose_estimation", "--seed", "3", "--out",
           str(tmp_path)]
    for o in ("resolution=32", "frame_end=2", "quality=draft", "character_source=procedural",
              "motion_source=procedural", "cameras=stereo", "baseline=0.15",
              "max_num_people=2"):  # baseline: both cameras see the person at 32 px
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    meta = json.loads((tmp_path / "scene_00000003" / "metadata.json").read_text())
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    right = meta["camera"]["rig"]["views"]["right"]
    people = [i for i in meta["instances"] if "keypoints_3d" in i]
    assert people
    for person in people:
        for t, points in enumerate(np.asarray(person["keypoints_3d"], np.float64)):
            ext = np.asarray(right["extrinsics_opencv"][t])
            xy = cv2.projectPoints(points, cv2.Rodrigues(ext[:3, :3])[0], ext[:3, 3], k,
                                   np.zeros(5))[0][:, 0]
            mine = np.asarray(person["cameras"]["right"]["keypoints_2d"][t])
            assert np.abs(xy - mine).max() < 1e-3
            assert np.abs(mine - np.asarray(person["keypoints_2d"][t])).max() > 0.1
    # kubric export coco: the right camera's images carry the right camera's keypoints
    from kubric.datasets.exports import exporter
    exporter("coco")(tmp_path / "scene_00000003", tmp_path / "coco.json", progress=False)
    coco = json.loads((tmp_path / "coco.json").read_text())
    right_images = {i["id"]: i["frame"] for i in coco["images"] if i["camera"] == "right"}
    checked = 0
    for ann in coco["annotations"]:
        if ann["image_id"] not in right_images or "keypoints" not in ann:
            continue
        t, own = right_images[ann["image_id"]], meta["instances"][ann["instance"]]
        own = own["cameras"]["right"]
        kp, vis = np.reshape(ann["keypoints"], (-1, 3)), np.asarray(own["keypoints_visibility"][t])
        assert np.array_equal(kp[:, 2], vis)
        xy = np.asarray(own["keypoints_2d"][t]) - 0.5
        assert np.abs(kp[vis > 0, :2] - xy[vis > 0]).max() <= 5e-4
        checked += 1
    assert checked


@pytest.mark.blender
def test_movi_f_stereo_with_motion_blur(tmp_path):
    """MOVi-F (mesh objects, HDRI dome, a moving camera, motion blur) with cameras=stereo: both
    cameras path traced with the shutter, the disparity = f·B / z of Blender's own z layer."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_f", "--seed", "2", "--out",
           str(tmp_path)]
    for o in (f"resolution={W}x{H}", "frame_end=2", "collection_limit=8", "samples=2",
              "denoise=false", "min_num_objects=2", "max_num_objects=3", "settle_frames=5",
              "cameras=stereo", f"baseline={BASELINE}"):
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene = tmp_path / "scene_00000002"
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["metadata"]["motion_blur"] > 0
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    z, disparity = file_io.read_layer(scene, "z"), file_io.read_layer(scene, "disparity")
    hit = z < geo.BACKGROUND_DEPTH * 0.999
    expected = k[0, 0] * BASELINE / z[hit]
    assert hit.mean() > 0.5 and np.abs(disparity[hit] - expected).max() / expected.min() < 1e-4
    right = _right_layers(scene)["rgba"]
    assert right[..., 3].min() == 255
    assert np.abs(right.astype(int) - file_io.read_layer(scene, "rgba")).mean() > 1


def test_tapvid_export_has_every_camera(stereo, tmp_path):
    import pickle

    from kubric.datasets.exports import exporter
    root, scene, _, layers = stereo
    exporter("tapvid")(root, tmp_path / "tracks.pkl")
    data = pickle.loads((tmp_path / "tracks.pkl").read_bytes())
    assert sorted(data) == [scene.name, f"{scene.name}:right"]
    right = dict(np.load(scene / "tracks_right.npz"))
    entry = data[f"{scene.name}:right"]
    assert np.array_equal(entry["target_points"], right["target_points"])
    assert np.array_equal(entry["occluded"], right["occluded"])
    assert np.array_equal(entry["video"], _right_layers(scene)["rgba"][..., :3])


def test_random_rig_geometry():
    """random_rig: each camera within its distance and elevation bands about the pivot (the
    point the reference looks at), looking at it upright; the same rng state, the same rig."""
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=2)
    camera = kb.PerspectiveCamera(position=(1, -6, 3), look_at=(0, 0, 0.5))
    scene.camera = camera
    d = float(np.linalg.norm(np.subtract((1, -6, 3), (0, 0, 0.5))))
    rig = rigs.random_rig(camera, 6, d, np.random.RandomState(7), frame=1)
    cams = rig.build(scene)
    assert list(cams) == [f"cam{k}" for k in range(6)] and rig.kind == "random"
    lo, hi = np.radians(rigs.RANDOM_ELEVATION)
    for c in list(cams.values())[1:]:
        m = geo.camera_to_world(c, 1)
        offset = m[:3, 3] - (0, 0, 0.5)
        r = np.linalg.norm(offset)
        assert rigs.RANDOM_DISTANCE[0] * d <= r <= rigs.RANDOM_DISTANCE[1] * d
        assert lo <= np.arcsin(offset[2] / r) <= hi
        xy, _ = geo.project_to_pixels(c, np.array([0, 0, 0.5]), 1)
        assert np.allclose(xy, (W / 2, H / 2), atol=1e-6)
        assert abs(m[2, 0]) < 1e-6  # its x axis horizontal: upright
    again = rigs.random_rig(camera, 6, d, np.random.RandomState(7), frame=1)
    other = rigs.random_rig(camera, 6, d, np.random.RandomState(8), frame=1)
    assert all(np.array_equal(again.mounts[k], rig.mounts[k]) for k in rig.names)
    assert not np.allclose(other.mounts["cam1"], rig.mounts["cam1"])


def test_random_rig_scene_keeps_the_mono_scene(tmp_path):
    """movi_a cameras=random: the rig's draws leave the mono scene of the seed as it was (same
    reference camera and object trajectories), and every further camera looks at the origin."""
    options = ("frame_end=2", "max_num_objects=3")
    mono = json.loads((_worker(tmp_path / "mono", 4, *options) / "metadata.json").read_text())
    scene = _worker(tmp_path / "rig", 4, *options, "cameras=random", "num_cameras=3")
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["camera"]["rig"]["kind"] == "random"
    assert np.array_equal(meta["camera"]["matrices_world"], mono["camera"]["matrices_world"])
    assert sorted(map(json.dumps, (i["positions"] for i in meta["instances"]))) == \
        sorted(map(json.dumps, (i["positions"] for i in mono["instances"])))
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    for name in ("cam1", "cam2"):
        view = meta["camera"]["rig"]["views"][name]
        ext = np.asarray(view["extrinsics_opencv"])
        centre = k @ ext[:, :3, 3].T  # the origin in each frame's OpenCV camera
        assert np.allclose((centre[:2] / centre[2]).T, (W / 2, H / 2), atol=1e-3)
        assert not np.allclose(view["matrices_world"], meta["camera"]["matrices_world"])
    assert (scene / "cam2_rgba_00000.png").is_file()
