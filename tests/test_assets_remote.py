"""Asset sources at URLs (kubric.assets.remote_source) against real servers on 127.0.0.1: the
standard library's HTTP server and moto's S3 server. KuBasic served from a URL gives the same
assets as the local folder, is downloaded once per machine (also by two processes at once), a
cut transfer or a bad checksum caches nothing, and bad URLs fail in one line."""

import hashlib
import json
import os
import pathlib
import shutil
import socket
import subprocess
import sys
import time

import pytest
from http_helpers import serve

import kubric as kb
from kubric.asset_tools import ensure_kubasic
from kubric.assets.asset_source import ManifestError
from kubric.assets.remote_source import RemoteSourceError, cache_folder

ROOT = pathlib.Path(__file__).resolve().parents[1]


def tree(folder: pathlib.Path) -> dict:
    """{relative path: bytes} of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def kubasic_dir():
    return ensure_kubasic().manifest_path.parent


@pytest.fixture
def published(kubasic_dir, tmp_path, monkeypatch):
    """A copy of KuBasic whose manifest holds every archive's sha256, in a folder to serve; the
    asset cache is a fresh folder of this test."""
    root = tmp_path / "www"
    shutil.copytree(kubasic_dir, root / "kubasic")
    manifest = json.loads((root / "kubasic" / "manifest.json").read_text())
    for asset_id, entry in manifest["assets"].items():
        archive = root / "kubasic" / entry.get("path", f"{asset_id}.tar.gz")
        entry["sha256"] = hashlib.sha256(archive.read_bytes()).hexdigest()
    (root / "kubasic" / "manifest.json").write_text(json.dumps(manifest))
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))
    return root


def test_http_source_equals_local_and_downloads_once(published, kubasic_dir):
    local = kb.AssetSource(kubasic_dir, scratch_dir=published.parent / "local-extract")
    with serve(published) as server:
        url = f"{server.url}/kubasic"
        source = kb.AssetSource.from_manifest(url)
        assert source.all_asset_ids == local.all_asset_ids and source.name == local.name
        for asset_id in ("cube", "suzanne", "dome"):
            assert tree(source.fetch(asset_id)) == tree(local.fetch(asset_id)), asset_id
            kwargs = source.get_asset_kwargs(asset_id)
            assert pathlib.Path(kwargs["render_filename"]).is_file()
        obj = source.create("cube", scale=0.7)
        assert obj.metadata["asset_id"] == "cube" and obj.metadata["license"]
        # a second open (the manifest URL itself) and a fresh extraction: no new request
        again = kb.AssetSource(f"{url}/manifest.json", scratch_dir=published.parent / "x2")
        assert tree(again.fetch("cube")) == tree(local.fetch("cube"))
        source.close()
        again.close()
        listing = subprocess.run([sys.executable, "-m", "kubric", "assets", "list", url],
                                 cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert listing.returncode == 0, listing.stderr
        assert f"{local.name} {local.version}: {len(local)} assets" in listing.stdout
    assert server.gets == {"/kubasic/manifest.json": 1, "/kubasic/cube.tar.gz": 1,
                           "/kubasic/suzanne.tar.gz": 1, "/kubasic/dome.tar.gz": 1}
    folder = cache_folder(url)
    assert folder.parent.parent == published.parent / "cache"
    cached = sorted(p.name for p in (folder / "archives").iterdir() if not p.name.startswith("."))
    assert len(cached) == 3 and all(n.endswith(".tar.gz") for n in cached)


_FETCH = """
import pathlib, sys, time
import kubric as kb
pathlib.Path(sys.argv[2]).touch()
while not pathlib.Path(sys.argv[3]).exists():
    time.sleep(0.01)
source = kb.AssetSource(sys.argv[1])
print(sorted(p.name for p in source.fetch("cube").rglob("*")))
"""


def test_two_processes_download_once(published, tmp_path):
    with serve(published) as server:
        server.delay.update({"/kubasic/manifest.json": 1.0, "/kubasic/cube.tar.gz": 1.0})
        procs = [subprocess.Popen([sys.executable, "-c", _FETCH, f"{server.url}/kubasic",
                                   str(tmp_path / f"ready{k}"), str(tmp_path / "go")],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for k in range(2)]
        end = time.time() + 120
        while not all((tmp_path / f"ready{k}").exists() for k in range(2)):
            assert time.time() < end and all(p.poll() is None for p in procs)
            time.sleep(0.02)
        (tmp_path / "go").touch()  # both ask at once; each answer takes a second
        outputs = [p.communicate(timeout=120) for p in procs]
    for proc, (out, err) in zip(procs, outputs, strict=True):
        assert proc.returncode == 0, err
        assert "visual_geometry.obj" in out
    assert outputs[0][0] == outputs[1][0]
    assert server.gets == {"/kubasic/manifest.json": 1, "/kubasic/cube.tar.gz": 1}


def _visible(folder: pathlib.Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if p.is_file()
                  and not p.name.startswith(".")) if folder.exists() else []


def test_cut_transfer_and_bad_checksum_cache_nothing(published):
    with serve(published) as server:
        url = f"{server.url}/kubasic"
        source = kb.AssetSource(url)
        server.cut.add("/kubasic/cube.tar.gz")  # full Content-Length, half the bytes
        with pytest.raises(RemoteSourceError, match=r"transfer cut 3 times \(last: connection "
                           r"closed after \d+ of \d+ bytes\)"):
            source.fetch("cube")
        assert server.gets["/kubasic/cube.tar.gz"] == 3
        archives = cache_folder(url) / "archives"
        assert _visible(archives) == []  # no file that looks complete (nor a partial one)
        assert not list(archives.glob(".*.part"))
        assert not source.scratch_dir.exists() or not any(
            p.name.startswith("cube") for p in source.scratch_dir.iterdir())
        server.cut.clear()
        assert (source.fetch("cube") / "visual_geometry.obj").is_file()  # the next try succeeds

        # an archive that does not match the manifest's sha256 is refused and not kept
        (published / "kubasic" / "sphere.tar.gz").write_bytes(
            (published / "kubasic" / "cone.tar.gz").read_bytes())
        with pytest.raises(RemoteSourceError, match=r"asset 'sphere' .*sphere.tar.gz\): sha256 "
                           r"[0-9a-f]{64} does not match the manifest's [0-9a-f]{64}$"):
            source.fetch("sphere")
        assert not any("sphere" in n for n in _visible(archives))
        source.close()


def test_bad_urls_fail_in_one_line(published, tmp_path, monkeypatch):
    with serve(published) as server:
        with pytest.raises(RemoteSourceError, match=r"^asset source http://127.0.0.1:\d+/"
                           r"nothing/manifest.json: HTTP 404 File not found$"):
            kb.AssetSource(f"{server.url}/nothing")
        bad = published / "bad"
        bad.mkdir()
        (bad / "manifest.json").write_text('{"name": "x", "assets": ')
        with pytest.raises(ManifestError, match=r"/bad/manifest.json: not valid JSON"):
            kb.AssetSource(f"{server.url}/bad")
        (bad / "manifest.json").write_text('{"name": "x", "assets": {"a": {"id": "a"}}}')
        with pytest.raises(ManifestError, match=r"asset 'a': missing required field "
                           r"'asset_type'"):
            kb.AssetSource(f"{server.url}/bad")  # the malformed copy was not cached
        server.status["/kubasic/cube.tar.gz"] = 500
        with pytest.raises(RemoteSourceError, match=r"^asset 'cube' \(http://.*/cube.tar.gz\): "
                           r"HTTP 500 Internal Server Error$"):
            kb.AssetSource(f"{server.url}/kubasic").fetch("cube")

    with socket.socket() as silent:  # accepts connections, never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen(8)
        port = silent.getsockname()[1]
        monkeypatch.setenv("KUBRIC_FETCH_TIMEOUT", "1")
        start = time.monotonic()
        with pytest.raises(RemoteSourceError, match=r"no answer within 1 s "
                           r"\(\$KUBRIC_FETCH_TIMEOUT\)$"):
            kb.AssetSource(f"http://127.0.0.1:{port}/kubasic")
        assert time.monotonic() - start < 10
    # closed now: nothing listens on that port
    with pytest.raises(RemoteSourceError, match=r"cannot connect \(.*[Cc]onnection refused"):
        kb.AssetSource(f"http://127.0.0.1:{port}/kubasic")

    # the CLI: one line, exit 2, nothing started
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "kubric", "generate", "movi_a", "--out",
                           str(out), "--scenes", "1", "--set",
                           f"kubasic_source=http://127.0.0.1:{port}/kubasic"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert "kubasic_source 'http://127.0.0.1:" in proc.stderr and "cannot connect" in proc.stderr
    assert not out.exists()


@pytest.mark.slow
def test_s3_source_equals_local(kubasic_dir, tmp_path, monkeypatch):
    from dask_helpers import processes, s3_env, start_s3
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))
    with processes() as procs:
        endpoint = start_s3(procs, tmp_path)
        for key, value in s3_env(endpoint).items():
            monkeypatch.setenv(key, value)
        import fsspec.config
        monkeypatch.setitem(fsspec.config.conf, "s3", {"endpoint_url": endpoint})
        import s3fs
        s3fs.S3FileSystem.clear_instance_cache()
        fs = s3fs.S3FileSystem(endpoint_url=endpoint)
        fs.mkdir("assets")
        fs.put(str(kubasic_dir), "assets/kubasic", recursive=True)
        local = kb.AssetSource(kubasic_dir, scratch_dir=tmp_path / "local-extract")
        source = kb.AssetSource("s3://assets/kubasic")
        assert source.all_asset_ids == local.all_asset_ids
        for asset_id in source.all_asset_ids:
            assert tree(source.fetch(asset_id)) == tree(local.fetch(asset_id)), asset_id
        fs.rm("assets/kubasic/cube.tar.gz")  # cached: no longer needed
        assert kb.AssetSource("s3://assets/kubasic").fetch("cube").is_dir()
        with pytest.raises(RemoteSourceError, match=r"^asset source s3://assets/elsewhere/"
                           r"manifest.json: not found$"):
            kb.AssetSource("s3://assets/elsewhere")


@pytest.mark.blender
@pytest.mark.slow
def test_generate_with_url_source_equals_local_path(published, tmp_path):
    """`kubric generate movi_a --set kubasic_source=URL` renders the scene of the local folder:
    the same metadata (but for the recorded option itself), events and every layer."""
    import numpy as np

    from kubric import file_io

    tiny = ["resolution=32", "frame_end=3", "samples=2", "denoise=false", "max_num_objects=5"]

    def generate(out, source):
        cmd = [sys.executable, "-m", "kubric", "generate", "movi_a", "--out", str(out),
               "--scenes", "1", "--first-seed", "7", "--workers", "1", "--no-progress",
               "--set", f"kubasic_source={source}"]
        for option in tiny:
            cmd += ["--set", option]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=400)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        return out / "scene_00000007"

    with serve(published) as server:
        url = f"{server.url}/kubasic"
        remote = generate(tmp_path / "remote", url)
    local = generate(tmp_path / "local", published / "kubasic")
    meta, ref = (file_io.read_json(d / "metadata.json") for d in (remote, local))
    assert meta["flags"].pop("kubasic_source") == url
    assert ref["flags"].pop("kubasic_source") == str(published / "kubasic")
    assert meta == ref
    for name in ("events.json", "data_ranges.json"):
        assert file_io.read_json(remote / name) == file_io.read_json(local / name)
    layers, ref_layers = file_io.read_image_dict(remote), file_io.read_image_dict(local)
    assert sorted(layers) == sorted(ref_layers) and "segmentation" in layers
    for layer, values in layers.items():
        np.testing.assert_array_equal(values, ref_layers[layer], err_msg=layer)
    assert server.gets["/kubasic/manifest.json"] == 1  # the runner's and the worker's open


def test_unsafe_remote_archives_are_refused(published, tmp_path):
    """The downloaded archive goes through the same checks as a local one: a member with '..'
    or a link escaping the folder is refused and nothing lands outside the extraction folder."""
    import io
    import tarfile

    from kubric.assets.archive import UnsafeArchiveError

    def archive(name, member):
        with tarfile.open(published / "kubasic" / name, "w:gz") as tar:
            if member.issym():
                tar.addfile(member)
            else:
                member.size = 4
                tar.addfile(member, io.BytesIO(b"evil"))

    archive("cube.tar.gz", tarfile.TarInfo("../../escaped.txt"))
    link = tarfile.TarInfo("visual_geometry.obj")
    link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
    archive("cone.tar.gz", link)
    manifest = json.loads((published / "kubasic" / "manifest.json").read_text())
    for entry in manifest["assets"].values():
        entry.pop("sha256")  # the publisher's own (bad) archives
    manifest["assets"]["sphere"]["path"] = "../sphere.tar.gz"  # names a URL, not a file
    manifest["assets"]["torus"]["path"] = "../../torus.tar.gz"
    (published / "kubasic" / "manifest.json").write_text(json.dumps(manifest))
    with serve(published) as server:
        source = kb.AssetSource(f"{server.url}/kubasic")
        refused = [
            (UnsafeArchiveError, "cube", r"^asset 'cube': archive member '../../escaped.txt' "
             r"leaves the extraction directory"),
            (UnsafeArchiveError, "cone", r"^asset 'cone': archive member 'visual_geometry.obj' "
             r"is a link \(to '/etc/passwd'\)"),
            (RemoteSourceError, "sphere", r"^asset 'sphere' \(http://127.0.0.1:\d+/sphere.tar.gz"
             r"\): HTTP 404 File not found$"),
            (RemoteSourceError, "torus", r"^asset 'torus': path '../../torus.tar.gz' climbs "
             r"above http://127.0.0.1:\d+/$")]
        for error, asset_id, pattern in refused:
            with pytest.raises(error, match=pattern):
                source.fetch(asset_id)
    assert not list(tmp_path.rglob("escaped.txt"))
    assert not any(p.is_symlink() for p in tmp_path.rglob("*"))
