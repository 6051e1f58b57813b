"""NeRF and LASR exports of video scenes — camera rigs and one camera — on real output: tiny
MOVi-A scenes rendered by the raycast backend (bpy blocked), exported by the ``kubric export``
command, and read back without kubric's geometry:

* ``transforms.json`` is read as nerfstudio's ``Nerfstudio`` dataparser reads it (reimplemented
  here: a field at the top level is fixed for every frame, else each frame's; any of k1, k2, k3,
  p1, p2 at the top level fixes the distortion; ``camera_model`` from the top level; frames sorted
  by file name; ``file_path`` relative to the JSON's folder), and every (camera, frame) image is
  there with the pose, intrinsics and lens that ``metadata.json`` records for that camera;
* camera 0's depth, turned into world points through the exported fields with OpenCV
  (``cv2.undistortPointsIter`` / ``cv2.fisheye.undistortPoints``) and projected into camera 1
  and 2 with ``cv2.projectPoints`` / ``cv2.fisheye.projectPoints``, lands where those cameras'
  own depth puts the same point: on the floor, the other camera's ray through the projected
  position meets the floor plane fitted to its own depth at the point (< 1e-4 m), and the point
  its depth gives there (interpolated between pixel centres) is the same point (< 2e-3 of the
  distance for 98 % of them; a camera half a pixel off fails); object points seen at their
  distance carry their own instance label — for a pinhole random rig and a fisheye ring rig;
  through each lens the floor's points are flat;
* cameras that differ go into the frames (nerfstudio's per-frame fields), lenses nerfstudio
  cannot express are refused in one line;
* ``kubric export lasr --camera 1``: the camera files are camera 1's recorded extrinsics and
  intrinsics, the silhouettes its segmentation, the flow its flow layer; a bad index is one line.
"""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image
from test_rig import ROOT, _worker

from kubric import file_io
from kubric.datasets.exports import exporter
from kubric.errors import UsageError
from kubric.io.pfm_io import decode_pfm
from kubric.io.stored_schema import stored_schema

cv2 = pytest.importorskip("cv2")

CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
TO_CV = np.diag([1.0, -1.0, -1.0])  # OpenGL / Blender camera axes ↔ OpenCV's
FRAMES = 3
SCENES = {"random": (5, "cameras=random", "num_cameras=3"),
          "fisheye": (6, "cameras=ring", "num_cameras=3", "lens=fisheye",
                      "lens_coefficients=0.2,-0.05,0.01,-0.002"),
          "mono": (7, "lens=opencv")}


def kubric(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    base = tmp_path_factory.mktemp("rig_nerf")
    scenes = {name: _worker(base / "scenes", seed, f"frame_end={FRAMES}", "max_num_objects=4",
                            "resolution=64x48",
                            *options)
              for name, (seed, *options) in SCENES.items()}
    proc = kubric("export", "nerf", base / "scenes", "--out", base / "nerf")
    assert proc.returncode == 0, proc.stderr[-2000:]
    return base, scenes


def read_nerfstudio(folder: pathlib.Path) -> list[dict]:
    """Every frame of ``folder/transforms.json`` as nerfstudio's dataparser reads it, plus our
    additions (camera, frame, time, depth and segmentation files)."""
    meta = json.loads((folder / "transforms.json").read_text())
    distort_fixed = any(k in meta for k in ("k1", "k2", "k3", "p1", "p2"))
    model = meta.get("camera_model", "OPENCV")
    out = []
    for frame in sorted(meta["frames"], key=lambda f: str(folder / f["file_path"])):
        def get(key, frame=frame):
            return meta[key] if key in meta else frame[key]
        src = meta if distort_fixed else frame
        d = {k: float(src.get(k, 0.0)) for k in ("k1", "k2", "k3", "k4", "p1", "p2")}
        dist = [d["k1"], d["k2"], d["k3"], d["k4"]] if model == "OPENCV_FISHEYE" else \
            [d["k1"], d["k2"], d["p1"], d["p2"], d["k3"]]
        out.append({
            "K": np.array([[get("fl_x"), 0, get("cx")], [0, get("fl_y"), get("cy")], [0, 0, 1]],
                          np.float64),
            "size": (int(get("w")), int(get("h"))), "model": model,
            "dist": np.array(dist, np.float64),
            "c2w": np.array(frame["transform_matrix"], np.float64),
            "image": folder / frame["file_path"], "camera": frame["camera"],
            "frame": frame["frame"], "time": frame["time"],
            "depth": file_io.read_tiff(folder / frame["depth_file"])[..., 0].astype(np.float64),
            "seg": file_io.read_png(folder / frame["segmentation_file"])[..., 0]})
    return out


def _cameras(folder):
    return {(f["camera"], f["frame"]): f for f in read_nerfstudio(folder)}


def _world_points(cam, pixels, distance):
    """World points ``distance`` metres along OpenCV's rays through ``pixels`` (N, 2)."""
    p = pixels[:, None].astype(np.float64)
    if cam["model"] == "OPENCV_FISHEYE":
        ab = cv2.fisheye.undistortPoints(p, cam["K"], cam["dist"], criteria=CRITERIA)[:, 0]
    else:
        ab = cv2.undistortPointsIter(p, cam["K"], cam["dist"], None, None, CRITERIA)[:, 0]
    rays = np.concatenate([ab, np.ones((len(ab), 1))], 1)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    rays = rays @ TO_CV @ cam["c2w"][:3, :3].T
    return rays * distance[:, None] + cam["c2w"][:3, 3], rays


def _project(cam, world):
    rot = TO_CV @ cam["c2w"][:3, :3].T
    tvec = -rot @ cam["c2w"][:3, 3]
    rvec = cv2.Rodrigues(rot)[0]
    if cam["model"] == "OPENCV_FISHEYE":
        xy = cv2.fisheye.projectPoints(world[:, None], rvec, tvec, cam["K"], cam["dist"])[0]
    else:
        xy = cv2.projectPoints(world, rvec, tvec, cam["K"], cam["dist"])[0]
    return xy[:, 0], (world @ rot.T + tvec)[:, 2]


def _centres(h, w):
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return np.stack([xs, ys], -1)


def _records(meta):
    """Each camera's record in metadata.json, in rig order."""
    rig = meta["camera"].get("rig")
    return [meta["camera"]] + ([rig["views"][n] for n in rig["cameras"][1:]] if rig else [])


@pytest.mark.parametrize("name", list(SCENES))
def test_every_camera_and_frame_as_nerfstudio_reads_them(exported, name):
    base, scenes = exported
    scene = scenes[name]
    folder = base / "nerf" / scene.name
    meta = json.loads((scene / "metadata.json").read_text())
    data = json.loads((folder / "transforms.json").read_text())
    records = _records(meta)
    frames = read_nerfstudio(folder)
    assert sorted((f["camera"], f["frame"]) for f in frames) == \
        [(c, t) for c in range(len(records)) for t in range(FRAMES)]
    lens = {"random": "none", "fisheye": "fisheye", "mono": "opencv"}[name]
    for f in frames:
        record = records[f["camera"]]
        t = f["frame"]
        assert f["time"] == pytest.approx(t / (FRAMES - 1))  # D-NeRF's time in [0, 1]
        assert np.allclose(f["c2w"], record["matrices_world"][t], atol=1e-12)
        assert np.allclose(f["K"], record["intrinsics_pixels"])
        assert f["size"] == tuple(meta["metadata"]["resolution"])
        assert record["distortion_model"] == lens
        coefficients = np.asarray(record["distortion_coefficients"], np.float64)
        if lens == "fisheye":
            assert f["model"] == "OPENCV_FISHEYE"
            assert np.array_equal(f["dist"], coefficients[:4])
        else:  # nerfstudio's OPENCV: k1, k2, p1, p2, k3 (a pinhole: all 0)
            assert f["model"] == "OPENCV"
            assert np.array_equal(f["dist"], coefficients[:5])
        prefix = "" if f["camera"] == 0 else f"{meta['camera']['rig']['cameras'][f['camera']]}_"
        assert f["image"].name == f"{prefix}rgba_{t:05d}.png"
        assert f["image"].read_bytes() == (scene / f["image"].name).read_bytes()
        depth = file_io.read_tiff(scene / f"{prefix}depth_{t:05d}.tiff")[..., 0]
        assert np.array_equal(f["depth"], depth)
    if len(records) > 1:
        assert data["cameras"] == meta["camera"]["rig"]["cameras"]
    assets = {a["asset"] for a in data["licenses"]}
    assert {inst["asset_id"] for inst in meta["instances"]} <= assets


@pytest.mark.parametrize("name", ["mono", "fisheye", "random"])
def test_the_floor_is_flat_through_the_exported_lens(exported, name):
    """World z = 0 is MOVi's floor: its points, from depth along OpenCV's rays of the exported
    fields, lie on it (a wrong lens bends them) — every camera, every frame."""
    base, scenes = exported
    for cam in read_nerfstudio(base / "nerf" / scenes[name].name):
        floor = (cam["seg"] == 0) & (cam["depth"] < 1000)
        pts, _ = _world_points(cam, _centres(*cam["seg"].shape)[floor], cam["depth"][floor])
        flat = np.hypot(pts[:, 0], pts[:, 1]) < 20  # the dome curves up beyond
        assert flat.sum() > 100 and np.abs(pts[flat, 2]).max() < 1e-4, name


@pytest.mark.parametrize("name", ["random", "fisheye"])
def test_camera_0_depth_reprojects_into_the_other_cameras(exported, name):
    base, scenes = exported
    cams = _cameras(base / "nerf" / scenes[name].name)
    checked = objects = 0
    for a, b in [((0, t), (1, t)) for t in range(FRAMES)] + [((0, 0), (2, 0))]:
        A, B = cams[a], cams[b]
        h, w = A["seg"].shape
        centres = _centres(h, w)
        # B's floor plane, fitted to B's own depth
        floor_b = (B["seg"] == 0) & (B["depth"] < 1000)
        pts_b, _ = _world_points(B, centres[floor_b], B["depth"][floor_b])
        pts_b = pts_b[np.hypot(pts_b[:, 0], pts_b[:, 1]) < 20]
        centroid = pts_b.mean(0)
        normal = np.linalg.svd(pts_b - centroid)[2][-1]
        # B's depth-derived point at every pixel centre
        at_b = np.full((h, w, 3), np.nan)
        hit_b = B["depth"] < 1000
        at_b[hit_b] = _world_points(B, centres[hit_b], B["depth"][hit_b])[0]

        hit_a = A["depth"] < 1000
        pts_a, _ = _world_points(A, centres[hit_a], A["depth"][hit_a])
        labels_a = A["seg"][hit_a]
        xy, z = _project(B, pts_a)
        inside = (z > 0) & (xy[:, 0] > 0.5) & (xy[:, 0] < w - 0.5) & (xy[:, 1] > 0.5) & \
            (xy[:, 1] < h - 0.5)
        xy, pts, labels = xy[inside], pts_a[inside], labels_a[inside]
        u, v = xy[:, 0] - 0.5, xy[:, 1] - 0.5  # in pixel-centre units
        c0, r0 = np.floor(u).astype(int), np.floor(v).astype(int)
        fu, fv = (u - c0)[:, None], (v - r0)[:, None]
        around = np.stack([B["seg"][r0 + i, c0 + j] for i in (0, 1) for j in (0, 1)], 1)
        interpolated = (at_b[r0, c0] * (1 - fu) * (1 - fv) + at_b[r0, c0 + 1] * fu * (1 - fv)
                        + at_b[r0 + 1, c0] * (1 - fu) * fv + at_b[r0 + 1, c0 + 1] * fu * fv)
        distance = np.linalg.norm(pts - B["c2w"][:3, 3], axis=1)
        # B's depth-derived point there is the point (bilinear between pixel centres: measured
        # ≤ 1.1e-3 of the distance on the floor; half a pixel off would be ~7e-3)
        agree = np.linalg.norm(interpolated - pts, axis=1) < 2e-3 * distance

        on_floor = (labels == 0) & np.all(around == 0, axis=1) & \
            (np.hypot(pts[:, 0], pts[:, 1]) < 20)
        # all but the few floor points an object hides from B (at its edge)
        assert agree[on_floor].mean() > 0.98, (name, a, b, agree[on_floor].mean())
        sel = on_floor & agree
        origin = B["c2w"][:3, 3]
        _, rays = _world_points(B, xy[sel], np.ones(sel.sum()))
        t = ((centroid - origin) @ normal) / (rays @ normal)
        err = np.linalg.norm(origin + rays * t[:, None] - pts[sel], axis=1)
        assert sel.sum() > 50 and err.max() < 1e-4, (name, a, b, sel.sum(), err.max())
        checked += int(sel.sum())
        # object points B sees at their distance (nearest pixel) inside a region of one label:
        # that label is theirs
        rows, cols = np.floor(xy[:, 1]).astype(int), np.floor(xy[:, 0]).astype(int)
        seen = np.abs(np.linalg.norm(at_b[rows, cols] - origin, axis=1) - distance) < 0.1
        obj = seen & (labels > 0) & np.all(around == around[:, :1], axis=1)
        assert np.array_equal(B["seg"][rows, cols][obj], labels[obj]), (name, a, b)
        objects += int(obj.sum())
    assert checked > 800 and objects > 10, (checked, objects)


def _edited_copy(scenes, tmp_path, edit):
    scene = tmp_path / "scenes" / scenes["random"].name
    shutil.copytree(scenes["random"], scene)
    meta = json.loads((scene / "metadata.json").read_text())
    edit(meta)
    (scene / "metadata.json").write_text(json.dumps(meta))
    return scene, meta


def test_cameras_that_differ_carry_their_own_fields_per_frame(exported, tmp_path):
    """A rig whose cameras differ (metadata edited: camera 1 another focal length, camera 2 a
    Brown–Conrady lens): those fields leave the top level and every frame carries its own."""
    _, scenes = exported

    def edit(meta):
        views = meta["camera"]["rig"]["views"]
        views["cam1"]["intrinsics_pixels"][0][0] += 6.0
        views["cam2"]["distortion_model"] = "opencv"
        views["cam2"]["distortion_coefficients"] = [-0.2, 0.05, 0.001, -0.002, 0.01, 0, 0, 0]
    scene, meta = _edited_copy(scenes, tmp_path, edit)
    proc = kubric("export", "nerf", scene, "--out", tmp_path / "nerf")
    assert proc.returncode == 0, proc.stderr[-2000:]
    data = json.loads((tmp_path / "nerf" / scene.name / "transforms.json").read_text())
    fl = meta["camera"]["intrinsics_pixels"][0][0]
    assert data["fl_y"] == fl and data["camera_model"] == "OPENCV"
    assert not {"fl_x", "camera_angle_x", "k1", "k2", "p1", "p2"} & set(data)
    records = _records(meta)
    for f in read_nerfstudio(tmp_path / "nerf" / scene.name):
        record = records[f["camera"]]
        assert np.allclose(f["K"], record["intrinsics_pixels"])
        assert np.allclose(f["dist"], np.asarray(record["distortion_coefficients"])[:5])
    assert {f["K"][0, 0] for f in read_nerfstudio(tmp_path / "nerf" / scene.name)} == \
        {fl, fl + 6.0}


@pytest.mark.parametrize("case", ["rational", "mixed", "no_intrinsics"])
def test_lenses_nerfstudio_cannot_express_are_refused_in_one_line(exported, tmp_path, case):
    _, scenes = exported

    def edit(meta):
        if case == "no_intrinsics":
            del meta["camera"]["rig"]["views"]["cam2"]["intrinsics_pixels"]
            return
        for record in _records(meta)[: 1 if case == "mixed" else 3]:
            record["distortion_model"] = "fisheye" if case == "mixed" else "opencv"
            record["distortion_coefficients"] = [0.1, 0.01, 0, 0, 0, 0.02, 0, 0] if \
                case == "rational" else [0.1, 0.01, 0, 0, 0, 0, 0, 0]
    scene, _ = _edited_copy(scenes, tmp_path, edit)
    proc = kubric("export", "nerf", scene, "--out", tmp_path / "nerf")
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1, proc.stderr
    needle = {"rational": "cam0: NeRF transforms: nerfstudio's OPENCV model has no k4..k6, got "
                          "[0.02, 0.0, 0.0]",
              "mixed": "lens models ['OPENCV', 'OPENCV_FISHEYE']",
              "no_intrinsics": "cam2 has no intrinsics_pixels"}[case]
    assert needle in proc.stderr and scene.name in proc.stderr
    assert not (tmp_path / "nerf").exists()


def _rotation_wxyz(q):
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def test_lasr_of_camera_1_is_camera_1(exported, tmp_path):
    _, scenes = exported
    scene = scenes["random"]
    out = tmp_path / "lasr"
    proc = kubric("export", "lasr", scene, "--out", out, "--camera", "1", "--instances", "0,1",
                  "--root", "1", "--sequence", "seq")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "camera cam1" in proc.stdout
    meta = json.loads((scene / "metadata.json").read_text())
    record = meta["camera"]["rig"]["views"]["cam1"]
    k = np.asarray(record["intrinsics_pixels"])
    seg = np.stack([file_io.read_png(scene / f"cam1_segmentation_{t:05d}.png")[..., 0]
                    for t in range(FRAMES)])
    rgb = np.stack([file_io.read_png(scene / f"cam1_rgba_{t:05d}.png")[..., :3]
                    for t in range(FRAMES)]).astype(float)
    rgb0 = np.stack([file_io.read_png(scene / f"rgba_{t:05d}.png")[..., :3]
                     for t in range(FRAMES)]).astype(float)
    flow = file_io.read_layer(scene, "cam1_forward_flow", formats=stored_schema(scene).layers)
    summary = json.loads((out / "export.json").read_text())
    assert summary["camera"] == 1 and summary["camera_name"] == "cam1"
    davis = out / "DAVIS"
    root = meta["instances"][1]
    for t in range(FRAMES):
        ext = np.asarray(record["extrinsics_opencv"][t])
        world = np.loadtxt(davis / "CamerasWorld" / "Full-Resolution" / "seq" / f"{t:05d}.txt")
        assert np.allclose(world[:3], ext[:3], atol=1e-8)
        assert np.allclose(world[3], [k[0, 0], k[1, 1], k[0, 2] - 0.5, k[1, 2] - 0.5])
        pose = np.eye(4)
        pose[:3, :3] = _rotation_wxyz(root["quaternions"][t])
        pose[:3, 3] = root["positions"][t]
        obj = np.loadtxt(davis / "Cameras" / "Full-Resolution" / "seq" / f"{t:05d}.txt")
        assert np.allclose(obj[:3], (ext @ pose)[:3], atol=1e-6)
        mask = file_io.read_png(davis / "Annotations" / "Full-Resolution" / "seq" / f"{t:05d}.png")
        assert np.array_equal(mask[..., 0], np.where(np.isin(seg[t], [1, 2]), 128, 0))
        image = np.asarray(Image.open(davis / "JPEGImages" / "Full-Resolution" / "seq"
                                      / f"{t:05d}.jpg"), float)
        assert np.abs(image - rgb[t]).mean() < np.abs(image - rgb0[t]).mean() / 2
    assert np.isin(seg, [1, 2]).any() and not np.array_equal(
        seg, np.stack([file_io.read_png(scene / f"segmentation_{t:05d}.png")[..., 0]
                       for t in range(FRAMES)]))
    fw = decode_pfm((davis / "FlowFW" / "Full-Resolution" / "seq" / "flo-00000.pfm").read_bytes())
    assert np.allclose(fw[..., 0], flow[0, ..., 1]) and np.allclose(fw[..., 1], flow[0, ..., 0])


def test_lasr_camera_out_of_range_is_one_line(exported, tmp_path):
    _, scenes = exported
    for name, camera, allowed in (("random", 3, "allowed: 0..2 (cam0, cam1, cam2)"),
                                  ("mono", 1, "allowed: 0..0")):
        proc = kubric("export", "lasr", scenes[name], "--out", tmp_path / "lasr",
                      "--camera", camera)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
        assert f"camera {camera} is not a camera of this scene; {allowed}" in proc.stderr
        assert not (tmp_path / "lasr").exists()
    with pytest.raises(UsageError, match=r"camera -1 is not a camera of this scene; allowed: "
                       r"0\.\.2"):
        exporter("lasr")(scenes["random"], tmp_path / "lasr", camera=-1)
    assert not (tmp_path / "lasr").exists()
