"""Round-two hostile tests (issue #27) of the viewer: every request answered with a status, one
bad scene an error card (not an empty list), finite query numbers, a real listen backlog."""

import concurrent.futures
import json
import shutil
import subprocess
import sys
import time

import pytest
from viewer_helpers import get_json, request, serving, synthetic_scene


@pytest.fixture()
def folder(tmp_path):
    for seed in (1, 2, 3):
        synthetic_scene(tmp_path / f"scene_{seed:08d}", seed=seed)
    return tmp_path


def test_item13_bad_metadata_is_an_error_card(folder):
    meta = folder / "scene_00000002" / "metadata.json"
    data = json.loads(meta.read_text())
    data["flags"] = []
    meta.write_text(json.dumps(data))
    with serving(folder) as (address, _):
        status, body = get_json(address, "/api/scenes")
        assert status == 200
        rows = {r["name"]: r for r in body["scenes"]}
        assert sorted(rows) == ["scene_00000001", "scene_00000002", "scene_00000003"]
        assert rows["scene_00000001"]["error"] is None and rows["scene_00000003"]["error"] is None
        assert "'flags' has the wrong shape" in rows["scene_00000002"]["error"]
        status, body = get_json(address, "/api/scene/scene_00000002")
        assert status == 422 and "'flags' has the wrong shape" in body["error"]


def test_item13_non_finite_depth_range_and_truncated_tracks(folder):
    tracks = folder / "scene_00000001" / "tracks.npz"
    tracks.write_bytes(b"PK\x03\x04 truncated")
    with serving(folder) as (address, _):
        for query in ("lo=nan", "lo=inf&hi=inf", "lo=0&hi=-inf", "hi=1e999"):
            status, body = get_json(address, f"/api/frame/scene_00000001/depth/0.png?{query}")
            assert status == 400 and "must be a finite number" in body["error"], query
        status, _, png = request(address, "/api/frame/scene_00000001/depth/0.png?lo=1&hi=20")
        assert status == 200 and png.startswith(b"\x89PNG")
        status, body = get_json(address, "/api/tracks/scene_00000001")
        assert status == 422 and "tracks.npz" in body["error"] and "truncated" in body["error"]


def test_item13_unexpected_errors_are_answered_500(folder, monkeypatch):
    with serving(folder) as (address, service):
        def broken(*args, **kwargs):
            raise ZeroDivisionError("a bug")
        monkeypatch.setattr(service, "probe", broken)
        status, body = get_json(address, "/api/probe/scene_00000001/0?row=1&col=1")
        assert status == 500 and body["error"] == "ZeroDivisionError: a bug"
        assert get_json(address, "/api/scenes")[0] == 200  # the server still answers


def test_item8_three_hundred_concurrent_requests_all_answered(folder):
    with serving(folder) as (address, _):
        start = time.monotonic()
        with concurrent.futures.ThreadPoolExecutor(300) as pool:
            statuses = list(pool.map(lambda _: request(address, "/api/scenes")[0], range(300)))
        seconds = time.monotonic() - start
    assert statuses == [200] * 300
    assert seconds < 30  # with a backlog of 5, dropped SYNs are retried after 1, 3, 7 ... s


def test_item8_listen_backlog_is_real(folder):
    from kubric.viewer.server import LISTEN_BACKLOG
    with serving(folder) as (address, _):
        if shutil.which("ss") is None:
            pytest.skip("ss (iproute2) is not installed")
        out = subprocess.run(["ss", "-ltnH", f"sport = :{address[1]}"], capture_output=True,
                             text=True).stdout.split()
        assert int(out[2]) == LISTEN_BACKLOG  # a listening socket's Send-Q is its backlog


def test_item17_view_error_has_one_prefix(tmp_path):
    run = subprocess.run([sys.executable, "-m", "kubric", "view", str(tmp_path / "none")],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 1
    assert run.stderr.strip() == (f"kubric view: error: {str(tmp_path / 'none')!r} is not a "
                                  "directory (give a scene directory or a folder of scenes)")
