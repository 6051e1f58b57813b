"""MOVi-F with the exposure options end to end: ``dof=True`` and ``coverage_samples=K`` through the
worker (Blender), recorded in metadata, packed as ``movi_f_dof`` / ``movi_f_coverage`` and loaded;
the packed values are checked against the scene's own camera and z layer and against the
coverage's definition."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

pytestmark = [pytest.mark.blender, pytest.mark.slow]
pytest.importorskip("embreex")

ROOT = pathlib.Path(__file__).resolve().parents[1]
OPTIONS = ["samples=1", "denoise=false", "resolution=24", "frame_end=2", "min_num_objects=1",
           "max_num_objects=2", "max_num_dynamic=2", "dof=true", "min_fstop=2", "max_fstop=2.5",
           "coverage_samples=4", "max_motion_blur=1.5", "events=true"]


def _kubric(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, (args, proc.stdout[-2000:], proc.stderr[-3000:])


def test_movi_f_with_dof_and_coverage_packs_and_loads(tmp_path):
    from kubric.datasets import load
    from kubric.io.layers import read_layer
    sets = [a for o in OPTIONS for a in ("--set", o)]
    _kubric("worker", "movi_f", "--seed", 5, "--out", tmp_path / "scenes", *sets)
    scene = tmp_path / "scenes" / "scene_00000005"
    meta = json.loads((scene / "metadata.json").read_text())
    from kubric.docgen import undocumented_scene_fields
    assert undocumented_scene_fields(scene) == []  # docs/scene-format.md names every new file
    lens = meta["metadata"]["depth_of_field"]
    assert lens["use_dof"] and 2 <= lens["aperture_fstop"] <= 2.5
    assert 6 <= lens["focus_distance"] <= 14
    blur = meta["metadata"]["motion_blur"]
    cam = meta["camera"]
    # the defocus layer from the z layer and the recorded lens, by hand
    z = read_layer(scene, "z")
    f = cam["focal_length"]
    want = f * 1e-3 / lens["aperture_fstop"] * np.abs(1 / z - 1 / lens["focus_distance"]) \
        * f / cam["sensor_width"] * 24
    got = read_layer(scene, "defocus")
    np.testing.assert_allclose(got, want, rtol=1e-4)
    for variant in ("movi_f_dof", "movi_f_coverage", "movi_f_events"):
        _kubric("pack", tmp_path / "scenes", "--out", tmp_path / variant, "--splits", "train=1",
                "--schema", variant, "--verify")
    dof = load(tmp_path / "movi_f_dof", "train")[0]
    np.testing.assert_allclose(dof["defocus"], got, rtol=1e-6)
    assert dof["camera"]["aperture_fstop"] == pytest.approx(lens["aperture_fstop"], rel=1e-6)
    assert dof["camera"]["focus_distance"] == pytest.approx(lens["focus_distance"], rel=1e-6)
    example = load(tmp_path / "movi_f_coverage", "train")[0]
    cov = example["coverage"]
    assert int(cov["num_samples"]) == 4 and cov["shutter"] == pytest.approx(blur, rel=1e-6)
    # every pixel's counts sum to K over its labels
    t, h, w = example["segmentations"].shape[:3]
    total = np.zeros((t, h, w), np.int64)
    np.add.at(total, (cov["frame"], cov["y"], cov["x"]), cov["count"])
    assert (total == 4).all()
    assert cov["label"].max() <= len(meta["instances"])
    # the exposure flow packs as upstream's flows do (uint16 over the scene's range)
    lo, hi = example["metadata"]["exposure_flow_range"]
    unpacked = example["exposure_flow"] / 65535 * (hi - lo) + lo
    np.testing.assert_allclose(unpacked, read_layer(scene, "exposure_flow"),
                               atol=(hi - lo) / 65535 + 1e-6)
    # events.h5 from raycast sub-frames anchored at the Cycles frames (the default): between
    # frames, polarity × threshold sums to the change of log luminance of the RGB files
    # (decoded here) within one threshold
    from kubric.io.event_h5 import read_events
    events, sensor = read_events(scene), meta["metadata"]["event_camera"]
    assert sensor["source"] == "raycast sub-frames K=8, anchored at the rendered frames"
    assert sensor["num_events"] == len(events["t"])
    rgb = read_layer(scene, "rgba")[..., :3].astype(np.float64) / 255
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    log_i = np.log(linear @ [0.2126, 0.7152, 0.0722] + sensor["eps"])
    c_pos, c_neg = events["contrast_thresholds"]
    sign = np.where(events["p"] == 1, c_pos[events["y"], events["x"]],
                    -c_neg[events["y"], events["x"]])
    total = np.zeros((h, w))
    np.add.at(total, (events["y"], events["x"]), sign)  # frames 1 → 2: all events
    within = np.abs(total - (log_i[1] - log_i[0])) <= np.maximum(c_pos, c_neg)
    assert within.mean() >= 0.95 and len(events["t"]) > 0
    packed = load(tmp_path / "movi_f_events", "train")[0]["event_stream"]
    for key in ("x", "y", "t", "p"):
        np.testing.assert_array_equal(packed[key], events[key])
    np.testing.assert_array_equal(packed["contrast_thresholds"], events["contrast_thresholds"])
