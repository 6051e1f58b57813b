"""Round-two hostile tests (issue #27) of asset sources at URLs: a download is complete or absent
(a truncated archive without Content-Length, a file that is no archive), an overall deadline
(a trickling server), and no staging folder left by a killed extraction."""

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time

import pytest
from http_helpers import serve

import kubric as kb
from kubric.asset_tools import ensure_kubasic
from kubric.assets.archive import CorruptArchiveError, safe_extract
from kubric.assets.remote_source import RemoteSourceError, cache_folder


@pytest.fixture
def unchecked(tmp_path, monkeypatch):
    """A copy of KuBasic whose manifest has no checksums (as the published KuBasic 1.x)."""
    root = tmp_path / "www"
    shutil.copytree(ensure_kubasic().manifest_path.parent, root / "kubasic")
    manifest = json.loads((root / "kubasic" / "manifest.json").read_text())
    for entry in manifest["assets"].values():
        entry.pop("sha256", None)
        entry.pop("md5", None)
    (root / "kubasic" / "manifest.json").write_text(json.dumps(manifest))
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))
    return root


def _cached(url):
    folder = cache_folder(url) / "archives"
    return sorted(p.name for p in folder.iterdir() if not p.name.endswith(".lock")) \
        if folder.exists() else []


def test_item3_truncated_archive_without_length_is_never_cached(unchecked):
    with serve(unchecked) as server:
        url = f"{server.url}/kubasic"
        source = kb.AssetSource(url)
        server.unannounced.add("/kubasic/cube.tar.gz")
        with pytest.raises(CorruptArchiveError, match=r"asset 'cube' \(.*cube.tar.gz\): not a "
                           r"complete archive \(truncated"):
            source.fetch("cube")
        assert _cached(url) == []  # neither the half archive nor a .part file
        server.unannounced.clear()  # the server is fixed: the next try succeeds
        assert (source.fetch("cube") / "visual_geometry.obj").is_file()
        source.close()


def test_item11_a_non_archive_is_never_cached(unchecked):
    (unchecked / "kubasic" / "cone.tar.gz").write_bytes(os.urandom(1 << 20))
    with serve(unchecked) as server:
        url = f"{server.url}/kubasic"
        source = kb.AssetSource(url)
        with pytest.raises(CorruptArchiveError, match=r"asset 'cone' .*not a complete archive"):
            source.fetch("cone")
        assert _cached(url) == []
        source.close()


def test_item7_trickling_server_fails_at_the_deadline(unchecked, monkeypatch):
    monkeypatch.setenv("KUBRIC_FETCH_DEADLINE", "2")
    monkeypatch.setenv("KUBRIC_FETCH_TIMEOUT", "30")  # longer than the test: only the deadline
    with serve(unchecked) as server:
        url = f"{server.url}/kubasic"
        source = kb.AssetSource(url)
        server.trickle["/kubasic/cube.tar.gz"] = 0.05  # one byte every 50 ms: never a timeout
        start = time.monotonic()
        with pytest.raises(RemoteSourceError, match=r"asset 'cube' .*: not complete within "
                           r"\$KUBRIC_FETCH_DEADLINE = 2 s \(\d+ bytes so far\)$"):
            source.fetch("cube")
        assert time.monotonic() - start < 10
        assert _cached(url) == []
        source.close()


def test_item7_builder_downloads_have_the_deadline_too(unchecked, tmp_path, monkeypatch):
    from kubric.assets.download import DownloadError, fetch_file
    monkeypatch.setenv("KUBRIC_FETCH_DEADLINE", "1.5")
    with serve(unchecked) as server:
        server.trickle["/kubasic/cube.tar.gz"] = 0.05
        start = time.monotonic()
        with pytest.raises(DownloadError, match=r"not complete within \$KUBRIC_FETCH_DEADLINE"):
            fetch_file(f"{server.url}/kubasic/cube.tar.gz", tmp_path / "cube.tar.gz")
        assert time.monotonic() - start < 10 and not (tmp_path / "cube.tar.gz").exists()


def test_item3_builders_record_checksums(tmp_path):
    from kubric.asset_tools.writer import write_manifest
    (tmp_path / "a.tar.gz").write_bytes(b"archive bytes")
    write_manifest(tmp_path / "manifest.json", "x", "1.0",
                   {"a": {"asset_type": "Texture"}, "b": {"asset_type": "Texture",
                                                          "sha256": "given"}})
    assets = json.loads((tmp_path / "manifest.json").read_text())["assets"]
    assert assets["a"]["sha256"] == hashlib.sha256(b"archive bytes").hexdigest()
    assert assets["b"]["sha256"] == "given"


KILL_MID_EXTRACT = """
import sys, os, signal
from kubric.assets import archive
real = archive._write_checked
def write_then_die(checked, staging, *args, **kwargs):
    (staging / "partial.bin").write_bytes(b"x" * 1000)
    os.kill(os.getpid(), signal.SIGKILL)
archive._write_checked = write_then_die
archive.safe_extract(sys.argv[1], sys.argv[2], "cube")
"""


def test_item11_staging_of_a_killed_extraction_is_removed(tmp_path):
    cube = ensure_kubasic().manifest_path.parent / "cube.tar.gz"
    target = tmp_path / "extract" / "cube"
    run = subprocess.run([sys.executable, "-c", KILL_MID_EXTRACT, str(cube), str(target)],
                         capture_output=True, timeout=120)
    assert run.returncode == -9
    left = [p.name for p in (tmp_path / "extract").iterdir()]
    assert len(left) == 1 and left[0].startswith(".cube.staging-")  # the kill left it
    safe_extract(cube, target, "cube")
    assert [p.name for p in (tmp_path / "extract").iterdir()] == ["cube"]
