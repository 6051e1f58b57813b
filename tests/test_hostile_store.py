"""Round three (issue 41) on object storage, against moto's S3 server on 127.0.0.1: two packs of
one URL never remove what the other wrote (kubric.datasets.store_lease), a stale lease of a
killed pack does not block, and a corrupt shard in the local cache of a dataset URL is fetched
again (content checksums), with errors naming the URL."""

import json
import os
import pathlib
import subprocess
import sys
import time

import pytest
from dask_helpers import point_at_s3, processes, start_s3

from kubric.pipeline.worker import run_scene

pytestmark = [pytest.mark.slow]

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACK = ["--splits", "train=1", "--examples-per-shard", "2", "--no-progress"]


def env_with(extra=None):
    env = dict(os.environ, PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}")
    env.update(extra or {})
    return env


def kubric(*args, timeout=300, env=None):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=env_with(env))


def popen(*args, env=None):
    return subprocess.Popen([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env_with(env))


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hostile_store")
    with processes() as procs, pytest.MonkeyPatch.context() as mp:
        fs = point_at_s3(mp, start_s3(procs, tmp), tmp / "cache")
        from kubric.recipes.bench import Bench
        scenes = tmp / "scenes"
        for seed in range(6):
            run_scene(Bench(), seed, scenes)
        fs.mkdir("hostile")
        yield {"tmp": tmp, "scenes": scenes, "fs": fs}


def objects(fs, prefix):
    fs.invalidate_cache()
    return {k[len(prefix) + 1:]: fs.cat_file(k) for k in sorted(fs.find(prefix))}


def test_a_second_pack_of_one_url_refuses_and_removes_nothing(store):
    fs, url = store["fs"], "s3://hostile/two"
    slow = {"KUBRIC_FAULT": "pack.encode_scene:sleep", "KUBRIC_FAULT_SLEEP": "1"}
    first = popen("pack", store["scenes"], "--out", url, *PACK, env=slow)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # the first holds its lease
        fs.invalidate_cache()
        if fs.exists("hostile/two/.kubric-pack-leases") and \
                fs.ls("hostile/two/.kubric-pack-leases"):
            break
        time.sleep(0.2)
    second = kubric("pack", store["scenes"], "--out", url, *PACK)
    assert first.poll() is None, "the first pack ended before the second started"
    assert second.returncode == 3, second.stderr
    line, = second.stderr.strip().splitlines()
    assert "is being packed by another run" in line and f"pid {first.pid}" in line
    out, err = first.communicate(timeout=240)
    assert first.returncode == 0, err
    published = objects(fs, "hostile/two")
    marker = json.loads(published["kubric_dataset.json"])
    assert not [n for n in published if n.startswith(".")], sorted(published)  # lease gone too
    from kubric.datasets import load
    assert len(load(url, "train")) == marker["counts"]["train"] == 6
    # sequentially, without --overwrite: refused, the dataset untouched
    again = kubric("pack", store["scenes"], "--out", url, *PACK)
    assert again.returncode == 2 and "already a dataset" in again.stderr, again.stderr
    assert objects(fs, "hostile/two") == published


def test_packs_started_together_leave_a_whole_dataset_or_none(store):
    fs = store["fs"]
    for attempt in range(2):
        url = f"s3://hostile/race{attempt}"
        runs = [popen("pack", store["scenes"], "--out", url, *PACK) for _ in range(2)]
        codes = [r.wait(timeout=300) for r in runs]
        assert set(codes) <= {0, 3}, [r.stderr.read() for r in runs]
        published = objects(fs, url[5:])
        if 0 in codes:
            assert codes.count(0) == 1
            from kubric.datasets import load
            assert len(load(url, "train")) == 6
        else:  # both refused: nothing of a dataset
            assert "kubric_dataset.json" not in published


def test_the_lease_of_a_killed_pack_is_stale(store):
    fs, url = store["fs"], "s3://hostile/killed"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import socket
    fs.pipe_file("hostile/killed/.kubric-pack-leases/dead.json", json.dumps(
        {"host": socket.gethostname(), "pid": dead.pid, "renewed": time.time()}).encode())
    proc = kubric("pack", store["scenes"], "--out", url, *PACK)
    assert proc.returncode == 0, proc.stderr
    assert not [n for n in objects(fs, "hostile/killed") if n.startswith(".")]


def test_a_corrupt_cached_shard_is_fetched_again_and_a_corrupt_store_names_the_url(
        store, monkeypatch, tmp_path):
    fs, url = store["fs"], "s3://hostile/cached"
    proc = kubric("pack", store["scenes"], "--out", url, *PACK)
    assert proc.returncode == 0, proc.stderr
    marker = json.loads(fs.cat_file("hostile/cached/kubric_dataset.json"))
    import hashlib
    for name, digest in marker["shard_sha256"].items():  # independent: hash the store's bytes
        assert hashlib.sha256(fs.cat_file(f"hostile/cached/{name}")).hexdigest() == digest
    assert len(marker["shard_sha256"]) == len(marker["shard_lengths"]["train"]) == 3
    # the local pack of the same scenes records the same checksums
    local = kubric("pack", store["scenes"], "--out", tmp_path / "local", *PACK)
    assert local.returncode == 0, local.stderr
    local_marker = json.loads((tmp_path / "local" / "kubric_dataset.json").read_text())
    assert local_marker["shard_sha256"] == marker["shard_sha256"]

    from kubric.datasets import dataset_cache, load
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache1"))
    first = [load(url, "train")[i]["video"] for i in range(6)]
    folder = dataset_cache.fetch(url, "train")
    shard = sorted(p for p in folder.glob("*.array_record-*") if not p.name.startswith("."))[0]
    data = bytearray(shard.read_bytes())
    data[len(data) // 2] ^= 0xFF  # same size, other bytes
    shard.write_bytes(bytes(data))
    again = load(url, "train")
    assert all((again[i]["video"] == first[i]).all() for i in range(6))
    assert hashlib.sha256(shard.read_bytes()).hexdigest() == marker["shard_sha256"][shard.name]
    # damage in the store itself: one line naming the URL, nothing corrupt left in the cache
    key = f"hostile/cached/{shard.name}"
    stored = bytearray(fs.cat_file(key))
    stored[len(stored) // 2] ^= 0xFF
    fs.pipe_file(key, bytes(stored))
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache2"))
    with pytest.raises(Exception, match=f"'{url}/{shard.name}' is damaged") as err:
        load(url, "train")
    assert "\n" not in str(err.value)
    assert not list((tmp_path / "cache2").rglob(shard.name))


def _stalled_server():
    """A TCP server on 127.0.0.1 that accepts connections and never answers (a stalled store)."""
    import socket
    import threading
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(64)
    held = []

    def accept():
        while True:
            try:
                held.append(server.accept()[0])
            except OSError:
                return
    threading.Thread(target=accept, daemon=True).start()
    return server, held


def test_a_stalled_store_ends_in_one_line_within_its_deadline(store):
    server, held = _stalled_server()
    try:
        endpoint = f"http://127.0.0.1:{server.getsockname()[1]}"
        start = time.monotonic()
        proc = kubric("pack", store["scenes"], "--out", "s3://stalled/ds", *PACK, timeout=120,
                      env={"FSSPEC_S3_ENDPOINT_URL": endpoint, "KUBRIC_STORE_TIMEOUT": "1"})
        took = time.monotonic() - start
    finally:
        server.close()
        for conn in held:
            conn.close()
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode in (1, 2) and len(lines) == 1, proc.stderr[-3000:]
    assert "'s3://stalled/ds'" in lines[0] and "no answer within the deadline" in lines[0]
    assert took < 60, took  # one operation's deadline (10 × 1 s), not minutes
    assert held, "the pack never reached the stalled server"


def test_the_store_dying_mid_pack_is_one_line_and_nothing_is_published(tmp_path):
    (tmp_path / "killstore.py").write_text(
        "import os, signal\n"
        "def kill(point):\n"
        "    os.kill(int(os.environ['MOTO_PID']), signal.SIGKILL)\n")
    with processes() as procs, pytest.MonkeyPatch.context() as mp:
        fs = point_at_s3(mp, start_s3(procs, tmp_path))
        fs.mkdir("dying")
        from kubric.recipes.bench import Bench
        for seed in range(4):
            run_scene(Bench(), seed, tmp_path / "scenes")
        proc = kubric("pack", tmp_path / "scenes", "--out", "s3://dying/ds", *PACK, timeout=200,
                      env={"KUBRIC_FAULT": "pack.encode_scene:call",
                           "KUBRIC_FAULT_CALL": "killstore:kill",
                           "MOTO_PID": str(procs[-1].pid), "KUBRIC_STORE_TIMEOUT": "2",
                           "PYTHONPATH": f"{tmp_path}{os.pathsep}{ROOT}"})
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1, proc.stderr[-3000:]
    assert lines[0].startswith("kubric pack: error: --out 's3://dying/ds': the object store "
                               "failed during the pack"), lines[0]
    assert "rerun the same command to resume" in lines[0]
