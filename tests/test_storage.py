"""`--out` as a URL: kubric.io.storage against local paths / file:// URLs and a real
S3-compatible server (moto's standalone server on 127.0.0.1): a worker killed mid-upload leaves
nothing that reads as data, `kubric generate` resumes it, `kubric inspect` reads the URL."""

import os
import pathlib
import signal
import subprocess
import sys

import pytest
from dask_helpers import processes, s3_env, start_s3

from kubric.io import storage

ROOT = pathlib.Path(__file__).resolve().parents[1]
FAKE = f"{ROOT / 'tests' / 'fake_recipes.py'}:Fake"


def test_paths_and_file_urls_behave_alike(tmp_path):
    src = tmp_path / "src"
    (src / "sub").mkdir(parents=True)
    for name, data in (("b.txt", b"b"), ("_SUCCESS", b"ok"), ("a.txt", b"a"),
                       ("sub/c.txt", b"c")):
        (src / name).write_bytes(data)
    for root in (str(tmp_path / "plain"), f"file://{tmp_path}/url"):
        dest = storage.join(root, "scene_00000001")
        seen = []
        order = storage.upload_dir(src, dest, on_file=lambda *a, seen=seen: seen.append(a))
        assert order == ["a.txt", "b.txt", "sub/c.txt", "_SUCCESS"]  # _SUCCESS last
        assert seen[-1] == ("_SUCCESS", 4, 4)
        assert storage.listdir(dest) == ["_SUCCESS", "a.txt", "b.txt", "sub"]
        assert storage.read_bytes(storage.join(dest, "sub", "c.txt")) == b"c"
        storage.upload_dir(src, storage.join(root, "scene_00000002"), last="none-such")
        storage.remove(storage.join(root, "scene_00000002", "_SUCCESS"))
        assert storage.complete_scenes(root) == ["scene_00000001"]  # 2 has no _SUCCESS
        assert storage.listdir(storage.join(root, "missing")) == []
        # a re-upload replaces what was there (no stale file survives)
        storage.write_bytes(storage.join(dest, "stale.txt"), b"x")
        storage.upload_dir(src, dest)
        assert not storage.exists(storage.join(dest, "stale.txt"))
    assert (tmp_path / "url" / "scene_00000001" / "_SUCCESS").read_bytes() == b"ok"
    assert storage.normalise("S3://bucket/run/") == "s3://bucket/run"
    with pytest.raises(storage.StorageError, match="names no bucket"):
        storage.normalise("s3://")
    with pytest.raises(storage.StorageError, match="unknown storage protocol 'nosuch'"):
        storage.exists("nosuch://x/y")
    with pytest.raises(storage.StorageError, match="is a file, not a directory"):
        storage.check_writable(src / "a.txt" / "out")
    storage.check_writable(tmp_path / "new" / "deeper")
    assert not (tmp_path / "new").exists()  # checking creates nothing


#: 41 files per scene: the upload takes long enough to be stopped half way
OPTIONS = ["--set", "frames=20"]


def _worker_cmd(out, seed):
    return [sys.executable, "-m", "kubric", "worker", FAKE, "--seed", str(seed), "--out", out,
            *OPTIONS]


@pytest.mark.slow
def test_s3_kill_mid_upload_resume_and_inspect(tmp_path, monkeypatch):
    with processes() as procs:
        endpoint = start_s3(procs, tmp_path)
        for key, value in s3_env(endpoint).items():
            monkeypatch.setenv(key, value)
        env = dict(os.environ)
        import fsspec.config  # this process read fsspec's configuration at import
        monkeypatch.setitem(fsspec.config.conf, "s3", {"endpoint_url": endpoint})
        import s3fs
        s3fs.S3FileSystem.clear_instance_cache()
        s3fs.S3FileSystem(endpoint_url=endpoint).mkdir("bucket")
        run = "s3://bucket/run"

        # a worker stopped right after its first uploaded file, then killed: a partial scene
        worker = subprocess.Popen(_worker_cmd(run, 1), cwd=ROOT, stdout=subprocess.PIPE,
                                  stderr=subprocess.STDOUT, text=True, env=env)
        try:
            lines = []
            for line in worker.stdout:
                lines.append(line)
                if line.startswith("uploaded 1/"):
                    worker.send_signal(signal.SIGSTOP)
                    break
            assert lines and lines[-1].startswith("uploaded 1/"), "".join(lines)
            partial = storage.listdir(f"{run}/scene_00000001")
            assert partial and "_SUCCESS" not in partial
            assert storage.complete_scenes(run) == []  # a reader sees no data
            inspect = subprocess.run([sys.executable, "-m", "kubric", "inspect",
                                      f"{run}/scene_00000001"], cwd=tmp_path, env=env,
                                     capture_output=True, text=True, timeout=120)
            assert inspect.returncode == 2 and "incomplete (no _SUCCESS" in inspect.stderr
            worker.kill()
        finally:
            worker.kill()
            worker.wait(timeout=30)

        # resume: all three scenes generated (the partial one replaced), logs uploaded
        gen = [sys.executable, "-m", "kubric", "generate", FAKE, "--out", run, "--scenes", "3",
               "--workers", "2", "--no-progress", *OPTIONS]
        proc = subprocess.run(gen, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert "3 generated, 0 already complete, 0 failed of 3 scenes" in proc.stdout
        assert storage.complete_scenes(run) == [f"scene_{s:08d}" for s in range(3)]
        assert "uploaded" in storage.read_bytes(f"{run}/logs/scene_00000001.log").decode()
        # the uploaded scenes are byte for byte those of a local run
        local = tmp_path / "local"
        for seed in range(3):
            subprocess.run(_worker_cmd(str(local), seed), cwd=ROOT, check=True, timeout=120,
                           capture_output=True)
            scene = local / f"scene_{seed:08d}"
            names = sorted(p.name for p in scene.iterdir() if p.name != "_SUCCESS")
            remote = f"{run}/scene_{seed:08d}"
            assert sorted(set(storage.listdir(remote)) - {"_SUCCESS"}) == names
            for name in names:
                assert storage.read_bytes(f"{remote}/{name}") == (scene / name).read_bytes()
        proc = subprocess.run(gen, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
        assert "0 generated, 3 already complete" in proc.stdout, proc.stdout + proc.stderr

        inspect = subprocess.run([sys.executable, "-m", "kubric", "inspect",
                                  f"{run}/scene_00000002"], cwd=tmp_path, env=env,
                                 capture_output=True, text=True, timeout=120)
        assert inspect.returncode == 0, inspect.stderr
        assert f"scene {run}/scene_00000002" in inspect.stdout and "complete: True" in inspect.stdout
        assert (tmp_path / "scene_00000002_contact_sheet.png").exists()

        # an output in a bucket that does not exist: one line, nothing started
        proc = subprocess.run([*gen[:6], "s3://no-such-bucket/run", *gen[7:]], cwd=ROOT,
                              env=env, capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert "'s3://no-such-bucket/run' is not writable" in proc.stderr
