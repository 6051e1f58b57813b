"""`kubric generate --cluster ADDRESS` on a cluster of plain `dask worker` processes (started with
no kubric flags: no `scene` resource): it completes, keeps one scene per worker slot
(nthreads // --threads-per-scene), and writes the same scenes as the process pool; a scheduler
that dies mid-run is one line and leaves no scene that looks complete but is not."""

import pathlib
import subprocess
import sys
import threading
import time

import pytest
from dask_helpers import kubric_workers, ppid, processes, start_dask

from kubric.pipeline.worker import SUCCESS

pytestmark = [pytest.mark.slow]

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = str(ROOT / "tests" / "fake_recipes.py") + ":Fake"


def kubric(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def scene_files(root: pathlib.Path) -> dict:
    """Every file of every scene but ``_SUCCESS`` (it holds the scene's seconds)."""
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.glob("scene_*/*")) if p.name != SUCCESS}


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """A `dask scheduler` and two `dask worker ADDRESS --nthreads 2` (no resources)."""
    tmp = tmp_path_factory.mktemp("plain")
    with processes() as procs:
        yield start_dask(procs, tmp, n_workers=2, plain=True, nthreads=2), procs


def test_slots_come_from_the_workers_threads(plain):
    from distributed import Client

    from kubric.pipeline.dask_slots import SceneSlots, uses_resource
    address, _ = plain
    with Client(address, timeout=30) as client:
        assert not uses_resource(client)
        for threads, per_worker in ((1, 2), (2, 1), (3, 1)):
            slots = SceneSlots(client, threads)
            slots.update(force=True)
            assert slots.mode == "threads"
            assert sorted(slots.per_worker.values()) == [per_worker, per_worker]
        slots = SceneSlots(client, 1)
        taken = [slots.take() for _ in range(5)]
        assert taken[4] is None and all(taken[:4])
        assert sorted(slots.busy.values()) == [2, 2]
        slots.give_back(taken[0])
        assert slots.take().worker == taken[0].worker


def test_generate_on_plain_workers_equals_the_pool(plain, tmp_path):
    address, _ = plain
    pool = kubric("generate", "bench", "--out", tmp_path / "pool", "--scenes", 12, "--workers",
                  2, "--no-progress")
    assert pool.returncode == 0, pool.stderr
    dask = kubric("generate", "bench", "--out", tmp_path / "dask", "--scenes", 12,
                  "--cluster", address, "--no-progress")
    assert dask.returncode == 0, dask.stdout + dask.stderr
    assert "12 generated, 0 already complete, 0 failed of 12 scenes" in dask.stdout
    assert "Dask slots: no worker offers the 'scene' resource: 4 slots from the workers' " \
        "threads (2 workers, nthreads // 1 each)" in dask.stdout
    got, want = scene_files(tmp_path / "dask"), scene_files(tmp_path / "pool")
    assert len(want) == 12 * 7 and got == want  # 6 files + schema.json


@pytest.mark.parametrize("threads,per_worker", [(1, 2), (2, 1)])
def test_one_scene_per_slot(plain, tmp_path, threads, per_worker):
    """Sampled every 20 ms: never more scene subprocesses under one Dask worker than its slots,
    and the cluster's slots all used at some moment."""
    address, _ = plain
    out = tmp_path / "out"
    seen: dict[int, int] = {}
    peak = [0]
    done = threading.Event()

    def sample():
        while not done.is_set():
            by_parent: dict[int, int] = {}
            for pid in kubric_workers(out):
                try:
                    parent = ppid(pid)
                except (OSError, IndexError):
                    continue
                by_parent[parent] = by_parent.get(parent, 0) + 1
            for parent, n in by_parent.items():
                seen[parent] = max(seen.get(parent, 0), n)
            peak[0] = max(peak[0], sum(by_parent.values()))
            time.sleep(0.02)

    sampler = threading.Thread(target=sample)
    sampler.start()
    try:
        proc = kubric("generate", FAKE, "--out", out, "--scenes", 8, "--cluster", address,
                      "--threads-per-scene", threads, "--set", "sleep=1.5", "--no-progress")
    finally:
        done.set()
        sampler.join()
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "8 generated" in proc.stdout
    assert seen and max(seen.values()) == per_worker, seen
    assert peak[0] == 2 * per_worker, (peak, seen)


def test_scheduler_dying_mid_run_is_one_line(tmp_path):
    with processes() as procs:
        address = start_dask(procs, tmp_path, n_workers=2, plain=True, nthreads=1)
        out = tmp_path / "out"
        client = subprocess.Popen(
            [sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out), "--scenes",
             "20", "--cluster", address, "--set", "sleep=1", "--no-progress"], cwd=ROOT,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.time() + 120
        while len(list(out.glob("scene_*"))) < 2 and time.time() < deadline:
            time.sleep(0.1)
        assert len(list(out.glob("scene_*"))) >= 2
        from dask_helpers import _stop
        _stop(procs[0])  # the scheduler
        stdout, stderr = client.communicate(timeout=120)
    assert client.returncode == 2, stdout + stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "the Dask scheduler at tcp://127.0.0.1:" in lines[0] and \
        "went away mid-run" in lines[0], stderr
    # every scene directory is complete; no work directory was left looking complete
    for scene in out.glob("scene_*"):
        assert (scene / SUCCESS).is_file() and (scene / "metadata.json").is_file()
    assert not [p for p in out.glob(".scene_*") if (p / SUCCESS).exists()]
