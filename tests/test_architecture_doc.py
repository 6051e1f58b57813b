"""docs/architecture.md's worked examples, run as written: the recipe (with its extra layer) makes
a scene without Blender; the page's own commands then inspect, pack and view it in fresh
processes that cannot import the recipe (its file is gone: the scene's schema.json says it all);
the dataset loads through the example task; the backend, added to a copy of the package, changes
exactly the files the page says and renders a MOVi-A scene; the page's file counts are the ones
measured here."""

import contextlib
import filecmp
import http.client
import json
import os
import pathlib
import re
import shlex
import shutil
import subprocess
import sys

import numpy as np

from kubric.io import scene_dir
from kubric.io.palette import label_palette
from kubric.io.tiff_io import read_tiff

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
BLOCK = re.compile(r"<!-- (file|row): (\S+) -->\n```python\n(.*?)```", re.S)


def blocks() -> dict:
    """{(kind, path): code} of the page's marked code blocks."""
    return {(kind, path): code for kind, path, code in BLOCK.findall(DOC.read_text())}


def files_touched(section: str) -> int:
    text = DOC.read_text().split(f"## {section}", 1)[1]
    return int(re.search(r"\*\*Files touched: (\d+)\*\*", text).group(1))


def example_commands() -> list[list[str]]:
    """The ``kubric ...`` command lines of Example 1's shell block, split into arguments."""
    text = DOC.read_text().split("## Example 1", 1)[1].split("## Example 2", 1)[0]
    block = re.search(r"```sh\n(.*?)```", text, re.S).group(1)
    return [shlex.split(line) for line in block.splitlines() if line.strip()]


def _env(pythonpath) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join(map(str, pythonpath)))


def kubric(*args, cwd, pythonpath):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=cwd,
                          env=_env(pythonpath), capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, (args, proc.stdout[-2000:], proc.stderr[-3000:])
    return proc


@contextlib.contextmanager
def kubric_view(*args, cwd, pythonpath):
    """A ``kubric view ARGS --port 0`` server in a fresh process; yields (host, port)."""
    proc = subprocess.Popen([sys.executable, "-m", "kubric", *map(str, args), "--port", "0"],
                            cwd=cwd, env=_env(pythonpath), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        match = re.search(r"http://([^:/]+):(\d+)/", line)
        assert match, (line, proc.stderr.read() if proc.poll() is not None else "")
        yield match.group(1), int(match.group(2))
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def http_get(host: str, port: int, path: str) -> tuple[int, str, bytes]:
    conn = http.client.HTTPConnection(host, port, timeout=60)
    try:
        conn.request("GET", path)
        response = conn.getresponse()
        return response.status, response.getheader("Content-Type"), response.read()
    finally:
        conn.close()


def test_the_page_marks_every_example():
    found = blocks()
    assert {("file", "spheres.py"), ("file", "kubric/renderer/labels.py"),
            ("row", "kubric/renderer/base.py"), ("file", "height_task.py"),
            ("file", "kubric/datasets/exports/yolo.py"),
            ("row", "kubric/datasets/exports/__init__.py")} <= set(found)
    assert [files_touched(f"Example {i}") for i in range(1, 6)] == [1, 1, 2, 1, 2]


def test_recipe_layer_and_task_examples_run_as_written(tmp_path, monkeypatch):
    code = blocks()
    for name in ("spheres.py", "height_task.py"):
        (tmp_path / name).write_text(code[("file", name)])
    worker, inspect, pack, view = example_commands()
    assert [c[:2] for c in (worker, inspect, pack, view)] == [
        ["kubric", "worker"], ["kubric", "inspect"], ["kubric", "pack"], ["kubric", "view"]]
    assert "--schema" not in pack  # the scenes carry their schema
    # Example 1 + 2: one module; the scene is made with bpy blocked
    kubric(*worker[1:], cwd=tmp_path, pythonpath=[NO_BPY, ROOT])
    scene = tmp_path / "out" / scene_dir.scene_name(1)
    assert scene_dir.is_complete(scene)
    assert sorted(p.name for p in scene.glob("height_*.tiff")) == [
        f"height_{i:05d}.tiff" for i in range(4)]
    stored = json.loads((scene / scene_dir.SCHEMA_FILE).read_text())
    assert stored["name"] == "spheres" and stored["layers"]["height"]["kind"] == "tiff"
    assert stored["options"]["num_spheres"] == 3
    # from here on no process can import the recipe: its file is gone
    (tmp_path / "spheres.py").unlink()
    report = kubric(*inspect[1:], cwd=tmp_path, pythonpath=[ROOT]).stdout
    assert re.search(r"^  height +\(4, 48, 64, 1\) +float32", report, re.M), report
    assert "schema spheres (from schema.json): 7 features, every source present" in report
    packed = kubric(*pack[1:], cwd=tmp_path, pythonpath=[ROOT]).stdout
    assert "schema: spheres, stored by the scenes (schema.json)" in packed, packed
    with kubric_view(*view[1:], cwd=tmp_path, pythonpath=[ROOT]) as (host, port):
        status, _, body = http_get(host, port, "/api/scenes")
        assert status == 200
        row, = json.loads(body)["scenes"]
        assert row["layers"] == ["rgba", "depth", "segmentation", "height"], row
        status, kind, png = http_get(host, port, f"/api/frame/{scene.name}/height/2.png")
        assert (status, kind) == (200, "image/png") and png.startswith(b"\x89PNG")
    # Example 4: the task reads the new layer, equal to the files the recipe wrote
    monkeypatch.syspath_prepend(str(tmp_path))
    import height_task  # noqa: F401  (registers the task)

    from kubric.datasets import load
    frames = load(tmp_path / "spheres_ds", "train", task="height_maps")
    assert len(frames) == 4
    for t in range(4):
        item = frames[t]
        np.testing.assert_array_equal(item["height"], read_tiff(scene / f"height_{t:05d}.tiff")[..., 0])
        assert item["image"].shape == (48, 64, 3)
    meta = json.loads((scene / scene_dir.METADATA_FILE).read_text())
    top = max(p[2] for inst in meta["instances"] for p in inst["positions"]) + 0.4
    assert 0.3 < float(frames[0]["height"].max()) <= top + 1e-3  # a sphere's top, radius 0.4
    assert "spheres" not in sys.modules and not any(
        getattr(m, "__file__", None) == str(tmp_path / "spheres.py") for m in list(sys.modules.values()))


def package_with_example(tmp_path, file: str, registry: str, table: str) -> pathlib.Path:
    """A copy of the package with the page's ``file`` block written and its ``row`` block added
    as the last row of ``table`` (a dict literal ``TABLE = {...}`` in ``registry``); checks that
    exactly those two files differ from the package."""
    code = blocks()
    package = tmp_path / "pkg"
    shutil.copytree(ROOT / "kubric", package / "kubric",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (package / file).write_text(code[("file", file)])
    path = package / registry
    text = path.read_text()
    start = text.index(f"\n{table} = {{")
    end = text.index("\n}\n", start) + 1   # the table's closing brace
    path.write_text(text[:end] + code[("row", registry)] + text[end:])
    changed = _changed_files(ROOT / "kubric", package / "kubric")
    assert changed == sorted(str(pathlib.Path(f).relative_to("kubric")) for f in (file, registry))
    return package


def test_backend_example_touches_two_files_and_renders(tmp_path):
    from kubric.asset_tools import ensure_kubasic
    ensure_kubasic()  # built here (bpy makes one of its shapes), so the worker below needs no bpy
    package = package_with_example(tmp_path, "kubric/renderer/labels.py",
                                   "kubric/renderer/base.py", "BACKENDS")
    assert files_touched("Example 3") == 2
    kubric("worker", "movi_a", "--seed", 2, "--out", tmp_path / "out", "--set", "renderer=labels",
           "--set", "resolution=32", "--set", "frame_end=2", "--set", "max_num_objects=4",
           cwd=tmp_path, pythonpath=[NO_BPY, package])
    scene = tmp_path / "out" / scene_dir.scene_name(2)
    meta = json.loads((scene / scene_dir.METADATA_FILE).read_text())
    assert meta["metadata"]["renderer"]["engine"] == "LABELS"
    from kubric import file_io
    rgba = file_io.read_image_dict(scene)["rgba"]
    palette = {tuple(c) for c in label_palette(64)}
    assert {tuple(c) for c in rgba[..., :3].reshape(-1, 3)} <= palette
    # recipes ask the row's capabilities: one that needs photoreal RGB refuses it in one line
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(map(str, [NO_BPY, package])))
    refused = subprocess.run([sys.executable, "-m", "kubric", "worker", "complex_brdf", "--seed",
                              "1", "--out", str(tmp_path / "brdf"), "--set", "renderer=labels"],
                             cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert refused.returncode == 2
    assert refused.stderr == ("kubric worker: error: complex_brdf: renderer=labels cannot render "
                              "photoreal RGB (the complex_brdf recipe); backends that can: "
                              "blender\n")
    assert "`complex_brdf: renderer=labels cannot render photoreal RGB (the complex_brdf " \
        "recipe); backends\nthat can: blender`" in DOC.read_text()


def test_export_example_touches_two_files_and_matches_the_segmentation(tmp_path):
    from kubric.asset_tools import ensure_kubasic
    from kubric.io.layers import read_layer
    ensure_kubasic()
    package = package_with_example(tmp_path, "kubric/datasets/exports/yolo.py",
                                   "kubric/datasets/exports/__init__.py", "FORMATS")
    assert files_touched("Example 5") == 2
    kubric("worker", "movi_a", "--seed", 5, "--out", tmp_path / "out", "--set", "renderer=raycast",
           "--set", "resolution=32", "--set", "frame_end=2", "--set", "max_num_objects=5",
           cwd=tmp_path, pythonpath=[NO_BPY, package])
    assert "yolo" in kubric("export", "--help", cwd=tmp_path, pythonpath=[package]).stdout
    kubric("export", "yolo", "out", "--out", "yolo", cwd=tmp_path, pythonpath=[package])
    scene = tmp_path / "out" / scene_dir.scene_name(5)
    meta = json.loads((scene / scene_dir.METADATA_FILE).read_text())
    names = sorted({inst["asset_id"] for inst in meta["instances"]})
    assert f"names: {json.dumps(names)}" in (tmp_path / "yolo" / "data.yaml").read_text()
    seg = read_layer(scene, "segmentation")[..., 0]
    t, h, w = seg.shape
    seen = 0
    for frame in range(t):
        stem = f"{scene.name}_{frame:05d}"
        assert filecmp.cmp(tmp_path / "yolo" / "images" / f"{stem}.png",
                           scene / f"rgba_{frame:05d}.png", shallow=False)
        lines = (tmp_path / "yolo" / "labels" / f"{stem}.txt").read_text().splitlines()
        expected = []
        for k, inst in enumerate(meta["instances"]):   # label k + 1, independently of the boxes
            rows, cols = np.nonzero(seg[frame] == k + 1)
            if rows.size:
                x0, x1, y0, y1 = cols.min() / w, (cols.max() + 1) / w, rows.min() / h, (rows.max() + 1) / h
                expected.append([names.index(inst["asset_id"]), (x0 + x1) / 2, (y0 + y1) / 2,
                                 x1 - x0, y1 - y0])
        got = [[float(v) for v in line.split()] for line in lines]
        assert len(got) == len(expected)
        np.testing.assert_allclose(np.array(got).reshape(-1, 5), np.array(expected).reshape(-1, 5),
                                   atol=2e-6)
        seen += len(got)
    assert seen > 0


def _changed_files(a: pathlib.Path, b: pathlib.Path) -> list[str]:
    out = []
    for path in sorted(b.rglob("*.py")):
        rel = path.relative_to(b)
        if not (a / rel).is_file() or not filecmp.cmp(a / rel, path, shallow=False):
            out.append(str(rel))
    return out
