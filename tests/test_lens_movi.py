"""Real MOVi-A scenes rendered through a lens (``lens=opencv`` / ``lens=fisheye``; the raycast
backend with bpy blocked, and the blender backend's custom lens camera), read back from the scene
directory and checked with OpenCV itself:

* tracks: ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints`` of every track's 3D point, with
  the camera of metadata.json, lands on the written pixel position (< 1e-3 px);
* depth and flow: each pixel's ray from ``cv2.undistortPoints`` (OpenCV's inverse, not ours),
  walked by the written depth, moved with its instance's written poses and projected by OpenCV
  into the next / previous frame, lands where the written flow says (median < 1e-3 px);
* z: depth times the cosine of OpenCV's ray to the optical axis;
* the lens options: metadata, refusals, sampling.
"""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kubric import file_io
from kubric.annotations.track_files import read_tracks
from kubric.core import lenses
from kubric.pipeline import OptionError, get_recipe

cv2 = pytest.importorskip("cv2")

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
W, H, T = 80, 60, 4
LENSES = {"opencv": "-0.3,0.09,0.002,-0.001,-0.01", "fisheye": "0.2,-0.05,0.01,-0.002"}
CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)


@pytest.fixture(scope="module", params=[
    ("opencv", "raycast"), ("fisheye", "raycast"),
    pytest.param(("fisheye", "blender"), marks=pytest.mark.blender),
    pytest.param(("opencv", "blender"), marks=pytest.mark.blender)], ids="-".join)
def scene(tmp_path_factory, request):
    model, renderer = request.param
    root = tmp_path_factory.mktemp("lens")
    paths = [str(ROOT)] if renderer == "blender" else [str(NO_BPY), str(ROOT)]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths))
    options = [f"resolution={W}x{H}", f"frame_end={T}", f"renderer={renderer}",
               "max_num_objects=5", "tracks=300", "track_stride=2", "track_max_fraction=0.5",
               f"lens={model}", f"lens_coefficients={LENSES[model]}"]
    options += ["samples=2", "denoise=false"] if renderer == "blender" else []
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "7", "--out", str(root)]
    for o in options:
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene_dir = root / "scene_00000007"
    meta = json.loads((scene_dir / "metadata.json").read_text())
    return (model, meta, file_io.read_image_dict(scene_dir), read_tracks(scene_dir),
            scene_dir)


def _opencv_camera(meta, t):
    """(rvec, tvec, K, coefficients) of frame index t, derived here from matrices_world."""
    cam = meta["camera"]
    m = np.asarray(cam["matrices_world"][t], np.float64)
    rot = np.diag([1.0, -1.0, -1.0]) @ m[:3, :3].T
    tvec = -rot @ m[:3, 3]
    return (cv2.Rodrigues(rot)[0][:, 0], tvec, np.asarray(cam["intrinsics_pixels"], np.float64),
            np.asarray(cam["distortion_coefficients"], np.float64))


def _cv_project(model, world, camera):
    rvec, tvec, k, coeffs = camera
    if model == "fisheye":
        return cv2.fisheye.projectPoints(world[:, None], rvec, tvec, k, coeffs[:4])[0][:, 0]
    return cv2.projectPoints(world, rvec, tvec, k, coeffs)[0][:, 0]


def _cv_rays(model, pixels, camera):
    """OpenCV-frame ray directions (N, 3), unnormalised (z = 1), of pixel positions (N, 2)."""
    _, _, k, coeffs = camera
    if model == "fisheye":
        ab = cv2.fisheye.undistortPoints(pixels[:, None], k, coeffs[:4], criteria=CRITERIA)
    else:
        ab = cv2.undistortPointsIter(pixels[:, None], k, coeffs, None, None, CRITERIA)
    return np.concatenate([ab[:, 0], np.ones((len(pixels), 1))], axis=1)


def test_metadata_records_the_lens_in_opencvs_convention(scene):
    model, meta, _, _, _ = scene
    cam = meta["camera"]
    assert cam["distortion_model"] == model
    given = [float(v) for v in LENSES[model].split(",")]
    assert cam["distortion_coefficients"][:len(given)] == pytest.approx(given, abs=0)
    assert not any(cam["distortion_coefficients"][len(given):])
    assert meta["flags"]["lens"] == model
    for t in range(T):
        rvec, tvec, _, _ = _opencv_camera(meta, t)
        ext = np.asarray(cam["extrinsics_opencv"][t])
        assert np.abs(ext[:3, :3] - cv2.Rodrigues(rvec)[0]).max() < 1e-9
        assert np.abs(ext[:3, 3] - tvec).max() < 1e-9


def test_tracks_are_opencvs_projection_of_their_points(scene):
    model, meta, _, tracks, _ = scene
    assert len(tracks["target_points"]) == 300
    errors = []
    for t in range(T):
        world = tracks["points_world"][:, t].astype(np.float64)
        ours = tracks["target_points"][:, t].astype(np.float64)
        theirs = _cv_project(model, world, _opencv_camera(meta, t))
        errors.append(np.abs(ours - theirs).max())
    assert max(errors) < 1e-3, errors


def _pixels_of_instances(layers, t):
    seg = layers["segmentation"][t, ..., 0].astype(int)
    rows, cols = np.nonzero(seg > 0)
    return rows, cols, seg[rows, cols]


def _pose(instance, t):
    q = np.asarray(instance["quaternions"][t], np.float64)  # WXYZ
    rot = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()
    return rot, np.asarray(instance["positions"][t], np.float64)


@pytest.mark.parametrize("layer, step", [("forward_flow", 1), ("backward_flow", -1)])
def test_flow_is_the_reprojection_of_depth_and_poses_through_the_lens(scene, layer, step):
    model, meta, layers, _, _ = scene
    errors = []
    for t in range(T):
        if not 0 <= t + step < T:
            continue  # the pose at frame_end + 1 is not in metadata.json
        rows, cols, labels = _pixels_of_instances(layers, t)
        pixels = np.stack([cols + 0.5, rows + 0.5], 1)
        camera = _opencv_camera(meta, t)
        rays = _cv_rays(model, pixels, camera)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        rot_cv = cv2.Rodrigues(camera[0])[0]
        centre = -rot_cv.T @ camera[1]
        depth = layers["depth"][t, rows, cols, 0].astype(np.float64)
        world = centre + (rays @ rot_cv) * depth[:, None]
        moved = np.empty_like(world)
        for label in np.unique(labels):
            sel = labels == label
            instance = meta["instances"][label - 1]
            r0, p0 = _pose(instance, t)
            r1, p1 = _pose(instance, t + step)
            moved[sel] = (world[sel] - p0) @ r0 @ r1.T + p1
        target = _cv_project(model, moved, _opencv_camera(meta, t + step))
        flow = layers[layer][t, rows, cols].astype(np.float64)  # (Δrow, Δcol)
        errors.append(np.abs(pixels + flow[:, ::-1] - target).max(axis=1))
    errors = np.concatenate(errors)
    assert len(errors) > 200
    assert np.median(errors) < 1e-3, np.percentile(errors, [50, 90, 99])


def test_z_is_depth_along_opencvs_ray(scene):
    model, meta, layers, _, _ = scene
    rows, cols, _ = _pixels_of_instances(layers, 0)
    pixels = np.stack([cols + 0.5, rows + 0.5], 1)
    rays = _cv_rays(model, pixels, _opencv_camera(meta, 0))
    expected = layers["depth"][0, rows, cols, 0] / np.linalg.norm(rays, axis=1)
    assert np.abs(layers["z"][0, rows, cols, 0] - expected).max() < 1e-4


def test_lens_options_are_checked():
    movi_a = get_recipe("movi_a")
    assert movi_a.from_assignments(["lens=fisheye"]).lens == "fisheye"  # both backends can
    with pytest.raises(OptionError, match=r"lens_coefficients=0.1,0.2: .*4, 5 or 8 values"):
        movi_a.from_assignments(["renderer=raycast", "lens=opencv", "lens_coefficients=0.1,0.2"])
    with pytest.raises(OptionError, match="lens_coefficients needs lens=opencv or lens=fisheye"):
        movi_a.from_assignments(["renderer=raycast", "lens_coefficients=0.1,0,0,0"])
    with pytest.raises(OptionError, match="lens_coefficients_high=.* must have the 4 values"):
        movi_a.from_assignments(["renderer=raycast", "lens=fisheye",
                                 "lens_coefficients=0,0,0,0", "lens_coefficients_high=0.1,0"])
    with pytest.raises(OptionError, match="lens"):
        movi_a.from_assignments(["renderer=raycast", "lens=kb4"])
    with pytest.raises(OptionError, match=r"lens=fisheye with dof=True: a lens-model camera is a "
                                          r"pinhole aperture"):
        movi_a.from_assignments(["lens=fisheye", "dof=true"])


def test_lens_ranges_are_drawn_from_the_scene_rng():
    recipe = get_recipe("movi_a").from_assignments(
        ["renderer=raycast", "lens=fisheye", "lens_coefficients=0,-0.02,0,0",
         "lens_coefficients_high=0.1,0,0.01,0"])
    draws = [recipe.make_lens(np.random.RandomState(s)) for s in (1, 1, 2)]
    assert draws[0] == draws[1] != draws[2]
    for lens in draws:
        assert isinstance(lens, lenses.Fisheye)
        assert 0 <= lens.k1 <= 0.1 and -0.02 <= lens.k2 <= 0 and 0 <= lens.k3 <= 0.01
    assert get_recipe("movi_a").from_assignments([]).make_lens(None) is lenses.PINHOLE


def test_multiview_scene_records_the_lens_for_nerf_and_opencv(tmp_path):
    """klevr with lens=opencv (raycast): the transforms files carry nerfstudio's OPENCV fields,
    their rays are OpenCV's (cv2.undistortPoints), and every point of points.npz projects with
    cv2.projectPoints onto the pixel centre it was unprojected from."""
    coeffs = [-0.3, 0.1, 0.001, 0.002, -0.01]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    cmd = [sys.executable, "-m", "kubric", "worker", "klevr", "--seed", "2", "--out",
           str(tmp_path)]
    for o in ("resolution=48x40", "num_views=3", "split_ratio=1,1,1", "renderer=raycast",
              "lens=opencv", "lens_coefficients=" + ",".join(map(str, coeffs))):
        cmd += ["--set", o]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene_dir = tmp_path / "scene_00000002"
    data = json.loads((scene_dir / "transforms_train.json").read_text())
    assert data["camera_model"] == "OPENCV"
    assert [data[k] for k in ("k1", "k2", "p1", "p2", "k3")] == coeffs
    from kubric.datasets.exports import nerf
    entry = data["frames"][0]
    _, dirs = nerf.pixel_rays_from_transforms(data, entry)
    k = np.array([[data["fl_x"], 0, data["cx"]], [0, data["fl_y"], data["cy"]], [0, 0, 1.0]])
    pix = np.stack(np.meshgrid(np.arange(48) + 0.5, np.arange(40) + 0.5), -1).reshape(-1, 2)
    ab = cv2.undistortPointsIter(pix[:, None], k, np.array(coeffs), None, None, CRITERIA)[:, 0]
    local = np.concatenate([ab, np.ones((len(ab), 1))], 1) * [1, -1, -1]  # OpenCV → Blender
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    truth = local @ np.asarray(entry["transform_matrix"])[:3, :3].T
    assert np.abs(dirs.reshape(-1, 3) - truth).max() < 1e-6
    meta = json.loads((scene_dir / "metadata.json").read_text())
    points = np.load(scene_dir / "points.npz")
    for view in range(3):
        sel = points["view"] == view
        rvec, tvec, kk, dist = _opencv_camera(meta, view)
        xy = cv2.projectPoints(points["xyz"][sel].astype(np.float64), rvec, tvec, kk, dist)[0]
        centres = points["pixel"][sel][:, ::-1] + 0.5  # (row, col) → (x, y)
        assert np.abs(xy[:, 0] - centres).max() < 1e-3


def test_multiview_refuses_a_lens_nerfstudio_cannot_record():
    with pytest.raises(OptionError, match=r"nerfstudio's OPENCV model\) have no k4, k5, k6"):
        get_recipe("klevr").from_assignments(["renderer=raycast", "lens=opencv",
                                              "lens_coefficients=0,0,0,0,0,0.1,0,0"])


def test_viewer_unprojects_through_the_lens(scene):
    from kubric.viewer.service import _unproject

    model, meta, layers, _, _ = scene
    rows, cols, _ = _pixels_of_instances(layers, 1)
    camera = _opencv_camera(meta, 1)
    rays = _cv_rays(model, np.stack([cols + 0.5, rows + 0.5], 1), camera)
    rot_cv = cv2.Rodrigues(camera[0])[0]
    for i in range(0, len(rows), max(1, len(rows) // 20)):
        depth = float(layers["depth"][1, rows[i], cols[i], 0])
        truth = -rot_cv.T @ camera[1] + rot_cv.T @ (rays[i] / np.linalg.norm(rays[i])) * depth
        got = _unproject(meta["camera"], 1, int(cols[i]), int(rows[i]), depth)
        assert np.abs(np.asarray(got) - truth).max() < 1e-6


def test_pinhole_only_exports_refuse_a_lens_scene(scene, tmp_path):
    from kubric.datasets.exports.bop import export_bop
    from kubric.datasets.exports.lasr import export_lasr
    from kubric.errors import InputError

    model, _, _, _, scene_dir = scene
    with pytest.raises(InputError, match=f"LASR's .* pinhole cameras only; .* lens {model}"):
        export_lasr(scene_dir, tmp_path / "lasr")
    with pytest.raises(InputError, match=f"BOP's cam_K describes pinhole cameras only; .* lens "
                                         f"{model}"):
        export_bop(scene_dir, tmp_path / "bop")


def test_sampled_lens_is_recorded_and_leaves_the_rest_of_the_scene(tmp_path):
    """lens_coefficients_high: each seed draws its own coefficients within the ranges (recorded
    in metadata.json), after every other draw: the objects are those of the pinhole scene."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    low, high = [0.0, -0.02, 0.0, 0.0], [0.1, 0.0, 0.01, 0.001]
    common = ["resolution=32x24", "frame_end=2", "renderer=raycast", "max_num_objects=4"]
    runs = {"pinhole": common, "lens": common + [
        "lens=fisheye", "lens_coefficients=" + ",".join(map(str, low)),
        "lens_coefficients_high=" + ",".join(map(str, high))]}
    meta = {}
    for name, options in runs.items():
        for seed in (1, 2):
            out = tmp_path / f"{name}{seed}"
            cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", str(seed),
                   "--out", str(out)]
            for o in options:
                cmd += ["--set", o]
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True,
                                  timeout=300)
            assert proc.returncode == 0, proc.stderr[-2000:]
            meta[name, seed] = json.loads(
                (out / f"scene_{seed:08d}" / "metadata.json").read_text())
    drawn = [meta["lens", s]["camera"]["distortion_coefficients"][:4] for s in (1, 2)]
    assert drawn[0] != drawn[1]
    for values in drawn:
        assert all(lo <= v <= hi for lo, v, hi in zip(low, values, high, strict=True))
    for seed in (1, 2):
        a, b = meta["pinhole", seed], meta["lens", seed]
        assert a["camera"]["distortion_model"] == "none"
        assert a["camera"]["matrices_world"] == b["camera"]["matrices_world"]
        # (instances are sorted by visible pixels, which the lens changes)
        assert sorted(map(str, (i["positions"] for i in a["instances"]))) == \
            sorted(map(str, (i["positions"] for i in b["instances"])))


def test_packed_lens_scene_gives_rays_through_the_lens(scene, tmp_path):
    """`kubric pack` of a lens scene keeps its distortion features, and the nerf_rays task of the
    loaded dataset casts through them: origin + depth · direction projects with OpenCV onto
    each pixel centre (the depth is MOVi's uint16 quantisation, hence 0.05 px)."""
    from kubric.datasets import load

    model, meta, layers, _, scene_dir = scene
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copytree(scene_dir, scenes / scene_dir.name)
    out = tmp_path / "packed"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    proc = subprocess.run([sys.executable, "-m", "kubric", "pack", str(scenes), "--out", str(out),
                           "--splits", "train=1", "--verify", "--no-progress"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    example = load(out, "train")[0]
    assert example["camera"]["distortion_model"] in (model, model.encode())
    frame = load(out, "train", task="frames")[1]
    assert frame["distortion_model"] in (model, model.encode())
    assert np.allclose(frame["distortion_coefficients"],
                       meta["camera"]["distortion_coefficients"], rtol=1e-6)
    rays = load(out, "train", task="nerf_rays")
    for t in range(T):
        item = rays[t]
        hit = (layers["segmentation"][t, ..., 0] > 0)
        points = (item["ray_origins"].astype(np.float64) + item["depth"][..., None].astype(
            np.float64) * item["ray_directions"].astype(np.float64))[hit]
        rows, cols = np.nonzero(hit)
        xy = _cv_project(model, points, _opencv_camera(meta, t))
        assert np.abs(xy - np.stack([cols + 0.5, rows + 0.5], 1)).max() < 0.05
