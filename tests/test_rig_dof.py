"""Depth of field on a camera rig (Cycles): every camera has the reference's thin lens.

* Real output: a white plate seen by the *right* camera of a stereo rig whose reference camera
  has depth of field; the right image's edge blur is the disk of the defocus diameter computed by
  hand (the f-number, focus distance and the plate's z-depth), centred where the plate's pinhole
  image lies in the right camera (shifted by the disparity fx·B/Z) — without the lens copied to
  the rig's cameras the edge would be sharp.
* The recipe: a stereo MOVi-A scene with ``dof=true`` writes the right camera's ``defocus``
  layer, equal to the thin-lens formula on its own ``z`` layer (by hand), and packs it.
"""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from test_exposure_blender import PLATE_LENS, _disk_cdf, _linear, plate_scene

from kubric import file_io
from kubric.core import rig as rigs

ROOT = pathlib.Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.blender
pytest.importorskip("embreex")


def test_the_right_camera_renders_the_reference_s_depth_of_field():
    from kubric.renderer.blender import Blender
    scene, baseline = plate_scene(), 0.1
    w, h, f_mm, sw, fstop, focus = (*scene.resolution, *PLATE_LENS)
    rig = rigs.stereo(scene.camera, baseline)
    rig.build(scene)
    scene.camera = rig.cameras["right"]
    out = Blender(scene, samples_per_pixel=128, use_denoising=False).render(
        return_layers=("rgba", "z"))
    row = _linear(out["rgba"][0, h // 2, :, 0])
    z = 2.0 - 0.251
    fx = f_mm / sw * w
    d_expected = f_mm * 1e-3 / fstop * abs(1 / z - 1 / focus) * fx  # by hand
    a = 0.25 / z * fx  # the plate's pinhole half-width, px
    centre = -fx * baseline / z  # its centre in the right image, px from the image centre
    x = np.arange(w) + 0.5 - w / 2 - centre

    def profile(d):
        r = d / 2
        return _disk_cdf((a - x) / r) - _disk_cdf((-a - x) / r)

    candidates = np.linspace(0.5 * d_expected, 1.5 * d_expected, 101)
    best = candidates[int(np.argmin([np.abs(row - profile(d)).mean() for d in candidates]))]
    assert abs(best - d_expected) < 0.08 * d_expected, (best, d_expected)
    assert np.abs(row - profile(d_expected)).max() < 0.1
    sharp = np.abs(row - profile(0.05)).max()  # a pinhole's edge: far from what was rendered
    assert sharp > 0.3, sharp


def test_a_stereo_movi_scene_writes_the_right_camera_s_defocus(tmp_path):
    from kubric.datasets import load, pack
    from kubric.io.stored_schema import stored_schema
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "5", "--out",
           str(tmp_path / "scenes")]
    for option in ("resolution=24x16", "frame_end=2", "cameras=stereo", "baseline=0.4",
                   "max_num_objects=3", "dof=true", "quality=draft"):
        cmd += ["--set", option]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene = tmp_path / "scenes" / "scene_00000005"
    meta = json.loads((scene / "metadata.json").read_text())
    lens = meta["metadata"]["depth_of_field"]
    formats = stored_schema(scene).layers
    z = file_io.read_layer(scene, "right_z", formats=formats).astype(np.float64)
    got = file_io.read_layer(scene, "right_defocus", formats=formats)
    fx = np.asarray(meta["camera"]["rig"]["views"]["right"]["intrinsics_pixels"])[0, 0]
    f_m = meta["camera"]["focal_length"] * 1e-3
    s = lens["focus_distance"]
    expected = f_m / lens["aperture_fstop"] * np.abs(1 / z - 1 / s) * fx  # by hand
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5)
    pack(tmp_path / "scenes", tmp_path / "ds", splits={"train": 1})
    example = load(tmp_path / "ds", "train")[0]
    np.testing.assert_array_equal(example["cameras"]["right"]["defocus"], got)
