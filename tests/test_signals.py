"""SIGTERM (what Slurm sends) and SIGINT to a real worker and to the runner leave nothing behind
(issue 16): no ``.scene_…incomplete-PID/``, no temporary folder (Blender's ``blender_*`` session
folders included), no final-named directory without ``_SUCCESS``; a rerun completes the scenes
byte-identical to an uninterrupted run."""

import os
import pathlib
import signal
import subprocess
import sys
import time

import pytest

from kubric.pipeline.cleanup import PRIVATE_PREFIX, own, private_tmpdir, remove_stale_private

pytestmark = pytest.mark.blender

TINY = ["--set", "resolution=16", "--set", "frame_end=3", "--set", "samples=1"]


def start(args, tmp):
    env = dict(os.environ, TMPDIR=str(tmp))
    return subprocess.Popen([sys.executable, "-m", "kubric", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)


def signal_when_working(proc, out: pathlib.Path, delay: float, sig) -> bool:
    """Send ``sig`` ``delay`` s after the first work directory appears; False if the process
    ended first."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if out.is_dir() and any(".incomplete-" in p.name for p in out.iterdir()):
            time.sleep(delay)
            if proc.poll() is not None:
                return False
            proc.send_signal(sig)
            return True
        time.sleep(0.02)
    return False


def assert_nothing_left(out: pathlib.Path, tmp: pathlib.Path):
    leftovers = [p.name for p in out.iterdir() if ".incomplete-" in p.name] if out.is_dir() else []
    assert leftovers == []
    assert sorted(p.name for p in tmp.iterdir()) == []  # no blender_*, no kubric-tmp-*
    for scene in out.glob("scene_*") if out.is_dir() else ():
        assert (scene / "_SUCCESS").is_file(), scene


def scene_bytes(scene: pathlib.Path) -> dict:
    skip = {"_SUCCESS", "metadata.json"}  # timings
    return {p.name: p.read_bytes() for p in sorted(scene.iterdir()) if p.name not in skip}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    root = tmp_path_factory.mktemp("reference")
    (root / "tmp").mkdir()
    proc = start(["worker", "movi_a", "--seed", "0", *TINY, "--out", str(root / "out")],
                 root / "tmp")
    assert proc.wait(timeout=300) == 0, proc.stdout.read().decode()
    return scene_bytes(root / "out" / "scene_00000000")


@pytest.mark.parametrize("sig,delay", [(signal.SIGTERM, 0.0), (signal.SIGTERM, 0.3),
                                       (signal.SIGTERM, 0.7), (signal.SIGINT, 0.4)])
def test_signal_to_a_worker_leaves_nothing(tmp_path, reference, sig, delay):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    tmp.mkdir()
    args = ["worker", "movi_a", "--seed", "0", *TINY, "--out", str(out)]
    proc = start(args, tmp)
    sent = signal_when_working(proc, out, delay, sig)
    rc = proc.wait(timeout=120)
    log = proc.stdout.read().decode(errors="replace")
    if sent and "done: " not in log:
        assert rc == 128 + sig, log
    else:  # finished first; a signal during the interpreter's shutdown may still end it
        assert rc in (0, 128 + sig, -sig), log
    assert "Traceback" not in log
    assert_nothing_left(out, tmp)
    proc = start(args, tmp)  # the rerun completes the scene, as an uninterrupted run wrote it
    assert proc.wait(timeout=300) == 0
    assert_nothing_left(out, tmp)
    assert scene_bytes(out / "scene_00000000") == reference


def test_sigterm_to_the_runner_leaves_nothing(tmp_path, reference):
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    tmp.mkdir()
    args = ["generate", "movi_a", "--scenes", "2", "--workers", "1", "--no-progress", *TINY,
            "--out", str(out)]
    proc = start(args, tmp)
    assert signal_when_working(proc, out, 0.3, signal.SIGTERM)
    proc.wait(timeout=120)
    assert_nothing_left(out, tmp)
    proc = start(args, tmp)
    assert proc.wait(timeout=300) == 0, proc.stdout.read().decode()
    assert_nothing_left(out, tmp)
    assert scene_bytes(out / "scene_00000000") == reference
    assert (out / "scene_00000001" / "_SUCCESS").is_file()


def test_private_tmpdir_is_owned_and_stale_ones_are_removed(tmp_path, monkeypatch):
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    stale = tmp_path / f"{PRIVATE_PREFIX}{dead}-abc"
    (stale / "blender_x").mkdir(parents=True)
    alive = tmp_path / f"{PRIVATE_PREFIX}{os.getppid()}-abc"
    alive.mkdir()
    mine = private_tmpdir()
    assert not stale.exists() and alive.exists() and mine.parent == tmp_path
    assert os.environ["TMPDIR"] == str(mine) and tempfile.gettempdir() == str(mine)
    assert remove_stale_private(tmp_path) == []  # the live ones stay
    from kubric.pipeline import cleanup
    assert own(mine) == mine and mine in cleanup._owned
    cleanup.remove_owned(ignore_signals=False)  # (the test process keeps its handlers)
    assert not mine.exists()


def test_sigterm_while_a_worker_exits_leaves_nothing(tmp_path, reference):
    """The signal lands after the scene is done, while the process removes its folders: the
    removal is not cut short (the atexit cleanup ignores further signals)."""
    for attempt in range(5):
        out, tmp = tmp_path / f"out{attempt}", tmp_path / f"tmp{attempt}"
        tmp.mkdir()
        env = dict(os.environ, TMPDIR=str(tmp), PYTHONUNBUFFERED="1")
        proc = subprocess.Popen([sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "0",
                                 *TINY, "--out", str(out)], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True)
        for line in proc.stdout:
            if line.startswith("done: "):
                proc.send_signal(signal.SIGTERM)
                break
        proc.communicate(timeout=120)
        assert_nothing_left(out, tmp)
        assert scene_bytes(out / "scene_00000000") == reference
