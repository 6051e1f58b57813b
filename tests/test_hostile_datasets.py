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


@pytest.mark.slow  # torch and grain imports: ~25 s
def test_item0_readers_survive_fork_after_parent_read(dataset):
    code = FORK_SCRIPT.format(tests=str(pathlib.Path(__file__).parent), ds=str(dataset))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    seen, grain_seen, first = run.stdout.strip().splitlines()[-1].rsplit(" ", 1)[0], None, None
    expected = [int(s.split("_")[1]) for s in load(dataset, "train").scenes]
    assert run.stdout.strip().splitlines()[-1] == f"{expected} {sorted(expected)} {expected[0]}"


# ---------------------------------------------------------------- item 1
def corrupt_a_shard(name):
    """KUBRIC_FAULT_CALL target: flip one byte of the first shard (between pack and verify)."""
    work = pathlib.Path(os.environ["HOSTILE_WORK"])
    shard = sorted(work.glob("*.array_record-*"))[0]
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF
    shard.write_bytes(bytes(data))


def change_a_scene(name):
    """KUBRIC_FAULT_CALL target: change one scene's metadata after its example was packed."""
    meta = pathlib.Path(os.environ["HOSTILE_SCENE"]) / "metadata.json"
    data = json.loads(meta.read_text())
    data["metadata"]["seed"] = 999
    meta.write_text(json.dumps(data))


@pytest.mark.parametrize("fault", ["corrupt_a_shard", "change_a_scene"])
def test_item1_failed_verify_leaves_no_dataset(scenes, tmp_path, fault):
    mine = tmp_path / "scenes"
    shutil.copytree(scenes, mine)
    out = tmp_path / "ds"
    env = {"KUBRIC_FAULT": "pack.finalised:call",
           "KUBRIC_FAULT_CALL": f"test_hostile_datasets:{fault}",
           "HOSTILE_WORK": str(tmp_path / ".ds.incomplete"),
           "HOSTILE_SCENE": str(mine / "scene_00000002")}
    run = kubric("pack", mine, "--out", out, "--verify", "--splits", "train=1",
                 "--examples-per-shard", "2", "--no-progress", env=env)
    assert run.returncode == 1, run.stderr
    assert "nothing was written to" in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert not out.exists() and not list(tmp_path.glob(".ds*"))
    info = kubric("datasets", "info", out)
    assert info.returncode != 0 and "is not a directory" in info.stderr


# ---------------------------------------------------------------- item 2
def test_item2_kill_during_final_renames_never_poisons(scenes, tmp_path, dataset):
    out = tmp_path / "ds"
    run = kubric("pack", scenes, "--out", out, "--splits", "train=1", "--examples-per-shard",
                 "2", "--no-progress", env={"KUBRIC_FAULT": "pack.shard_renamed:kill"})
    assert run.returncode == -9
    assert not out.exists()
    work = tmp_path / ".ds.incomplete"
    assert work.is_dir() and not (work / "progress.json").exists()  # no record of moved files
    again = kubric("pack", scenes, "--out", out, "--splits", "train=1", "--examples-per-shard",
                   "2", "--no-progress")
    assert again.returncode == 0, again.stderr
    assert tree(out) == tree(dataset)
    assert not work.exists()


def test_item2_a_record_naming_missing_files_is_not_trusted(scenes, tmp_path, dataset):
    out = tmp_path / "ds"
    run = kubric("pack", scenes, "--out", out, "--splits", "train=1", "--examples-per-shard",
                 "2", "--no-progress", env={"KUBRIC_FAULT": "pack.before_swap:kill"})
    assert run.returncode == -9
    work = tmp_path / ".ds.incomplete"
    # an older kubric's order: the record survived the renames. Put one back, naming a part file.
    (work / "progress.json").write_text(json.dumps({"plan": "x", "shards": {"train": [
        {"file": "test_hostile-train.part-00000", "scenes": ["scene_00000000"]}]}}))
    again = pack(scenes, out, **KW)
    assert sum(again.counts.values()) == 6 and tree(out) == tree(dataset)


def test_item2_item10_second_pack_on_one_output_refuses(scenes, tmp_path):
    out = tmp_path / "ds"
    from kubric.datasets import packer
    with packer.output_lock(out):
        run = kubric("pack", scenes, "--out", out, "--splits", "train=1", "--no-progress")
    assert run.returncode == 2
    assert "is being written by another run (pid " in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1 and not out.exists()
    assert not (tmp_path / ".ds.lock").exists()  # released and removed


# ---------------------------------------------------------------- item 4, 11 (.old)
def test_item4_overwrite_touches_only_packer_files(scenes, tmp_path, dataset):
    out = tmp_path / "ds"
    shutil.copytree(dataset, out)
    (out / "NOTES.txt").write_text("mine")
    (out / "results").mkdir()
    run = kubric("pack", scenes, "--out", out, "--overwrite", "--splits", "train=1",
                 "--no-progress")
    assert run.returncode == 2 and "NOTES.txt, results, which kubric pack did not write" in \
        run.stderr
    assert (out / "NOTES.txt").read_text() == "mine" and (out / "results").is_dir()
    (out / "NOTES.txt").unlink()
    (out / "results").rmdir()
    # a kill between moving the old dataset aside and the new one in: the next run cleans up
    run = kubric("pack", scenes, "--out", out, "--overwrite", "--splits", "train=1",
                 "--examples-per-shard", "3", "--no-progress",
                 env={"KUBRIC_FAULT": "pack.old_moved:kill"})
    assert run.returncode == -9 and (tmp_path / ".ds.old").is_dir()
    again = kubric("pack", scenes, "--out", out, "--overwrite", "--splits", "train=1",
                   "--examples-per-shard", "3", "--no-progress")
    assert again.returncode == 0, again.stderr
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    assert load(out, "train").info["shard_lengths"]["train"] == [3, 3]


# ---------------------------------------------------------------- item 5
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGKILL"])
def test_item5_pool_workers_end_with_the_parent(scenes, tmp_path, sig):
    import signal
    import time
    proc = popen("pack", scenes, "--out", tmp_path / "ds", "--workers", "2", "--splits",
                 "train=1", "--no-progress", stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 env={"KUBRIC_FAULT": "pack.encode_scene:sleep", "KUBRIC_FAULT_SLEEP": "2"})
    children = _wait_children(proc.pid, 3)
    os.kill(proc.pid, getattr(signal, sig))
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail(f"kubric pack did not end within 20 s of {sig}")
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(c) for c in children):
        time.sleep(0.1)
    assert not [c for c in children if _alive(c)], f"orphans after {sig}"
    assert not (tmp_path / "ds").exists()


def _wait_children(pid, count, timeout=60):
    import time
    import psutil
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        kids = psutil.Process(pid).children(recursive=True)
        if len(kids) >= count:
            time.sleep(0.5)
            return [k.pid for k in psutil.Process(pid).children(recursive=True)]
        time.sleep(0.1)
    pytest.fail(f"pack made only {len(kids)} child processes")


def _alive(pid):
    from kubric.pipeline.cleanup import pid_alive
    return pid_alive(pid)
