"""`kubric generate`: pool, retries, logs, summary, resume, and kills mid-run."""

import pathlib
import signal
import subprocess
import sys
import time

from kubric.pipeline.worker import is_complete

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def generate(out, *args, timeout=120):
    return subprocess.run([sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out),
                           "--no-progress", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout)


def scene_dirs(out):
    return sorted(p.name for p in out.iterdir() if p.name.startswith(("scene_", ".scene_")))


def assert_consistent(out):
    """Every scene directory is complete and whole; nothing else looks like a scene."""
    for name in scene_dirs(out):
        path = out / name
        assert not name.startswith("."), f"left-over work directory {name}"
        assert is_complete(path), f"{name} has no _SUCCESS"
        assert (path / "metadata.json").exists() and len(list(path.glob("rgba_*.png"))) == 3


def test_generate_retries_reports_and_resumes(tmp_path):
    out = tmp_path / "ds"
    proc = generate(out, "--scenes", "4", "--first-seed", "20", "--workers", "2",
                    "--set", "flaky=true")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert scene_dirs(out) == [f"scene_{s:08d}" for s in range(20, 24)]
    assert_consistent(out)
    assert "4 generated, 0 already complete, 0 failed of 4 scenes" in proc.stdout
    assert "(8 worker runs)" in proc.stdout  # every flaky scene needed its retry
    log = (out / "logs" / "scene_00000020.log").read_text()
    assert "attempt 1" in log and "attempt 2" in log and "fails on its first attempt" in log
    # resume: the complete scenes are skipped, new ones added
    proc = generate(out, "--scenes", "6", "--first-seed", "20", "--workers", "2",
                    "--set", "flaky=true")  # the same options (other options refuse)
    assert "2 generated, 4 already complete" in proc.stdout, proc.stdout
    assert len(scene_dirs(out)) == 6
    # a scene that keeps failing: bounded retries, reported with its log, non-zero exit
    proc = generate(out, "--scenes", "1", "--first-seed", "40", "--retries", "1",
                    "--set", "fail=true", "--resume-any")  # beside scenes of other options
    assert proc.returncode == 1
    assert "1 failed" in proc.stdout and "(2 worker runs)" in proc.stdout
    assert "FAILED scene_00000040: RuntimeError: scene 40 fails on purpose" in proc.stdout
    assert (out / "logs" / "scene_00000040.log").exists()
    assert not (out / "scene_00000040").exists()
    # bad options fail before any worker starts
    proc = generate(tmp_path / "bad", "--scenes", "2", "--set", "resolution=-3")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def _start(out, n):
    return subprocess.Popen([sys.executable, "-m", "kubric", "generate", FAKE, "--out", str(out),
                             "--scenes", str(n), "--workers", "2", "--no-progress",
                             "--set", "sleep=0.8"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _wait_for_first_scene(out, proc, timeout=30):
    end = time.time() + timeout
    while time.time() < end and proc.poll() is None:
        if out.exists() and any(is_complete(p) for p in out.glob("scene_*")):
            return
        time.sleep(0.05)
    raise AssertionError("no scene completed in time")


def test_kill_mid_run_then_rerun_completes_dataset(tmp_path):
    n = 8
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        out = tmp_path / sig.name
        proc = _start(out, n)
        _wait_for_first_scene(out, proc)
        proc.send_signal(sig)
        stdout = proc.communicate(timeout=60)[0]
        time.sleep(0.5)  # let workers of a SIGKILLed runner die (parent-death signal)
        done_before = [p for p in out.glob("scene_*") if is_complete(p)]
        assert 0 < len(done_before) < n
        assert not list(out.glob(".scene_*"))  # no work directory left
        if sig != signal.SIGKILL:  # SIGTERM is handled like SIGINT; the summary counts the disk
            assert proc.returncode == 130, stdout
            assert "interrupted" in stdout
            assert f"{len(done_before)} generated, 0 already complete" in stdout, stdout
        for p in out.glob("scene_*"):  # nothing that looks complete is partial
            if is_complete(p):
                assert len(list(p.glob("rgba_*.png"))) == 3
        proc = generate(out, "--scenes", str(n), "--workers", "2", "--set", "sleep=0.8")
        assert proc.returncode == 0, proc.stdout + proc.stderr  # the same command finishes it
        assert f"{len(done_before)} already complete" in proc.stdout
        assert scene_dirs(out) == [f"scene_{s:08d}" for s in range(n)]
        assert_consistent(out)


def test_demo_wiring_with_a_fast_recipe(tmp_path, monkeypatch, capsys):
    from kubric import demo
    monkeypatch.setattr(demo, "DEMO_DATASETS", ((FAKE, 2, ["frames=2"]),))
    assert demo.run_demo(tmp_path, workers=2, progress=False) == 0
    out = capsys.readouterr().out
    sheet = tmp_path / "test_fake_scene_00000000_contact_sheet.png"
    assert f"contact sheet: {sheet.resolve()}" in out and sheet.exists()
    assert "2 generated" in out and (tmp_path / "test_fake" / "scene_00000001" / "_SUCCESS").exists()


def test_wait_exit_reaps_at_exit_and_times_out_otherwise():
    from kubric.pipeline.runner import wait_exit
    quick = subprocess.Popen([sys.executable, "-c", "import sys; sys.exit(3)"])
    assert wait_exit(quick, 30.0) is True and quick.returncode == 3
    slow = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert wait_exit(slow, 0.2) is False and slow.returncode is None
    finally:
        slow.kill()
    assert wait_exit(slow, 30.0) is True and slow.returncode == -signal.SIGKILL
    assert wait_exit(slow, 1.0) is True  # already reaped: still "exited"
