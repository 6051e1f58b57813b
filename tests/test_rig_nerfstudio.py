"""A multi-view scene through a fisheye lens, read as nerfstudio reads its ``transforms_*.json``
(``camera_model`` OPENCV_FISHEYE, ``fl_x``, ``fl_y``, ``cx``, ``cy`` with pixel centres at +0.5,
``k1``…``k4``, ``transform_matrix`` camera → world in OpenGL / Blender camera axes) and
reprojected with OpenCV's own fisheye functions, is consistent between views: a floor point seen
by view A (its depth along ``cv2.fisheye.undistortPoints``' ray) projected into view B by
``cv2.fisheye.projectPoints`` lies on view B's ray through that position, which meets the floor
plane fitted to view B's own depth at that same point (< 1e-4 m); object points land where view
B sees a surface at their distance, on their own instance. Nothing of kubric's geometry is
used: only the JSON and the layers' files."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric import file_io

cv2 = pytest.importorskip("cv2")

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
TO_CV = np.diag([1.0, -1.0, -1.0])  # OpenGL / Blender camera axes ↔ OpenCV's


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    root = tmp_path_factory.mktemp("fisheye_views")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    cmd = [sys.executable, "-m", "kubric", "worker", "klevr", "--seed", "4", "--out", str(root)]
    for o in ("renderer=raycast", "resolution=64x48", "num_views=10", "lens=fisheye",
              "lens_coefficients=0.2,-0.05,0.01,-0.002"):
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene = root / "scene_00000004"
    cameras = {}
    for split in ("train", "val", "test"):
        data = json.loads((scene / f"transforms_{split}.json").read_text())
        assert data["camera_model"] == "OPENCV_FISHEYE"
        k = np.array([[data["fl_x"], 0, data["cx"]], [0, data["fl_y"], data["cy"]], [0, 0, 1]])
        dist = np.array([data[f"k{i}"] for i in range(1, 5)], np.float64)
        for frame in data["frames"]:
            cameras[frame["view"]] = (k, dist, np.asarray(frame["transform_matrix"], np.float64))
    layers = file_io.read_image_dict(scene, ["depth", "segmentation"])
    return cameras, layers["depth"][..., 0].astype(np.float64), layers["segmentation"][..., 0]


def _world_points(camera, pixels, depth):
    """World points at ``depth`` (metres along the ray) through ``pixels`` (N, 2), OpenCV's rays."""
    k, dist, c2w = camera
    ab = cv2.fisheye.undistortPoints(pixels[:, None].astype(np.float64), k, dist,
                                     criteria=CRITERIA)[:, 0]
    rays = np.concatenate([ab, np.ones((len(ab), 1))], 1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    return (rays * depth[:, None]) @ TO_CV @ c2w[:3, :3].T + c2w[:3, 3], \
        rays @ TO_CV @ c2w[:3, :3].T


def _project(camera, world):
    k, dist, c2w = camera
    rot = TO_CV @ c2w[:3, :3].T
    tvec = -rot @ c2w[:3, 3]
    cam = world @ rot.T + tvec
    xy = cv2.fisheye.projectPoints(world[:, None], cv2.Rodrigues(rot)[0], tvec, k, dist)[0][:, 0]
    return xy, cam[:, 2]


def test_fisheye_views_agree_through_opencv(views):
    cameras, depth, seg = views
    _, h, w = depth.shape
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    centres = np.stack([xs, ys], -1)
    checked = objects = 0
    for a, b in [(0, 3), (1, 6), (2, 8), (5, 9)]:
        floor_b = (seg[b] == 0) & (depth[b] < 1000)
        pts_b, _ = _world_points(cameras[b], centres[floor_b], depth[b][floor_b])
        # the dome's floor is flat out to 25 m from its centre, then curves up
        flat = (np.abs(pts_b[:, 2] - np.median(pts_b[:, 2])) < 0.01) & \
            (np.hypot(pts_b[:, 0], pts_b[:, 1]) < 20)
        centroid = pts_b[flat].mean(0)
        normal = np.linalg.svd(pts_b[flat] - centroid)[2][-1]
        assert np.abs((pts_b[flat] - centroid) @ normal).max() < 1e-4  # B's floor: one plane

        hit_a = depth[a] < 1000
        pts_a, _ = _world_points(cameras[a], centres[hit_a], depth[a][hit_a])
        xy, z = _project(cameras[b], pts_a)
        inside = (z > 0) & (xy[:, 0] > 1) & (xy[:, 0] < w - 1) & (xy[:, 1] > 1) & \
            (xy[:, 1] < h - 1)
        rows, cols = np.floor(xy[inside, 1]).astype(int), np.floor(xy[inside, 0]).astype(int)
        dist_b = np.linalg.norm(pts_a[inside] - cameras[b][2][:3, 3], axis=1)
        seen = depth[b][rows, cols] > dist_b - 0.05  # not hidden from B
        on_floor = (seg[a][hit_a][inside] == 0) & \
            (np.abs((pts_a[inside] - centroid) @ normal) < 1e-3)
        sel = seen & on_floor & (seg[b][rows, cols] == 0)
        origin = cameras[b][2][:3, 3]
        _, rays = _world_points(cameras[b], xy[inside][sel], np.ones(sel.sum()))
        t = ((centroid - origin) @ normal) / (rays @ normal)
        err = np.linalg.norm(origin + rays * t[:, None] - pts_a[inside][sel], axis=1)
        assert sel.sum() > 50 and err.max() < 1e-4, (a, b, sel.sum(), err.max())
        checked += int(sel.sum())
        # object points inside a region of one label in B (the 4 pixel centres around the
        # position) where B sees a surface at their distance: that label is theirs
        r0 = np.clip(np.floor(xy[inside, 1] - 0.5).astype(int), 0, h - 2)
        c0 = np.clip(np.floor(xy[inside, 0] - 0.5).astype(int), 0, w - 2)
        around = np.stack([seg[b][r0 + i, c0 + j] for i in (0, 1) for j in (0, 1)], 1)
        obj = (np.abs(depth[b][rows, cols] - dist_b) < 0.1) & (seg[a][hit_a][inside] > 0) & \
            np.all(around == around[:, :1], axis=1)
        assert np.array_equal(seg[b][rows, cols][obj], seg[a][hit_a][inside][obj]), (a, b)
        objects += int(obj.sum())
    assert checked > 500 and objects > 50
