"""COCO and BOP exports of a camera-rig scene, on real output: a tiny stereo MOVi-A scene
rendered by the raycast backend (bpy blocked), exported, and read back by the formats' own
readers, each camera checked against its own files and metadata:

* COCO read by pycocotools: each camera's frames are images of their own, with unique ids (the
  reference camera's those of a mono scene, ``seed · 10⁴ + t``; the right camera's
  ``seed · 10⁴ + T + t``); every right-camera mask decoded by pycocotools equals the right
  camera's segmentation layer for that label, and every visible label has its annotation;
* BOP: the right camera's images (``T + t``) have ``cam_K`` = its OpenCV intrinsics with pixel
  centres at integers and ``cam_R_w2c`` / ``cam_t_w2c`` = the rig's recorded
  ``extrinsics_opencv`` of that camera (metres → mm); its ``mask_visib`` = its segmentation; its
  depth PNG = the z-depth derived here from its own distance layer.
"""

import json

import numpy as np
import pytest
from test_rig import H, W, _right_layers, _worker

from kubric import file_io
from kubric.core import camera_geometry as geo
from kubric.datasets.exports import exporter

SEED = 5


@pytest.fixture(scope="module")
def stereo(tmp_path_factory):
    root = tmp_path_factory.mktemp("rig_exports")
    scene = _worker(root, SEED, "frame_end=3", "cameras=stereo", "baseline=0.4",
                    "max_num_objects=4")
    meta = json.loads((scene / "metadata.json").read_text())
    return root, scene, meta


def test_coco_has_every_camera_as_images(stereo, tmp_path):
    from pycocotools import mask as mask_utils
    from pycocotools.coco import COCO
    root, scene, meta = stereo
    exporter("coco")(root, tmp_path / "coco.json", progress=False)
    coco = COCO(str(tmp_path / "coco.json"))
    t = meta["metadata"]["num_frames"]
    images = coco.loadImgs(coco.getImgIds())
    assert len(images) == 2 * t and len({i["id"] for i in images}) == 2 * t
    by_camera = {c: sorted((i for i in images if i["camera"] == c), key=lambda i: i["frame"])
                 for c in ("left", "right")}
    assert [i["id"] for i in by_camera["left"]] == [SEED * 10_000 + f for f in range(t)]
    assert [i["id"] for i in by_camera["right"]] == [SEED * 10_000 + t + f for f in range(t)]
    right_seg = _right_layers(scene)["segmentation"][..., 0]
    right_rgb = _right_layers(scene)["rgba"]
    record = meta["camera"]["rig"]["views"]["right"]
    checked = 0
    for image in by_camera["right"]:
        f = image["frame"]
        assert image["file_name"] == f"{scene.name}/right_rgba_{f:05d}.png"
        assert np.array_equal(file_io.read_png(root / image["file_name"]), right_rgb[f])
        assert np.allclose(image["extrinsics_opencv"], record["extrinsics_opencv"][f])
        assert np.allclose(image["intrinsics_pixels"], record["intrinsics_pixels"])
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[image["id"]]))
        labels = set(np.unique(right_seg[f]).tolist()) - {0}
        assert {a["instance"] + 1 for a in anns} == labels
        for ann in anns:
            decoded = mask_utils.decode(coco.annToRLE(ann)).astype(bool)
            assert np.array_equal(decoded, right_seg[f] == ann["instance"] + 1)
            assert ann["area"] == int(decoded.sum())
            checked += 1
    assert checked >= 3
    # the two cameras see different pixels: the right masks are not the left ones
    left_seg = file_io.read_layer(scene, "segmentation")[..., 0]
    assert not np.array_equal(left_seg, right_seg)


def test_bop_has_every_camera_with_its_own_camera(stereo, tmp_path):
    root, scene, meta = stereo
    summary = exporter("bop")(root, tmp_path / "bop", progress=False)
    t = meta["metadata"]["num_frames"]
    assert summary.images == 2 * t
    bop = tmp_path / "bop" / "train_pbr" / f"{SEED:06d}"
    cams = json.loads((bop / "scene_camera.json").read_text())
    gts = json.loads((bop / "scene_gt.json").read_text())
    assert sorted(map(int, cams)) == list(range(2 * t))
    right = _right_layers(scene)
    record = meta["camera"]["rig"]["views"]["right"]
    k = np.asarray(record["intrinsics_pixels"])
    xs, ys = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    ray = np.linalg.norm(np.stack([(xs - k[0, 2]) / k[0, 0], (ys - k[1, 2]) / k[1, 1],
                                   np.ones_like(xs)], -1), axis=-1)
    for name, offset, camera in (("left", 0, meta["camera"]), ("right", t, record)):
        for f in range(t):
            cam = cams[str(offset + f)]
            assert cam["camera"] == name
            ext = np.asarray(camera["extrinsics_opencv"][f])
            assert np.allclose(np.reshape(cam["cam_R_w2c"], (3, 3)), ext[:3, :3], atol=1e-6)
            assert np.allclose(cam["cam_t_w2c"], ext[:3, 3] * 1000, atol=1e-3)
            expected_k = np.asarray(camera["intrinsics_pixels"]) - [[0, 0, 0.5], [0, 0, 0.5],
                                                                    [0, 0, 0]]
            assert np.allclose(np.reshape(cam["cam_K"], (3, 3)), expected_k)
    for f in range(t):
        im = t + f
        seg, depth = right["segmentation"][f, ..., 0], right["depth"][f, ..., 0]
        for g, _ in enumerate(gts[str(im)]):
            visib = file_io.read_png(bop / "mask_visib" / f"{im:06d}_{g:06d}.png")[..., 0] > 0
            assert np.array_equal(visib, seg == g + 1)  # MOVi-A: no people, gt = instance
        png = file_io.read_png(bop / "depth" / f"{im:06d}.png")[..., 0].astype(float)
        hit = depth < geo.BACKGROUND_DEPTH * 0.999
        assert np.abs(png[hit] - np.rint(depth[hit] / ray[hit] * 1000)).max() <= 1
        assert np.all(png[~hit] == 0)
    left_png = file_io.read_png(bop / "depth" / f"{0:06d}.png")[..., 0]
    assert not np.array_equal(left_png, file_io.read_png(bop / "depth" / f"{t:06d}.png")[..., 0])
