"""Point tracks through the dataset pipeline: MOVi-A with tracks=N → `kubric pack --schema
movi_a_tracks` → the `point_tracks` task gives exactly the tracks.npz of each scene."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from kubric.annotations.track_files import read_tracks
from kubric.datasets import load

pytestmark = pytest.mark.blender
ROOT = Path(__file__).resolve().parents[1]
OPTIONS = ["resolution=64", "frame_end=3", "samples=2", "denoise=false", "min_num_objects=3",
           "max_num_objects=4", "tracks=24"]


def _kubric(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc


def test_point_tracks_task_reads_the_scenes_tracks(tmp_path):
    scenes, out = tmp_path / "scenes", tmp_path / "ds"
    args = ["generate", "movi_a", "--out", scenes, "--scenes", 2, "--workers", 2, "--no-progress"]
    for option in OPTIONS:
        args += ["--set", option]
    _kubric(*args)
    _kubric("pack", scenes, "--out", out, "--schema", "movi_a_tracks", "--splits", "train=1",
            "--no-progress", "--verify")
    source = load(out, "train", task="point_tracks")
    assert len(source) == 2
    for item in (source[0], source[1]):
        expect = read_tracks(scenes / str(item["video_name"]) / "tracks.npz")
        np.testing.assert_array_equal(item["query_points"], expect["query_points"])
        np.testing.assert_array_equal(item["target_points"], expect["target_points"])
        np.testing.assert_array_equal(item["occluded"], expect["occluded"])
        assert item["video"].shape == (3, 64, 64, 3) and item["video"].dtype == np.uint8
        assert item["target_points"].shape == (24, 3, 2)


def test_packing_without_tracks_under_a_tracks_schema_reports_the_scene(tmp_path):
    scenes = tmp_path / "scenes"
    args = ["generate", "movi_a", "--out", scenes, "--scenes", 1, "--no-progress"]
    for option in OPTIONS[:-1]:
        args += ["--set", option]
    _kubric(*args)
    proc = subprocess.run([sys.executable, "-m", "kubric", "pack", str(scenes), "--out",
                           str(tmp_path / "ds"), "--schema", "movi_a_tracks", "--splits",
                           "train=1", "--no-progress"], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode != 0
    assert "tracks.npz" in proc.stderr + proc.stdout
    assert not (tmp_path / "ds").exists()
