"""The pose_estimation recipe with the procedural person (no humans source needed)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from kubric.file_io import read_palette_png
from tests.collection_fixtures import run_worker

PROCEDURAL = ["character_source=procedural", "motion_source=procedural"]


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("pose")
    run_worker("pose_estimation", 3, out, ["resolution=64", "frame_end=3", "quality=draft",
                                           "tracks=48", "track_max_fraction=0.5",
                                           "max_num_people=2", *PROCEDURAL])
    return out / "scene_00000003"


@pytest.mark.blender
def test_scene_fields_are_documented(scene_dir):
    from kubric.docgen import undocumented_scene_fields
    assert undocumented_scene_fields(scene_dir) == []


@pytest.mark.blender
def test_keypoints_reproject_and_agree_with_segmentation_and_boxes(scene_dir):
    meta = json.loads((scene_dir / "metadata.json").read_text())
    cam = meta["camera"]
    k = np.asarray(cam["intrinsics_pixels"])
    people = meta["instances"]
    assert 1 <= len(people) <= 2 and all(p["character_id"] == "tube_person" for p in people)
    w, h = meta["metadata"]["resolution"]
    checked = 0
    for label, person in enumerate(people, start=1):
        kp3 = np.asarray(person["keypoints_3d"])
        kp2 = np.asarray(person["keypoints_2d"])
        vis = np.asarray(person["keypoints_visibility"])
        assert kp3.shape == (3, 17, 3) and vis.shape == (3, 17)
        assert person["keypoint_names"][0] == "nose" and len(person["keypoint_skeleton"]) == 19
        boxes = dict(zip(person["bbox_frames"], person["bboxes"], strict=True))
        for t, m in enumerate(np.asarray(cam["matrices_world"])):
            c = (kp3[t] - m[:3, 3]) @ m[:3, :3]
            p = np.stack([c[:, 0], -c[:, 1], -c[:, 2]], -1) @ k.T
            np.testing.assert_allclose(p[:, :2] / p[:, 2:], kp2[t], atol=1e-3)
            seg = read_palette_png(scene_dir / f"segmentation_{t:05d}.png")[..., 0]
            for j in np.flatnonzero(vis[t] == 2):
                x, y = kp2[t, j]
                assert seg[int(y), int(x)] == label       # visible: the pixel shows the person
                ymin, xmin, ymax, xmax = boxes[t]
                assert xmin * w - 1 <= x <= xmax * w + 1 and ymin * h - 1 <= y <= ymax * h + 1
                checked += 1
    assert checked > 10


@pytest.mark.blender
def test_tracks_follow_the_people(scene_dir):
    tracks = np.load(scene_dir / "tracks.npz")
    assert tracks["target_points"].shape == (48, 3, 2)
    assert (tracks["instance_id"] > 0).sum() >= 1


def test_a_bad_character_source_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "kubric", "worker", "pose_estimation",
                           "--seed", "0", "--out", str(tmp_path), "--set",
                           "character_source=/no/such/folder"], capture_output=True, text=True)
    assert proc.returncode != 0
    lines = [ln for ln in proc.stderr.strip().splitlines() if "character_source" in ln]
    assert lines and "procedural" in lines[-1] and "Traceback" not in proc.stderr


@pytest.mark.blender
def test_the_scene_packs_with_keypoints(scene_dir, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "kubric", "pack", str(scene_dir.parent),
                           "--out", str(tmp_path / "ds"), "--schema", "pose_estimation_tracks",
                           "--verify", "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "every example equals its scene directory" in proc.stdout + proc.stderr
    features = json.loads((tmp_path / "ds" / "features.json").read_text())
    assert '"keypoints_2d"' in json.dumps(features) and '"keypoints_visibility"' in json.dumps(features)


@pytest.mark.blender
def test_coco_export_has_person_keypoints(scene_dir, tmp_path):
    """pycocotools reads the export; masks, boxes and keypoints agree with the scene."""
    pytest.importorskip("pycocotools")
    from pycocotools.coco import COCO
    out = tmp_path / "people.json"
    proc = subprocess.run([sys.executable, "-m", "kubric", "export", "coco", str(scene_dir),
                           "--out", str(out), "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    coco = COCO(str(out))
    (person_cat,) = coco.dataset["categories"]
    assert person_cat["name"] == "person" and len(person_cat["keypoints"]) == 17
    assert person_cat["keypoints"][0] == "nose" and len(person_cat["skeleton"]) == 19
    meta = json.loads((scene_dir / "metadata.json").read_text())
    w, h = meta["metadata"]["resolution"]
    checked = 0
    for img in coco.dataset["images"]:
        t = img["frame"]
        seg = read_palette_png(scene_dir / f"segmentation_{t:05d}.png")[..., 0]
        for ann in coco.loadAnns(coco.getAnnIds(imgIds=[img["id"]])):
            inst = meta["instances"][ann["instance"]]
            assert (coco.annToMask(ann).astype(bool) == (seg == ann["instance"] + 1)).all()
            ymin, xmin, ymax, xmax = inst["bboxes"][inst["bbox_frames"].index(t)]
            np.testing.assert_allclose(ann["bbox"], [xmin * w, ymin * h, (xmax - xmin) * w,
                                                     (ymax - ymin) * h], atol=1e-4)
            kp = np.asarray(ann["keypoints"], np.float64).reshape(17, 3)
            vis = np.asarray(inst["keypoints_visibility"][t])
            ours = np.asarray(inst["keypoints_2d"][t]) - 0.5   # COCO: pixel-index coordinates
            assert (kp[:, 2] == vis).all() and ann["num_keypoints"] == int((vis > 0).sum())
            np.testing.assert_allclose(kp[vis > 0, :2], ours[vis > 0], atol=1e-3)
            assert (kp[vis == 0] == 0).all()
            checked += 1
    assert checked >= 3


@pytest.mark.blender
def test_person_keypoints_task_reads_the_metadata(scene_dir, tmp_path):
    from kubric.datasets import load
    proc = subprocess.run([sys.executable, "-m", "kubric", "pack", str(scene_dir.parent),
                           "--out", str(tmp_path / "ds"), "--splits", "train=1", "--no-progress"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    item = load(tmp_path / "ds", "train", task="person_keypoints")[0]
    meta = json.loads((scene_dir / "metadata.json").read_text())
    people = meta["instances"]
    assert item["keypoints_2d"].shape == (len(people), 3, 17, 2)
    for k, person in enumerate(people):
        np.testing.assert_allclose(item["keypoints_2d"][k], person["keypoints_2d"], atol=1e-4)
        np.testing.assert_allclose(item["keypoints_3d"][k], person["keypoints_3d"], atol=1e-5)
        assert (item["keypoints_visibility"][k] == np.asarray(person["keypoints_visibility"])).all()
    assert item["video"].shape == (3, 64, 64, 3)
