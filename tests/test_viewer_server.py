"""`kubric view`'s server on synthetic scene directories: endpoints against the files, path
traversal refused, read-only, corrupt / incomplete scenes answered with errors (not crashes)."""

import io
import os
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from PIL import Image
from viewer_helpers import CAMERA_TO_WORLD, FOCAL_PX, H, W, get_json, request, serving, synthetic_scene

from kubric.annotations import pictures as render
from kubric.io.png_io import decode_png
from kubric.viewer.service import LRUCache
from kubric.viewer.source import DirectorySource

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def dataset(tmp_path):
    root = tmp_path / "data"
    layers, meta = synthetic_scene(root / "scene_00000003")
    synthetic_scene(root / "scene_00000004", seed=4)
    (tmp_path / "secret.txt").write_text("TOP-SECRET")
    return root, layers, meta


def _png(body):
    return np.asarray(Image.open(io.BytesIO(body)))


def test_scene_list_and_metadata(dataset):
    root, layers, meta = dataset
    synthetic_scene(root / "scene_00000009", seed=9, success=False)  # incomplete
    (root / ".scene_00000010.incomplete-123").mkdir()  # a worker's hidden work dir: not listed
    with serving(root) as (addr, _):
        status, body = get_json(addr, "/api/scenes")
        assert status == 200
        rows = {r["name"]: r for r in body["scenes"]}
        assert sorted(rows) == ["scene_00000003", "scene_00000004", "scene_00000009"]
        row = rows["scene_00000003"]
        assert (row["recipe"], row["seed"], row["num_instances"], row["num_frames"]) == \
            ("movi_a", 3, 1, 3)
        assert row["resolution"] == [W, H] and row["error"] is None
        # in the order of the one layer vocabulary (kubric.io.layers.LAYERS)
        assert row["layers"] == ["rgba", "depth", "segmentation", "forward_flow", "normal"]
        assert "_SUCCESS" in rows["scene_00000009"]["error"]
        status, scene = get_json(addr, "/api/scene/scene_00000003")
        assert status == 200 and scene["metadata"] == meta
        assert scene["events"]["collisions"][0]["force"] == 2.0
        assert scene["worker_command"] == (
            f"kubric worker movi_a --seed 3 --out {root} --set denoise=false "
            "--set kubasic_source=none --set resolution=16,12 --set samples=2")  # keys sorted
        hit = layers["depth"][0][layers["depth"][0] < 1000]
        assert scene["depth_range"] == pytest.approx([hit.min(), hit.max()])
        # the page's layer vocabulary comes from the server: labels, kinds, the depth-like
        # layers' first ranges (the page keeps no list of its own)
        from kubric.io.layers import LAYER_LABELS, LAYERS
        assert set(scene["layers"]) == set(LAYERS)
        for name, info in scene["layers"].items():
            assert (info["label"], info["kind"]) == (LAYER_LABELS[name], LAYERS[name].kind)
            assert info["adjustable_range"] == (LAYERS[name].kind == "tiff")
        assert scene["layers"]["depth"]["range"] == pytest.approx([hit.min(), hit.max()])
        assert "range" not in scene["layers"]["z"]  # the scene has no z layer
        # the page and its scripts
        status, ctype, html = request(addr, "/")
        assert status == 200 and ctype.startswith("text/html") and b"sceneview.js" in html


def test_frames_are_the_files_pictures(dataset):
    root, layers, _ = dataset
    with serving(root) as (addr, _):
        status, ctype, body = request(addr, "/api/frame/scene_00000003/rgba/1.png")
        assert (status, ctype) == (200, "image/png")
        np.testing.assert_array_equal(_png(body), layers["rgba"][1])
        _, _, body = request(addr, "/api/frame/scene_00000003/segmentation/2.png")
        palette = render.label_palette(2)
        np.testing.assert_array_equal(_png(body), palette[layers["segmentation"][2, ..., 0]])
        # depth: colour map over the requested range; background black
        _, _, body = request(addr, "/api/frame/scene_00000003/depth/0.png?lo=10&hi=11")
        pic = _png(body)
        assert (pic[0, 0] == 0).all()
        d = layers["depth"][0, ..., 0]
        near, far = np.unravel_index(np.argmin(d), d.shape), np.unravel_index(
            np.argmax(np.where(d < 1000, d, 0)), d.shape)
        assert pic[near].sum() < pic[far].sum()  # viridis: near dark, far bright
        # outline: opaque exactly on the object's rim pixels
        _, _, body = request(addr, "/api/frame/scene_00000003/outline/0.png")
        alpha = _png(body)[..., 3] > 0
        square = layers["segmentation"][0, ..., 0] == 1
        interior = square.copy()
        interior[1:-1, 1:-1] = square[1:-1, 1:-1] & square[:-2, 1:-1] & square[2:, 1:-1] & \
            square[1:-1, :-2] & square[1:-1, 2:]
        np.testing.assert_array_equal(alpha, square & ~interior)


def test_flow_colour_wheel():
    """Middlebury wheel: zero flow white; right red, left cyan, down yellow-ish, up blue-ish."""
    flow = np.float32([[[0, 0], [0, 1], [0, -1], [1, 0], [-1, 0]]])  # (Δrow, Δcol)
    pic = render.flow_picture(flow, max_flow=1.0)[0].astype(int)
    assert (pic[0] == 255).all()
    right, left, down, up = pic[1:]
    assert right[0] == 255 and right[1] < 60
    assert left[0] < 60 and left[1] > 200 and left[2] > 200
    assert down[0] == 255 and down[1] > 150 and down[2] < 60
    assert up[2] == 255 and up[1] < 60


def test_probe_reads_the_files_and_unprojects(dataset):
    root, layers, meta = dataset
    with serving(root) as (addr, _):
        row, col, t = 5, 6, 1
        status, p = get_json(addr, f"/api/probe/scene_00000003/{t}?row={row}&col={col}")
        assert status == 200
        assert (p["label"], p["instance"], p["asset_id"]) == (1, 0, "cube")
        assert p["depth"] == pytest.approx(float(layers["depth"][t, row, col, 0]))
        rng = layers["forward_flow"][..., 0].max() - layers["forward_flow"][..., 0].min()
        np.testing.assert_allclose(p["forward_flow"], layers["forward_flow"][t, row, col],
                                   atol=rng / 65535)
        # independent derivation: the camera looks down -z from z = 10 (world y is image up)
        ray = np.array([(col + 0.5 - W / 2) / FOCAL_PX, -(row + 0.5 - H / 2) / FOCAL_PX, -1.0])
        expected = CAMERA_TO_WORLD[:3, 3] + ray / np.linalg.norm(ray) * p["depth"]
        np.testing.assert_allclose(p["point"], expected, atol=1e-9)
        _, bg = get_json(addr, f"/api/probe/scene_00000003/{t}?row=0&col=0")
        assert bg["background"] and bg["point"] is None and bg["instance"] is None
        status, err = get_json(addr, f"/api/probe/scene_00000003/{t}?row={H}&col=0")
        assert status == 404 and "outside" in err["error"]
        status, err = get_json(addr, "/api/probe/scene_00000003/1?row=x&col=0")
        assert status == 400 and "row" in err["error"]


@pytest.mark.parametrize("target", [
    "/static/../../secret.txt", "/static/%2e%2e/%2e%2e/secret.txt", "/static/%252e%252e/secret.txt",
    "/api/scene/..", "/api/scene/%2e%2e%2fsecret.txt", "/api/scene/..%2F..%2Fsecret.txt",
    "/api/scene/%2Fetc%2Fpasswd", "/api/scene//etc/passwd", "//etc/passwd", "/static/%2Fetc%2Fpasswd",
    "/api/frame/..%5c..%5csecret.txt/rgba/0.png", "/api/scene/scene_00000003%00",
    "/api/frame/scene_00000003/..%252F..%252Fsecret/0.png", "/static/..%c0%af..%c0%afsecret.txt",
    "/api/scene/~root", "/api/scene/C:secret.txt", "/../secret.txt", "/static/app.js/../../../x",
    "/api/scene/.hidden", "/api/scene/scene_99999999",
])
def test_path_traversal_is_refused(dataset, target):
    root, _, _ = dataset
    with serving(root) as (addr, _):
        status, ctype, body = request(addr, target)
        assert status in (400, 404), (target, status)
        assert b"TOP-SECRET" not in body and b"root:" not in body
        assert ctype == "application/json"


def test_server_never_writes(dataset):
    root, _, _ = dataset
    def tree():
        return {(p.relative_to(root.parent), p.stat().st_size, p.stat().st_mtime_ns)
                for p in root.parent.rglob("*")}
    before = tree()
    with serving(root) as (addr, _):
        for method in ("POST", "PUT", "DELETE", "PATCH"):
            status, _, body = request(addr, "/api/scene/scene_00000003", method)
            assert status == 405 and b"read-only" in body
        for target in ("/api/scenes", "/api/scene/scene_00000003", "/api/tracks/scene_00000003",
                       "/api/frame/scene_00000003/depth/0.png", "/api/probe/scene_00000003/0?row=1&col=1"):
            assert request(addr, target)[0] == 200
    assert tree() == before


def test_corrupt_and_incomplete_scenes_give_errors_not_crashes(dataset):
    root, _, _ = dataset
    png = root / "scene_00000004" / "rgba_00001.png"
    png.write_bytes(png.read_bytes()[:60])  # truncated
    (root / "scene_00000004" / "depth_00002.tiff").write_bytes(b"II*\x00garbage")
    broken = root / "scene_00000005"
    broken.mkdir()
    (broken / "metadata.json").write_text("{not json")
    with serving(root) as (addr, _):
        for target, word in (("/api/frame/scene_00000004/rgba/1.png", "rgba"),
                             ("/api/frame/scene_00000004/depth/2.png", "depth"),
                             ("/api/scene/scene_00000005", "metadata.json")):
            status, err = get_json(addr, target)
            assert status == 422 and word in err["error"], (target, err)
        assert request(addr, "/api/frame/scene_00000004/rgba/0.png")[0] == 200  # still serving
        status, err = get_json(addr, "/api/frame/scene_00000004/rgba/7.png")
        assert status == 404 and "frame 7" in err["error"]
        status, err = get_json(addr, "/api/frame/scene_00000004/bogus/0.png")
        assert status == 404 and "bogus" in err["error"]
        _, body = get_json(addr, "/api/scenes")
        errors = {r["name"]: r["error"] for r in body["scenes"]}
        assert "unreadable" in errors["scene_00000005"] and errors["scene_00000003"] is None


def test_new_and_finished_scenes_appear(dataset, monkeypatch):
    """Scenes written while the server runs show up; an incomplete one turns ok with _SUCCESS."""
    import kubric.viewer.source as source_module
    monkeypatch.setattr(source_module, "RESCAN_SECONDS", 0.0)
    root, _, _ = dataset
    with serving(root) as (addr, _):
        assert len(get_json(addr, "/api/scenes")[1]["scenes"]) == 2
        synthetic_scene(root / "scene_00000007", seed=7, success=False)
        rows = {r["name"]: r for r in get_json(addr, "/api/scenes")[1]["scenes"]}
        assert "_SUCCESS" in rows["scene_00000007"]["error"]
        (root / "scene_00000007" / "_SUCCESS").write_text("")
        rows = {r["name"]: r for r in get_json(addr, "/api/scenes")[1]["scenes"]}
        assert rows["scene_00000007"]["error"] is None


def test_frames_are_cached(dataset):
    root, _, _ = dataset
    with serving(root) as (addr, service):
        request(addr, "/api/frame/scene_00000003/rgba/0.png")
        misses = service.cache.misses
        request(addr, "/api/frame/scene_00000003/rgba/0.png")
        assert service.cache.misses == misses and service.cache.hits >= 1
    cache = LRUCache(max_bytes=250)
    for k in range(5):
        cache.get_or_make(k, lambda: np.zeros(100, np.uint8))
    assert list(cache._items) == [3, 4]
    cache.get_or_make(3, lambda: pytest.fail("3 is cached"))


def test_source_refuses_unknown_names(dataset):
    root, _, _ = dataset
    source = DirectorySource(root / "scene_00000003")  # a single scene directory
    assert source.names() == ["scene_00000003"]
    for bad in ("..", "scene_00000004", "/etc", "a/b", ""):
        with pytest.raises(KeyError):
            source.check_name(bad)
    with pytest.raises(NotADirectoryError, match="not a directory"):
        DirectorySource(root / "missing")


def test_cli_serves_and_reports_bad_paths(dataset, tmp_path):
    root, _, _ = dataset
    bad = subprocess.run([sys.executable, "-m", "kubric", "view", str(tmp_path / "nope")],
                         capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 1 and "not a directory" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    proc = subprocess.Popen([sys.executable, "-m", "kubric", "view", str(root), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        line = proc.stdout.readline()
        assert "serving 2 scene(s)" in line and "http://127.0.0.1:" in line
        port = int(line.rsplit(":", 1)[1].split("/")[0])
        status, body = get_json(("127.0.0.1", port), "/api/scenes")
        assert status == 200 and len(body["scenes"]) == 2
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_static_files_ship_in_the_wheel(tmp_path):
    """A wheel built from the sources (in a copy: nothing is written into the checkout) holds
    every file of the page, and the page loads only its own files (no CDN)."""
    src = tmp_path / "src"
    shutil.copytree(os.path.join(ROOT, "kubric"), src / "kubric",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(os.path.join(ROOT, name), src / name)
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "-w",
                            str(tmp_path / "dist"), str(src)], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr[-2000:]
    (wheel,) = (tmp_path / "dist").glob("kubric-*.whl")
    in_wheel = set(zipfile.ZipFile(wheel).namelist())
    static = os.path.join(ROOT, "kubric", "viewer", "static")
    html = open(os.path.join(static, "index.html")).read()
    for name in os.listdir(static):
        assert f"kubric/viewer/static/{name}" in in_wheel, name
        if name.endswith((".js", ".css")):
            assert f"/static/{name}" in html, name
    assert "http://" not in html and "https://" not in html


def test_decode_png_of_rendered_frames_round_trip():
    pic = render.picture("normal", np.float32([[[0, 0, 1], [1, 0, 0]]]))
    decoded, _ = decode_png(render.to_png(pic))
    np.testing.assert_array_equal(decoded, [[[128, 128, 255], [255, 128, 128]]])


def test_a_recipe_s_own_layers_are_shown_through_its_schema(tmp_path):
    """Layers a recipe declares in its schema (klevr's semantic labels, texture_nerf's bands and
    cut-off TIFFs) are listed and drawn by their kind, found through the scene's recipe."""
    from kubric.io.layers import LayerFormat
    from kubric.io.scene_writer import write_scene
    from kubric.io.schema import Feature, Schema
    from kubric.pipeline import Recipe

    schema = Schema("test_viewer_own_layers", (
        Feature("parts", "uint8", ("T", "H", "W", 1), "layer:parts", "png"),
        Feature("heat", "float32", ("T", "H", "W", 1), "layer:heat", "zlib")),
        {"parts": LayerFormat("parts_{:05d}.png", 1, "labels"),
         "heat": LayerFormat("heat_{:05d}.tiff", 1, "tiff")})

    class OwnLayers(Recipe, name="test_viewer_own_layers"):
        pass
    OwnLayers.schema = schema
    parts = np.zeros((2, 4, 5, 1), np.uint8)
    parts[:, 1:3, 1:4] = 2
    heat = np.linspace(0, 1, 2 * 4 * 5, dtype=np.float32).reshape(2, 4, 5, 1)
    scene = tmp_path / "scene_00000001"
    write_scene(schema, scene, {"parts": parts, "heat": heat},
                {"flags": {"recipe": "test_viewer_own_layers"},
                 "metadata": {"resolution": [5, 4], "num_frames": 2}})
    (scene / "_SUCCESS").write_text("{}")
    from kubric.io.schema import register_schema
    register_schema(schema)
    with serving(tmp_path) as (addr, _):
        _, body = get_json(addr, "/api/scenes")
        assert body["scenes"][0]["layers"] == ["parts", "heat"]
        _, _, body = request(addr, "/api/frame/scene_00000001/parts/1.png")
        np.testing.assert_array_equal(_png(body), render.label_palette(3)[parts[1, ..., 0]])
        _, _, body = request(addr, "/api/frame/scene_00000001/heat/0.png")
        pic = _png(body)
        np.testing.assert_array_equal(pic, render.depth_picture(heat[0], float(heat[0].min()),
                                                                float(heat[0].max()), np.inf))
        assert request(addr, "/api/frame/scene_00000001/nope/0.png")[0] == 404
