"""`kubric pack ... --out s3://...` (kubric.datasets.store_commit) against moto's S3 server on
127.0.0.1, and `kubric.datasets.load("s3://...")` (kubric.datasets.dataset_cache): the published
files are the local pack's bytes — also after a SIGKILL mid-pack and a rerun, and packed on a
cluster of plain `dask worker`s that share nothing but the store; a dataset loaded from the URL
equals the local one; bad outputs and damaged datasets are one line, nothing that looks complete
is left behind."""

import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from dask_helpers import processes, s3_env, start_dask, start_s3

from kubric.pipeline.worker import run_scene

pytestmark = [pytest.mark.slow]

ROOT = pathlib.Path(__file__).resolve().parents[1]
N = 40
PACK = ["--splits", "train=0.75,validation=0.25", "--examples-per-shard", "3", "--no-progress"]


def kubric(*args, timeout=300, **kwargs):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, **kwargs)


def tree(folder: pathlib.Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def s3_tree(fs, prefix: str) -> dict:
    """Every object under ``prefix`` (hidden ones included: nothing may be left behind)."""
    fs.invalidate_cache()
    return {k[len(prefix) + 1:]: fs.cat_file(k) for k in sorted(fs.find(prefix))}


def one_line(proc, text):
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and text in lines[0], proc.stderr


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """moto's S3 server (fsspec pointed at it) and bench scenes with a corrupt and an
    incomplete one, their local pack, and a bucket holding them."""
    tmp = tmp_path_factory.mktemp("store")
    with processes() as procs, pytest.MonkeyPatch.context() as mp:
        endpoint = start_s3(procs, tmp)
        for key, value in s3_env(endpoint).items():
            mp.setenv(key, value)
        mp.setenv("KUBRIC_CACHE_DIR", str(tmp / "cache"))
        import fsspec.config
        mp.setitem(fsspec.config.conf, "s3", {"endpoint_url": endpoint})
        import s3fs

        from kubric.recipes.bench import Bench
        scenes = tmp / "scenes"
        for seed in range(N):
            run_scene(Bench(), seed, scenes)
        (scenes / "scene_00000007" / "_SUCCESS").unlink()
        (scenes / "scene_00000011" / "rgba_00001.png").write_bytes(b"not a png")
        ref = kubric("pack", scenes, "--out", tmp / "ref", *PACK)
        assert ref.returncode == 0, ref.stderr
        assert "skipped corrupt scene" in ref.stdout
        s3fs.S3FileSystem.clear_instance_cache()
        fs = s3fs.S3FileSystem()
        fs.mkdir("data")
        fs.put(str(scenes), "data/scenes", recursive=True)
        yield {"procs": procs, "tmp": tmp, "scenes": scenes, "ref": tmp / "ref", "fs": fs,
               "endpoint": endpoint}


def test_pack_to_s3_is_bit_identical_and_loads_like_local(store):
    fs, ref = store["fs"], store["ref"]
    proc = kubric("pack", store["scenes"], "--out", "s3://data/ds", "--workers", 2, *PACK)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "skipped corrupt scene" in proc.stdout
    assert s3_tree(fs, "data/ds") == tree(ref)   # no work prefix left, same bytes
    # the same dataset read from the URL and from disk
    from kubric.datasets import load, to_grain, to_torch
    for split in ("train", "validation"):
        remote, local = load("s3://data/ds", split), load(ref, split)
        assert len(remote) == len(local) > 0 and remote.scenes == local.scenes
        for i in range(len(local)):
            a, b = remote[i], local[i]
            assert a["metadata"] == b["metadata"]
            for key in ("video", "segmentations"):
                assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key])
            assert np.array_equal(a["instances"]["positions"], b["instances"]["positions"])
    # the adapters take the URL's source as they take a local one
    torch_item = to_torch(load("s3://data/ds", "train"))[2]
    assert np.array_equal(torch_item["video"], load(ref, "train")[2]["video"])
    batch = next(iter(to_grain(load("s3://data/ds", "train"), batch_size=2)))
    assert batch["video"].shape[0] == 2
    info = kubric("datasets", "info", "s3://data/ds")
    assert info.returncode == 0, info.stderr
    local_info = kubric("datasets", "info", ref).stdout.splitlines()
    assert info.stdout.splitlines()[0] == "dataset bench at s3://data/ds"
    assert info.stdout.splitlines()[3:] == local_info[3:]  # splits, tasks, features
    size = lambda text: text.splitlines()[2].split("size on disk ")[1]  # noqa: E731
    assert size(info.stdout) == size("\n".join(local_info))
    marker = json.loads((ref / "kubric_dataset.json").read_text())  # the same bytes as on S3
    assert marker["shard_bytes"] and marker["shard_bytes"] == \
        {name: (ref / name).stat().st_size for name in marker["shard_sha256"]}
    # packing the same output again is refused, --overwrite replaces it
    one_line(kubric("pack", store["scenes"], "--out", "s3://data/ds", *PACK), "already a dataset")
    proc = kubric("pack", store["scenes"], "--out", "s3://data/ds", "--overwrite",
                  "--examples-per-shard", "5", "--splits", "train=0.75,validation=0.25",
                  "--no-progress")
    assert proc.returncode == 0, proc.stderr
    names = sorted(s3_tree(fs, "data/ds"))
    assert not [n for n in names if n.endswith("-00003-of-00010")], names  # old shards gone
    assert len(load("s3://data/ds", "train")) == len(load(ref, "train"))


def test_killed_pack_leaves_no_dataset_and_the_rerun_is_identical(store):
    fs, ref = store["fs"], store["ref"]
    cmd = [sys.executable, "-m", "kubric", "pack", str(store["scenes"]), "--out",
           "s3://data/killed", "--workers", "1", *PACK]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    deadline = time.time() + 120
    marks = []
    while time.time() < deadline and proc.poll() is None:
        fs.invalidate_cache()
        marks = [k for k in fs.find("data/killed") if k.endswith(".json")
                 and "/.kubric-pack/." in k]
        if len(marks) >= 3:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the pack finished before it could be killed"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    fs.invalidate_cache()
    left = sorted(fs.find("data/killed"))
    # only the work prefix and the killed run's lease (stale: the rerun removes it)
    assert left and all("/.kubric-pack/" in k or "/.kubric-pack-leases/" in k for k in left), left
    from kubric.datasets import DatasetError, load
    with pytest.raises(DatasetError, match="is not a kubric dataset"):
        load("s3://data/killed", "train")
    rerun = kubric("pack", store["scenes"], "--out", "s3://data/killed", "--workers", 1, *PACK)
    assert rerun.returncode == 0, rerun.stderr
    resumed = [ln for ln in rerun.stdout.splitlines() if "resumed:" in ln]
    assert resumed and int(resumed[0].split()[1]) >= 3 * 3 - 3, rerun.stdout
    assert s3_tree(fs, "data/killed") == tree(ref)


def test_pack_on_plain_dask_workers_sharing_only_the_store(store, tmp_path):
    """Scenes and dataset both in the bucket; workers started with no kubric flags and given
    no filesystem but their own."""
    fs, ref = store["fs"], store["ref"]
    address = start_dask(store["procs"], tmp_path, n_workers=2, plain=True, nthreads=1)
    proc = kubric("pack", "s3://data/scenes", "--out", "s3://data/cluster", "--cluster", address,
                  *PACK)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert s3_tree(fs, "data/cluster") == tree(ref)


def test_bad_store_outputs_and_damaged_datasets_are_one_line(store, tmp_path):
    fs = store["fs"]
    scenes = store["scenes"]
    one_line(kubric("pack", scenes, "--out", "s3://no-such-bucket/ds", *PACK),
             "'s3://no-such-bucket/ds' is not writable")
    # a read-only store: an HTTP server (fsspec's http filesystem cannot write)
    from dask_helpers import free_port, spawn
    port = free_port()
    server = spawn([sys.executable, "-m", "http.server", str(port), "--bind", "127.0.0.1",
                    "--directory", str(tmp_path)], tmp_path / "http.log")
    store["procs"].append(server)
    time.sleep(1.0)
    one_line(kubric("pack", scenes, "--out", f"http://127.0.0.1:{port}/ds", *PACK),
             f"'http://127.0.0.1:{port}/ds' is not writable")
    # an unreachable S3 endpoint
    env = dict(os.environ, FSSPEC_S3_ENDPOINT_URL=f"http://127.0.0.1:{free_port()}",
               AWS_MAX_ATTEMPTS="1", AWS_RETRY_MODE="standard")
    start = time.time()
    one_line(kubric("pack", scenes, "--out", "s3://data/unreachable", *PACK, env=env),
             "'s3://data/unreachable' is not writable")
    assert time.time() - start < 120
    assert not fs.exists("data/unreachable") and not fs.exists("no-such-bucket")
    # a prefix that holds something else is not written into
    fs.pipe_file("data/other/notes.txt", b"mine")
    one_line(kubric("pack", scenes, "--out", "s3://data/other", *PACK),
             "holds 'notes.txt', which is not part of a kubric dataset")
    assert sorted(fs.find("data/other")) == ["data/other/notes.txt"]
    # a dataset with a missing shard: loading it is one line naming the shard
    assert kubric("pack", scenes, "--out", "s3://data/damaged", *PACK).returncode == 0
    victim = sorted(k for k in fs.find("data/damaged") if ".array_record-" in k
                    and "-train." in k)[1]
    # a truncated shard: `datasets info` sees it from the listing and the marker's sizes
    fs.pipe_file(victim, fs.cat_file(victim)[:-30])
    info = kubric("datasets", "info", "s3://data/damaged")
    assert info.returncode == 1 and len(info.stderr.strip().splitlines()) == 1, info.stderr
    assert f"{victim.rsplit('/', 1)[1]}': " in info.stderr and "bytes, the marker says" in \
        info.stderr and "(truncated or replaced)" in info.stderr, info.stderr
    fs.rm(victim)
    from kubric.datasets import DatasetError, load
    with pytest.raises(DatasetError, match=rf"is damaged: shard '{victim.rsplit('/', 1)[1]}' "
                       r"is missing \(1 of \d+ shards of split 'train'\)"):
        load("s3://data/damaged", "train")
    assert len(load("s3://data/damaged", "validation")) > 0  # the intact split still reads
    proc = subprocess.run([sys.executable, "-c", "import kubric.datasets as d; "
                           "d.load('s3://data/damaged', 'train')"], capture_output=True,
                          text=True, cwd=ROOT)
    assert "DatasetError" in proc.stderr and "is damaged" in proc.stderr


def test_scheduler_dying_mid_pack_is_one_line_and_the_rerun_completes(store, tmp_path):
    fs = store["fs"]
    options = ["--splits", "train=0.75,validation=0.25", "--examples-per-shard", "1",
               "--no-progress"]
    ref = kubric("pack", store["scenes"], "--out", tmp_path / "ref", *options)
    assert ref.returncode == 0, ref.stderr
    with processes() as procs:
        address = start_dask(procs, tmp_path, n_workers=2, plain=True, nthreads=1)
        proc = subprocess.Popen(
            [sys.executable, "-m", "kubric", "pack", "s3://data/scenes", "--out",
             "s3://data/lost", "--cluster", address, *options], cwd=ROOT,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.time() + 120
        while time.time() < deadline and proc.poll() is None:
            fs.invalidate_cache()
            if len([k for k in fs.find("data/lost") if k.endswith(".json")
                    and "/.kubric-pack/." in k]) >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the pack finished before the scheduler could be stopped"
        from dask_helpers import _stop
        _stop(procs[0])  # the scheduler
        stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 2, stdout + stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "the Dask scheduler at tcp://127.0.0.1:" in lines[0] and \
        "finished chunks are kept (nothing is published)" in lines[0], stderr
    fs.invalidate_cache()
    assert all("/.kubric-pack/" in k for k in fs.find("data/lost"))  # no dataset published
    (tmp_path / "again").mkdir()
    with processes() as procs:
        address = start_dask(procs, tmp_path / "again", n_workers=2, plain=True, nthreads=1)
        rerun = kubric("pack", "s3://data/scenes", "--out", "s3://data/lost", "--cluster",
                       address, *options)
    assert rerun.returncode == 0, rerun.stdout + rerun.stderr
    assert "resumed:" in rerun.stdout
    assert s3_tree(fs, "data/lost") == tree(tmp_path / "ref")
