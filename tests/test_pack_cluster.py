"""`kubric pack --cluster` and packing from a URL (kubric.datasets.dask_pack): a real `dask
scheduler` + two `dask worker` processes on 127.0.0.1 and moto's S3 server. The packed dataset is
bit-identical (every file: shards and metadata) to the local packer's — also with an incomplete
and a corrupt scene (the split is re-cut), from s3://, and with `--cluster local`."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import pytest
from dask_helpers import processes, s3_env, start_dask, start_s3

pytestmark = [pytest.mark.blender, pytest.mark.slow]

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ["resolution=32", "frame_end=3", "samples=2", "denoise=false", "max_num_objects=4"]
PACK = ["--splits", "train=0.5,validation=0.5", "--examples-per-shard", "2", "--no-progress"]


def kubric(*args, env=None, timeout=400):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, env=env)


def tree(folder: pathlib.Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def summary(proc) -> list[str]:
    """The pack report without its timing (and without the path of the output)."""
    lines = proc.stdout.strip().splitlines()
    return [lines[0].split(" into ")[0], *lines[1:]] if lines else []


@pytest.fixture(scope="module")
def servers(tmp_path_factory):
    """An S3 server, then a Dask scheduler + 2 workers that see it (fsspec's environment)."""
    tmp = tmp_path_factory.mktemp("servers")
    with processes() as procs, pytest.MonkeyPatch.context() as mp:
        endpoint = start_s3(procs, tmp)
        for key, value in s3_env(endpoint).items():
            mp.setenv(key, value)
        import fsspec.config
        mp.setitem(fsspec.config.conf, "s3", {"endpoint_url": endpoint})
        address = start_dask(procs, tmp, n_workers=2)
        yield address, endpoint


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """6 tiny MOVi-A scenes, a copy with an incomplete and a corrupt scene, and the local
    packer's datasets of both."""
    root = tmp_path_factory.mktemp("pack")
    gen = ["generate", "movi_a", "--out", root / "scenes", "--scenes", 6, "--workers", 2,
           "--no-progress"]
    for option in TINY:
        gen += ["--set", option]
    proc = kubric(*gen)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    bad = root / "bad"
    shutil.copytree(root / "scenes", bad)
    (bad / "scene_00000004" / "_SUCCESS").unlink()
    (bad / "scene_00000001" / "normal_00002.png").write_bytes(b"not a png")
    refs = {}
    for name in ("scenes", "bad"):
        proc = kubric("pack", root / name, "--out", root / f"ref_{name}", *PACK)
        assert proc.returncode == 0, proc.stderr
        refs[name] = (root / f"ref_{name}", summary(proc))
    assert "skipped corrupt scene" in "\n".join(refs["bad"][1])
    return root, refs


def test_pack_on_dask_cluster_is_bit_identical(servers, scenes, tmp_path):
    address, _ = servers
    root, refs = scenes
    for name in ("scenes", "bad"):
        out = tmp_path / name
        proc = kubric("pack", root / name, "--out", out, "--cluster", address, *PACK)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        lines = proc.stdout.strip().splitlines()
        assert lines[0].startswith("Dask dashboard:")
        ref, ref_summary = refs[name]
        assert [lines[1].split(" into ")[0], *lines[2:]] == ref_summary
        got = tree(out)
        assert sorted(got) == sorted(tree(ref))
        assert got == tree(ref), [k for k in got if got[k] != tree(ref)[k]]
        assert not list(tmp_path.glob(".*incomplete*"))

    # scenes on object storage: the same dataset, on the cluster and with local processes
    import s3fs
    s3fs.S3FileSystem.clear_instance_cache()
    fs = s3fs.S3FileSystem()
    fs.mkdir("run")
    fs.put(str(root / "bad"), "run/bad", recursive=True)
    for how in (["--cluster", address], ["--workers", "2"]):
        out = tmp_path / f"s3-{how[0]}"
        proc = kubric("pack", "s3://run/bad", "--out", out, *how, *PACK, env=dict(os.environ))
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert tree(out) == tree(refs["bad"][0]), how
        assert "skipped corrupt scene s3://run/bad/scene_00000001: " in proc.stdout
        assert "skipped 1 incomplete scene directories" in proc.stdout


def test_pack_on_local_cluster_and_bad_input(scenes, tmp_path):
    root, refs = scenes
    out = tmp_path / "local"
    proc = kubric("pack", root / "bad", "--out", out, "--cluster", "local", "--workers", 2,
                  "--dashboard-address", ":0", *PACK)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert tree(out) == tree(refs["bad"][0])

    def one_line(proc, text):
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and text in proc.stderr, proc.stderr

    from dask_helpers import free_port
    one_line(kubric("pack", root / "scenes", "--out", tmp_path / "x", "--cluster",
                    f"tcp://127.0.0.1:{free_port()}", "--connect-timeout", "2", *PACK),
             "no Dask scheduler answered at tcp://127.0.0.1:")
    # a URL output is written through store_commit (tests/test_pack_store.py); a missing
    # bucket is one line before anything starts
    one_line(kubric("pack", root / "scenes", "--out", "s3://bucket/ds", *PACK),
             "'s3://bucket/ds' is not writable")
    one_line(kubric("pack", root / "scenes", "--out", tmp_path / "y", "--jobs", 2, *PACK),
             "--jobs needs --cluster")
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_interrupted_sharded_pack_resumes(scenes, tmp_path, monkeypatch):
    """A pack stopped by a failure keeps its finished chunks; the rerun packs only the rest and
    gives the same dataset."""
    from kubric.datasets import dask_pack, packer
    root, refs = scenes
    encode, calls = packer.encode_scene, []

    def failing(path):
        calls.append(path)
        if len(calls) == 4:  # train: chunks of 2 + 1 scenes done; validation's first scene
            raise RuntimeError("stopped")
        return encode(path)

    monkeypatch.setattr(packer, "encode_scene", failing)
    kwargs = dict(splits="train=0.5,validation=0.5", examples_per_shard=2, progress=False)
    with pytest.raises(RuntimeError, match="stopped"):
        dask_pack.pack_sharded(root / "scenes", tmp_path / "ds", **kwargs)
    assert not (tmp_path / "ds").exists()
    work = tmp_path / ".ds.incomplete"
    names = sorted(p.name for p in work.iterdir())
    marks = [n for n in names if n.endswith(".json") and n != "plan.json"]
    # the failed chunk left nothing; every finished one its file and its record (a chunk that
    # was already running when the failure came may have finished too)
    assert not any("validation.chunk-00000" in n for n in names), names
    assert {".movi_a-train.chunk-00000.json", ".movi_a-train.chunk-00001.json"} <= set(marks)
    assert sorted(names) == sorted(["plan.json", *marks, *(m[1:-5] for m in marks)])
    done = sum(len(json.loads((work / m).read_text())["scenes"]) for m in marks)
    calls.clear()
    result = dask_pack.pack_sharded(root / "scenes", tmp_path / "ds", **kwargs)
    assert result.resumed_scenes == done and len(calls) == 6 - done
    assert tree(tmp_path / "ds") == tree(refs["scenes"][0])
    assert not work.exists()
