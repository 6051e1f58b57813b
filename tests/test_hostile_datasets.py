"""Round-two hostile tests (issue #27) of packing and loading, on tiny toy scenes (no rendering).
Each test names the issue's item it covers."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from hostile_fixtures import NAME, Tiny, kubric, make_scenes, popen, tree  # noqa: F401
from kubric.datasets import DatasetError, load, pack

KW = dict(splits="train=1", examples_per_shard=2, progress=False)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    return make_scenes(tmp_path_factory.mktemp("hostile") / "scenes", 6)


@pytest.fixture(scope="module")
def dataset(scenes, tmp_path_factory):
    out = tmp_path_factory.mktemp("hostile_ds") / "ds"
    pack(scenes, out, **KW)
    return out


# ---------------------------------------------------------------- item 0
FORK_SCRIPT = """
import sys, torch
sys.path.insert(0, {tests!r})
import hostile_fixtures
from kubric.datasets import load
from kubric.datasets.adapters import to_torch
src = load({ds!r}, "train")
first = src[0]                      # the parent reads first: its reader is open
loader = torch.utils.data.DataLoader(to_torch(src), num_workers=2, batch_size=None)
assert torch.multiprocessing.get_start_method() == "fork"
seen = [int(ex["metadata"]["seed"]) for ex in loader]
import grain.python as grain
g = grain.MapDataset.source(src).to_iter_dataset(
    grain.ReadOptions(num_threads=1)).mp_prefetch(grain.MultiprocessingOptions(num_workers=2))
grain_seen = sorted(int(ex["metadata"]["seed"]) for ex in g)
print(seen, grain_seen, int(first["metadata"]["seed"]))
"""


def test_item0_readers_survive_fork_after_parent_read(dataset):
    code = FORK_SCRIPT.format(tests=str(pathlib.Path(__file__).parent), ds=str(dataset))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    seen, grain_seen, first = run.stdout.strip().splitlines()[-1].rsplit(" ", 1)[0], None, None
    expected = [int(s.split("_")[1]) for s in load(dataset, "train").scenes]
    assert run.stdout.strip().splitlines()[-1] == f"{expected} {sorted(expected)} {expected[0]}"
