"""MOVi-A with ``rolling_shutter=d`` through the worker (raycast backend, bpy blocked): the
duration recorded in metadata, the tracks at their rows' times (projected here with OpenCV from
the recorded camera, interpolated at the solved time), packed as ``movi_a_rolling_shutter`` and
loaded; a rolling shutter with motion blur or depth of field is refused in one line."""

import json
import os
import pathlib
import subprocess
import sys

import pytest

from kubric.pipeline import OptionError, get_recipe

pytest.importorskip("embreex")
ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
D = 0.6


def _kubric(*args):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, (args, proc.stdout[-2000:], proc.stderr[-3000:])
    return proc


def test_rolling_shutter_with_motion_blur_or_dof_is_refused_in_one_line():
    get_recipe("movi_a").from_assignments(["rolling_shutter=0.5"])  # blender: Cycles + raycast
    with pytest.raises(OptionError, match=r"^movi_f: option rolling_shutter=0.5 with "
                                          r"max_motion_blur=2.0: no renderer renders both"):
        get_recipe("movi_f").from_assignments(["rolling_shutter=0.5"])
    with pytest.raises(OptionError, match=r"rolling_shutter=0.5 with dof=True"):
        get_recipe("movi_a").from_assignments(["rolling_shutter=0.5", "dof=True"])


def test_movi_a_rolling_shutter_records_packs_and_loads(tmp_path):
    from kubric.datasets import load
    _kubric("worker", "movi_a", "--seed", 3, "--out", tmp_path / "scenes", "--set",
            "resolution=32", "--set", "frame_end=3", "--set", "renderer=raycast", "--set",
            "max_num_objects=3", "--set", f"rolling_shutter={D}", "--set", "tracks=40")
    scene = tmp_path / "scenes" / "scene_00000003"
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["metadata"]["rolling_shutter"]["duration"] == D
    from kubric.docgen import undocumented_scene_fields
    assert undocumented_scene_fields(scene) == []
    _kubric("pack", tmp_path / "scenes", "--out", tmp_path / "ds", "--splits", "train=1",
            "--schema", "movi_a_rolling_shutter", "--verify", "--no-progress")
    example = load(tmp_path / "ds", "train")[0]
    assert example["camera"]["rolling_shutter_duration"] == pytest.approx(D)
