"""The LASR export without a render: PFM files, the occlusion rule on flows whose occlusions are
known by construction, the camera files against Kubric's camera geometry, and the exported tree
of a synthetic scene directory."""

from __future__ import annotations

import json

import numpy as np
import pytest

import kubric as kb
from kubric.core import camera_geometry as geo
from kubric.datasets.exports import lasr as lx
from kubric.io.layers import write_image_dict
from kubric.io.pfm_io import decode_pfm, encode_pfm, read_pfm, write_pfm


@pytest.mark.parametrize("shape", [(5, 7, 3), (5, 7), (1, 1)])
def test_pfm_round_trip_and_layout(tmp_path, shape):
    data = np.random.RandomState(0).normal(size=shape).astype(np.float32)
    write_pfm(data, tmp_path / "a.pfm")
    np.testing.assert_array_equal(read_pfm(tmp_path / "a.pfm"), data)
    raw = encode_pfm(data)
    kind = b"PF" if len(shape) == 3 else b"Pf"
    header = kind + f"\n{shape[1]} {shape[0]}\n-1.0\n".encode()
    assert raw.startswith(header)
    # samples are little-endian float32, bottom row first
    first_row = np.frombuffer(raw[len(header):], "<f4")[:shape[1] * (3 if len(shape) == 3 else 1)]
    np.testing.assert_array_equal(first_row, data[-1].ravel())


def test_pfm_big_endian_and_bad_files():
    data = np.arange(6, dtype=np.float32).reshape(2, 3)
    big = b"Pf\n3 2\n1.0\n" + data[::-1].astype(">f4").tobytes()
    np.testing.assert_array_equal(decode_pfm(big), data)
    for bad, needle in ((b"P6\n3 2\n-1\n" + bytes(24), "PF or Pf"), (big[:-4], "samples"),
                        (b"Pf\n3 x\n-1\n", "size"), (b"Pf\n3 2", "truncated")):
        with pytest.raises(ValueError, match=needle):
            decode_pfm(bad)
    with pytest.raises(ValueError, match="finite"):
        encode_pfm(np.array([[np.nan]]))
    with pytest.raises(ValueError, match="shape"):
        encode_pfm(np.zeros((2, 2, 2)))


def test_flow_swaps_channels_and_carries_validity():
    flow = np.random.RandomState(1).normal(size=(4, 5, 2)).astype(np.float32)
    valid = np.zeros((4, 5), bool)
    valid[1, 2] = True
    out = lx.lasr_flow(flow, valid)
    np.testing.assert_array_equal(out[..., 0], flow[..., 1])  # Δx = Δcol
    np.testing.assert_array_equal(out[..., 1], flow[..., 0])  # Δy = Δrow
    np.testing.assert_array_equal(out[..., 2], valid.astype(np.float32))


def _square_scene():
    """A static wall (label 0, hit everywhere) and a 5×5 square (label 1) moving 3 px right;
    a 2×2 square (label 2) at the right border moving 4 px out of the image."""
    h, w = 20, 20
    fw = np.zeros((h, w, 2))
    bw = np.zeros((h, w, 2))
    lab0, lab1 = np.zeros((h, w), int), np.zeros((h, w), int)
    lab0[5:10, 5:10] = 1
    fw[5:10, 5:10] = (0, 3)
    lab1[5:10, 8:13] = 1
    bw[5:10, 8:13] = (0, -3)
    lab0[2:4, 17:19] = 2
    fw[2:4, 17:19] = (0, 4)
    hit = np.ones((h, w), bool)
    return fw, bw, lab0, lab1, hit


def test_occlusion_of_a_moving_square_is_exactly_what_it_covers_or_leaves():
    fw, bw, lab0, lab1, hit = _square_scene()
    occ = lx.flow_occlusion(fw, bw, lab0, lab1, hit, hit)
    expected = np.zeros_like(hit)
    expected[5:10, 10:13] = True  # wall the square moves over
    expected[2:4, 17:19] = True  # the small square: target col ≥ 20, outside the image
    np.testing.assert_array_equal(occ, expected)
    back = lx.flow_occlusion(bw, fw, lab1, lab0, hit, hit)
    expected = np.zeros_like(hit)
    expected[5:10, 5:8] = True  # wall uncovered by the square: was behind it
    expected[2:4, 17:19] = True  # wall uncovered by the small square
    np.testing.assert_array_equal(back, expected)
    # pixels that hit nothing are never occluded
    none = ~hit
    assert not lx.flow_occlusion(fw, bw, lab0, lab1, none, hit).any()


def test_self_occlusion_within_one_label_is_caught_by_the_backward_check():
    """Two halves of one label: the left half slides 4 px over the right half (e.g. a part of
    a surface turning behind another): same label at the target, flows disagree."""
    h, w = 10, 20
    fw, bw = np.zeros((h, w, 2)), np.zeros((h, w, 2))
    lab = np.zeros((h, w), int)
    lab[:, 4:16] = 1
    fw[:, 4:10] = (0, 4)
    bw[:, 8:14] = (0, -4)  # at t+1 the left half covers cols 8..13
    occ = lx.flow_occlusion(fw, bw, lab, lab, np.ones((h, w), bool), np.ones((h, w), bool))
    expected = np.zeros((h, w), bool)
    expected[:, 10:14] = True  # right-half pixels whose (static) target is now covered
    np.testing.assert_array_equal(occ, expected)


def test_camera_files_project_as_kubric_cameras_with_integer_pixel_centres():
    scene = kb.Scene(resolution=(64, 48))
    camera = kb.PerspectiveCamera(focal_length=35.0, sensor_width=32.0, position=(3, -4, 2),
                                  shift_x=0.05)
    camera.look_at((0.2, 0.1, 0.3))
    scene.camera = camera
    points = np.random.RandomState(2).uniform(-0.5, 0.5, size=(50, 3))
    xy, _ = geo.project_to_pixels(camera, points)
    k = geo.pixel_intrinsics(camera)
    world = lx.rtk_matrix(lx.opencv_world_to_camera(camera.matrix_world), k)
    np.testing.assert_allclose(lx.project_rtk(world, points), xy - 0.5, atol=1e-9)
    q = kb.Quaternion(axis=(1, 2, 3), angle=0.7)
    pose = lx.pose_matrix((0.3, -0.2, 0.1), q)
    local = (points - pose[:3, 3]) @ pose[:3, :3]
    obj = lx.rtk_matrix(lx.opencv_world_to_camera(camera.matrix_world) @ pose, k)
    np.testing.assert_allclose(lx.project_rtk(obj, local), xy - 0.5, atol=1e-9)
    np.testing.assert_allclose(obj[:3, :3] @ obj[:3, :3].T, np.eye(3), atol=1e-12)


def _synthetic_scene(path, two_roots=False):
    fw, bw, lab0, lab1, hit = _square_scene()
    t, h, w = 3, 20, 20
    seg = np.stack([lab0, lab1, lab0])[..., None].astype(np.uint32)
    layers = {"rgba": np.full((t, h, w, 4), 200, np.uint8),
              "depth": np.where(seg > 0, 5.0, 9.0).astype(np.float32),
              "segmentation": seg,
              "forward_flow": np.stack([fw, np.zeros_like(fw), fw]).astype(np.float32),
              "backward_flow": np.stack([bw, bw, bw]).astype(np.float32)}
    path.mkdir()
    write_image_dict(layers, path)
    pose = {"positions": [[0.0, 0.0, 0.0]] * t, "quaternions": [[1.0, 0.0, 0.0, 0.0]] * t}
    link = {} if two_roots else {"articulated_link": "arm"}
    meta = {"flags": {"recipe": "toy", "seed": 7},
            "camera": {"matrices_world": [np.eye(4).tolist()] * t,
                       "intrinsics_pixels": [[20.0, 0, 10.0], [0, 20.0, 10.0], [0, 0, 1]]},
            "instances": [dict(pose), dict(pose, **link)]}
    (path / "metadata.json").write_text(json.dumps(meta))
    return layers


def test_export_writes_the_lasr_tree(tmp_path):
    layers = _synthetic_scene(tmp_path / "scene")
    summary = lx.export_lasr(tmp_path / "scene", tmp_path / "lasr")
    seq = "toy_00000007"
    assert summary["sequence"] == seq and summary["root_instance"] == 0
    files = sorted(str(p.relative_to(tmp_path / "lasr")) for p in (tmp_path / "lasr").rglob("*")
                   if p.is_file())
    want = [f"configs/{seq}.config", "export.json"]
    for i in range(3):
        want += [f"DAVIS/{k}/Full-Resolution/{seq}/{i:05d}.{e}" for k, e in
                 (("JPEGImages", "jpg"), ("Annotations", "png"), ("Cameras", "txt"),
                  ("CamerasWorld", "txt"))]
    for kind, frames in (("FlowFW", (0, 1)), ("FlowBW", (1, 2))):
        want += [f"DAVIS/{kind}/Full-Resolution/{seq}/{n}-{i:05d}.pfm" for i in frames
                 for n in ("flo", "occ")]
    assert files == sorted(want)
    assert not list(tmp_path.glob(".lasr*"))  # no temporary folder left
    folder = tmp_path / "lasr" / "DAVIS" / "FlowFW" / "Full-Resolution" / seq
    occ = read_pfm(folder / "occ-00000.pfm")
    assert occ.sum() == 15 + 4 == summary["occluded_pixels"]["FlowFW"][0]
    flo = read_pfm(folder / "flo-00000.pfm")
    np.testing.assert_allclose(flo[..., 0], layers["forward_flow"][0, ..., 1], atol=1e-4)
    np.testing.assert_array_equal(flo[..., 2], 1 - occ)  # every pixel hits a surface here
    with pytest.raises(FileExistsError):
        lx.export_lasr(tmp_path / "scene", tmp_path / "lasr")


def test_export_refuses_bad_instances_and_ambiguous_roots(tmp_path):
    _synthetic_scene(tmp_path / "scene", two_roots=True)
    with pytest.raises(ValueError, match="pass root="):
        lx.export_lasr(tmp_path / "scene", tmp_path / "a")
    with pytest.raises(ValueError, match="instances"):
        lx.export_lasr(tmp_path / "scene", tmp_path / "b", instances=[5])
    with pytest.raises(ValueError, match="sequence name"):
        lx.export_lasr(tmp_path / "scene", tmp_path / "c", root=1, sequence="../x")
    lx.export_lasr(tmp_path / "scene", tmp_path / "d", instances=[1])  # one instance: its root
    assert json.loads((tmp_path / "d" / "export.json").read_text())["root_instance"] == 1
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())


def test_command_line(tmp_path):
    """``kubric export lasr``: the export, then one error line each (exit 2) for an existing
    output, a missing scene and a bad --instances."""
    import subprocess
    import sys

    def kubric(*args):
        return subprocess.run([sys.executable, "-m", "kubric", "export", "lasr", *map(str, args)],
                              capture_output=True, text=True, timeout=120)

    _synthetic_scene(tmp_path / "scene")
    ok = kubric(tmp_path / "scene", "--out", tmp_path / "o", "--instances", "0,1",
                "--sequence", "clip")
    assert ok.returncode == 0, ok.stderr
    assert "wrote LASR sequence clip (3 frames)" in ok.stdout
    assert (tmp_path / "o" / "configs" / "clip.config").is_file()
    for args, says, code in (((tmp_path / "scene", "--out", tmp_path / "o"), "already exists", 2),
                             ((tmp_path / "nowhere", "--out", tmp_path / "p"), "nowhere", 1),
                             ((tmp_path / "scene", "--out", tmp_path / "q", "--instances", "a"),
                              "--instances 'a'", 2)):
        bad = kubric(*args)
        lines = bad.stderr.strip().splitlines()
        assert bad.returncode == code and len(lines) == 1, bad.stderr  # docs/exit-codes.md
        assert lines[0].startswith("kubric export lasr: error: ") and says in lines[0]
