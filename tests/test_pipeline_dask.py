"""`kubric generate --cluster`: a real `dask scheduler` + two `dask worker` processes on
127.0.0.1 render MOVi-A scenes identical to the local runner's; a worker SIGKILLed mid-render and
a client SIGKILLed mid-run both end in the complete set."""

import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from dask_helpers import kubric_workers, ppid, processes, start_dask

from kubric import file_io
from kubric.pipeline.worker import is_complete

pytestmark = [pytest.mark.blender, pytest.mark.slow]

ROOT = pathlib.Path(__file__).resolve().parents[1]
N = 6
TINY = ["resolution=32", "frame_end=3", "samples=2", "denoise=false", "max_num_objects=5"]


def generate_cmd(out, *args):
    cmd = [sys.executable, "-m", "kubric", "generate", "movi_a", "--out", str(out), "--scenes",
           str(N), "--no-progress", *args]
    for option in TINY:
        cmd += ["--set", option]
    return cmd


def generate(out, *args, timeout=400):
    return subprocess.run(generate_cmd(out, *args), cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The local process pool's scenes for seeds 0..N-1."""
    out = tmp_path_factory.mktemp("local") / "ds"
    proc = generate(out, "--workers", "2")
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return out


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("dask")
    with processes() as procs:
        address = start_dask(procs, tmp, n_workers=2)
        yield address, procs, tmp


def assert_same_scenes(out, reference):
    names = sorted(p.name for p in out.iterdir() if p.name.startswith(("scene_", ".scene_")))
    assert names == [f"scene_{s:08d}" for s in range(N)], names
    for name in names:
        scene, ref = out / name, reference / name
        assert is_complete(scene)
        for js in ("metadata.json", "events.json", "data_ranges.json"):
            assert file_io.read_json(scene / js) == file_io.read_json(ref / js), (name, js)
        layers, ref_layers = file_io.read_image_dict(scene), file_io.read_image_dict(ref)
        assert sorted(layers) == sorted(ref_layers) and "segmentation" in layers
        for layer, values in layers.items():
            assert values.dtype == ref_layers[layer].dtype
            np.testing.assert_array_equal(values, ref_layers[layer], err_msg=f"{name} {layer}")


def test_dask_cluster_scenes_equal_local_runner(cluster, reference, tmp_path):
    address, _, _ = cluster
    out = tmp_path / "ds"
    proc = generate(out, "--cluster", address)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert f"{N} generated, 0 already complete, 0 failed of {N} scenes" in proc.stdout
    assert "Dask dashboard:" in proc.stdout
    assert_same_scenes(out, reference)
    log = (out / "logs" / "scene_00000003.log").read_text()
    assert "=== attempt 1" in log
    assert "tcp://127.0.0.1:" in log and "=== exit status 0" in log  # the worker that ran it
    # resume: everything is complete, nothing is submitted
    proc = generate(out, "--cluster", address)
    assert f"0 generated, {N} already complete" in proc.stdout, proc.stdout + proc.stderr


def _wait(predicate, timeout, what):
    end = time.time() + timeout
    while time.time() < end:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def assert_nothing_partial_looks_complete(out):
    for scene in out.glob("scene_*"):  # final names only appear complete (rename, then _SUCCESS)
        if is_complete(scene):
            assert len(list(scene.glob("segmentation_*.png"))) == 3
            assert (scene / "metadata.json").exists()


def _gone_or_zombie(pid: int) -> bool:
    try:  # the process may vanish between any two looks at /proc
        return pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def test_worker_killed_mid_render_and_client_killed_then_rerun(cluster, reference, tmp_path):
    address, procs, _ = cluster
    nannies = {p.pid for p in procs[1:]}
    out = tmp_path / "ds"
    client = subprocess.Popen(generate_cmd(out, "--cluster", address), cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # a kubric worker subprocess is rendering: SIGKILL its Dask worker process. Parents are
        # read as soon as the scene process appears (a tiny scene may finish within a second).
        def running_scene():
            for scene_pid in kubric_workers(out):
                try:
                    worker_pid = ppid(scene_pid)
                    return scene_pid, worker_pid, ppid(worker_pid)
                except OSError:  # it ended between two looks at /proc
                    continue
            return None

        pid, dask_worker, nanny = _wait(running_scene, 120, "a scene to start")
        assert nanny in nannies  # the Dask worker process under a `dask worker` nanny
        time.sleep(0.3)
        os.kill(dask_worker, signal.SIGKILL)
        _wait(lambda: _gone_or_zombie(pid), 30, "the orphaned scene process to die with its worker")
        stdout = client.communicate(timeout=400)[0]
    finally:
        client.kill()
    assert client.returncode == 0, stdout[-3000:]
    assert f"{N} generated, 0 already complete, 0 failed of {N} scenes" in stdout, stdout
    assert_same_scenes(out, reference)

    # SIGKILL the client mid-run: no partial scene looks complete, a rerun completes the set
    out = tmp_path / "ds2"
    client = subprocess.Popen(generate_cmd(out, "--cluster", address), cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait(lambda: [p for p in out.glob("scene_*") if is_complete(p)], 200, "a first scene")
        client.kill()
        client.wait(timeout=30)
    finally:
        client.kill()
    done_before = [p for p in out.glob("scene_*") if is_complete(p)]
    assert 0 < len(done_before) < N
    assert_nothing_partial_looks_complete(out)
    proc = generate(out, "--cluster", address)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert f"of {N} scenes" in proc.stdout and "0 failed" in proc.stdout
    _wait(lambda: not kubric_workers(out), 120, "orphaned scenes of the killed client to end")
    assert_same_scenes(out, reference)
