"""An 8-scene pack with the default splits (train 0.9, validation 0.1): no seed of 0..7 falls into
validation. `kubric pack` says so, `kubric datasets info` lists the split with 0 examples, and
`load(..., "validation")` is an empty split (not "no such split"); the scenes all went to train."""

import pathlib
import subprocess
import sys

import pytest

from kubric.datasets import load
from kubric.datasets.layout import DatasetError

ROOT = pathlib.Path(__file__).resolve().parents[1]


def kubric(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_a_split_without_scenes_is_reported_and_loads_empty(tmp_path):
    scenes, ds = tmp_path / "scenes", tmp_path / "ds"
    kubric("generate", "bench", "--out", str(scenes), "--scenes", "8", "--no-progress")
    packed = kubric("pack", str(scenes), "--out", str(ds), "--no-progress")
    assert "(train: 8, validation: 0)" in packed
    assert "split 'validation' got no scene" in packed and "loads as an empty split" in packed
    info = kubric("datasets", "info", str(ds))
    row = next(line for line in info.splitlines() if line.strip().startswith("validation"))
    assert row.split()[1] == "0" and "empty split" in row

    validation = load(ds, "validation")
    assert len(validation) == 0 and validation.scenes == []
    with pytest.raises(IndexError):
        validation[0]
    train = load(ds, "train")
    assert sorted(train.scenes) == sorted(p.name for p in scenes.glob("scene_*"))
    with pytest.raises(DatasetError, match=r"no split 'test' \(splits: train, validation\)"):
        load(ds, "test")
