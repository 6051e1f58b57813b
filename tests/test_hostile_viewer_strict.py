"""Round three (issue 41) of the viewer, on real scene folders and a real server on 127.0.0.1:
strict JSON out whatever a metadata.json holds (NaN, Infinity), a frame count the files do not
back (5,000,000 frames) refused instead of sent to the page, 405 for every method but GET / HEAD,
and no server path in an error."""

import json
import math

import pytest
from viewer_helpers import request, serving, synthetic_scene


def strict(body: bytes):
    """RFC 8259 JSON only: NaN / Infinity tokens are an error (the browser's JSON.parse)."""
    def refuse(token):
        raise ValueError(f"non-standard JSON token {token}")
    return json.loads(body, parse_constant=refuse)


@pytest.fixture()
def folder(tmp_path):
    for seed in (1, 2, 3):
        synthetic_scene(tmp_path / f"scene_{seed:08d}", seed=seed)
    return tmp_path


def _edit(folder, name, edit):
    meta = folder / name / "metadata.json"
    data = json.loads(meta.read_text())
    edit(data)
    meta.write_text(json.dumps(data))  # Python writes NaN / Infinity tokens


def test_nan_and_infinity_in_metadata_give_strict_json(folder):
    def poison(data):
        data["metadata"]["weird"] = [math.nan, math.inf, -math.inf, 1.5]
        data["instances"][0]["mass"] = math.nan
    _edit(folder, "scene_00000002", poison)
    assert "NaN" in (folder / "scene_00000002" / "metadata.json").read_text()
    with serving(folder) as (address, _):
        status, _, body = request(address, "/api/scenes")
        rows = {r["name"]: r for r in strict(body)["scenes"]}
        assert status == 200 and sorted(rows) == [f"scene_0000000{i}" for i in (1, 2, 3)]
        status, _, body = request(address, "/api/scene/scene_00000002")
        scene = strict(body)
        assert status == 200
        assert scene["metadata"]["metadata"]["weird"] == [None, None, None, 1.5]
        assert scene["metadata"]["instances"][0]["mass"] is None


def test_a_frame_count_the_files_do_not_back_is_refused(folder):
    _edit(folder, "scene_00000001", lambda d: d["metadata"].update(num_frames=5_000_000))
    _edit(folder, "scene_00000003", lambda d: d["metadata"].update(num_frames="lots"))
    with serving(folder) as (address, _):
        status, _, body = request(address, "/api/scenes")
        rows = {r["name"]: r for r in strict(body)["scenes"]}
        assert rows["scene_00000002"]["error"] is None and rows["scene_00000002"]["num_frames"]
        big = rows["scene_00000001"]
        assert big["num_frames"] is None and "claims 5000000 frames" in big["error"]
        assert "num_frames 'lots' is not a whole number" in rows["scene_00000003"]["error"]
        for name, says in (("scene_00000001", "the viewer shows at most 100000"),
                           ("scene_00000003", "num_frames 'lots'")):
            status, _, body = request(address, f"/api/scene/{name}")
            assert status == 422 and says in strict(body)["error"]
    _edit(folder, "scene_00000001", lambda d: d["metadata"].update(num_frames=50))
    with serving(folder) as (address, _):  # under the bound, but the files end at frame 1
        status, _, body = request(address, "/api/scene/scene_00000001")
        assert status == 422 and "claims 50 frames, but rgba frame 49 is missing" in \
            strict(body)["error"]


def test_every_other_method_is_405_and_errors_hide_server_paths(folder):
    (folder / "scene_00000002" / "rgba_00000.png").write_bytes(b"not a png")
    with serving(folder) as (address, _):
        for method in ("POST", "PUT", "DELETE", "PATCH", "OPTIONS", "TRACE", "PROPFIND"):
            status, _, body = request(address, "/api/scenes", method)
            assert status == 405, method
            assert "read-only" in strict(body)["error"]
        status, _, body = request(address, "/api/frame/scene_00000002/rgba/0.png")
        assert status >= 400
        assert str(folder) not in body.decode(), body
