"""Round-two hostile tests (issue #27) of packing and loading, on tiny toy scenes (no rendering).
Each test names the issue's item it covers."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

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
    assert run.returncode == 3
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
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGKILL", "Ctrl-C"])
def test_item5_pool_workers_end_with_the_parent(scenes, tmp_path, sig):
    """Ctrl-C: SIGINT to the whole process group, as a terminal sends it."""
    import signal
    import time
    proc = popen("pack", scenes, "--out", tmp_path / "ds", "--workers", "2", "--splits",
                 "train=1", "--no-progress", stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 env={"KUBRIC_FAULT": "pack.encode_scene:sleep", "KUBRIC_FAULT_SLEEP": "2"},
                 start_new_session=True)
    children = _wait_children(proc.pid, 3)
    if sig == "Ctrl-C":
        os.killpg(proc.pid, signal.SIGINT)
    else:
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


# ---------------------------------------------------------------- items 12, 16, 19
def _edit_meta(scene, edit):
    meta = scene / "metadata.json"
    meta.write_text(json.dumps(edit(json.loads(meta.read_text()))))


def test_item12_item16_bad_scenes_are_skipped_by_name(scenes, tmp_path):
    mine = tmp_path / "scenes"
    shutil.copytree(scenes, mine)
    _edit_meta(mine / "scene_00000000", lambda m: {**m, "metadata": {**m["metadata"],
                                                                      "seed": [4]}})
    _edit_meta(mine / "scene_00000001", lambda m: [])
    _edit_meta(mine / "scene_00000002", lambda m: {**m, "metadata": "x"})
    npz = mine / "scene_00000003" / "toy_points.npz"
    npz.write_bytes(npz.read_bytes()[:40])
    _edit_meta(mine / "scene_00000004", lambda m: {**m, "flags": {**m["flags"],
                                                                   "recipe": "movi_a"}})
    (mine / "scene_00000004" / "schema.json").unlink()  # an older movi_a scene: by its recipe
    run = kubric("pack", mine, "--out", tmp_path / "ds", "--splits", "train=1",
                 "--schema", NAME, "--no-progress")
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr + run.stdout
    lines = {ln.split("scene_0000000")[1][0]: ln for ln in run.stdout.splitlines()
             if "skipped corrupt scene" in ln}
    assert sorted(lines) == ["0", "1", "2", "3", "4"], run.stdout
    assert "seed [4] is not a whole number" in lines["0"]
    assert "is not a JSON object" in lines["1"]
    assert "'metadata' is not an object" in lines["2"]
    assert "toy_points.npz" in lines["3"]
    assert "is a scene of recipe 'movi_a', not of the dataset's schema 'test_hostile'" in \
        lines["4"]
    assert load(tmp_path / "ds", "train").scenes == ["scene_00000005"]


def test_item12_item17_full_disk_names_the_shard(scenes, tmp_path):
    run = kubric("pack", scenes, "--out", tmp_path / "ds", "--splits", "train=1",
                 "--no-progress", env={"KUBRIC_FAULT": "pack.shard_write:enospc"})
    assert run.returncode == 1, run.stderr
    line, = run.stderr.strip().splitlines()
    assert f"{tmp_path / '.ds.incomplete' / 'test_hostile-train.part-00000'}" in line
    assert "No space left on device" in line and "MiB free there" in line
    assert not (tmp_path / "ds").exists()


def test_item19_exit_status_usage_2_data_1(scenes, tmp_path):
    bad_option = kubric("pack", scenes, "--out", tmp_path / "ds", "--splits", "train=2")
    assert bad_option.returncode == 2
    empty = tmp_path / "empty"
    empty.mkdir()
    bad_data = kubric("pack", empty, "--out", tmp_path / "ds")
    assert bad_data.returncode == 1 and "holds no complete scene" in bad_data.stderr


# ---------------------------------------------------------------- items 14, 15
def test_item14_item15_loader_and_info_name_the_file(dataset, tmp_path):
    ds = tmp_path / "ds"
    shutil.copytree(dataset, ds)
    marker = json.loads((ds / "kubric_dataset.json").read_text())
    shard = ds / "test_hostile-train.array_record-00001-of-00003"
    source = load(ds, "train")
    assert int(source[3]["metadata"]["seed"]) == 3

    shard.write_bytes(shard.read_bytes()[:-30])  # truncated: the footer is gone
    info = kubric("datasets", "info", ds)
    assert info.returncode == 1 and f"{str(shard)!r}: unreadable (truncated" in info.stderr
    with pytest.raises(DatasetError, match=f"{shard}.*: cannot read example"):
        load(ds, "train")[3]
    shard.unlink()
    info = kubric("datasets", "info", ds)
    assert info.returncode == 1 and f"{str(shard)!r}: shard missing" in info.stderr
    with pytest.raises(DatasetError, match=f"{shard}.*: shard missing"):
        load(ds, "train")[0]

    shutil.rmtree(ds)
    shutil.copytree(dataset, ds)
    (ds / "features.json").write_text("{not json")
    with pytest.raises(DatasetError, match=f"{ds / 'features.json'}.* cannot be read"):
        load(ds, "train")[0]
    del marker["counts"]
    (ds / "kubric_dataset.json").write_text(json.dumps(marker))
    info = kubric("datasets", "info", ds)
    assert info.returncode == 1 and "kubric_dataset.json' lacks 'counts'" in info.stderr
    assert len(info.stderr.strip().splitlines()) == 1


# ---------------------------------------------------------------- item 18 (loader)
def test_item18_loader_options_refused_at_load(dataset):
    for bad in (-2, 0, 1.5, "3"):
        with pytest.raises(DatasetError, match=r"num_frames must be a whole number ≥ 1"):
            load(dataset, "train", task="video", num_frames=bad)
    assert load(dataset, "train", task="video", num_frames=1)[0]["video"].shape[0] == 1


def test_item2_two_real_packs_at_once(scenes, tmp_path, dataset):
    import time
    out = tmp_path / "ds"
    first = popen("pack", scenes, "--out", out, "--splits", "train=1", "--examples-per-shard",
                  "2", "--no-progress", stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                  env={"KUBRIC_FAULT": "pack.encode_scene:sleep", "KUBRIC_FAULT_SLEEP": "0.5"})
    lock = tmp_path / ".ds.lock"
    deadline = time.monotonic() + 60
    while not lock.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = kubric("pack", scenes, "--out", out, "--splits", "train=1",
                    "--examples-per-shard", "2", "--no-progress")
    assert first.poll() is None, "the first pack ended before the second started"
    assert second.returncode == 3 and f"(pid {first.pid}," in second.stderr
    assert first.wait(timeout=120) == 0
    assert tree(out) == tree(dataset) and not lock.exists()
