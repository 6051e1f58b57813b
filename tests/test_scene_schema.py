"""A scene directory describes itself (``schema.json``, written by ``write_scene``): a file
recipe's scene packs, inspects, views and exports in fresh processes that cannot import the
recipe; an older scene without the file falls back to its recipe's name; an unknown schema and
disagreeing scenes fail in one line; every file of a scene is declared to the writer."""

import json
import os
import pathlib
import shutil
import subprocess
import sys

import numpy as np
import pytest

from kubric.io import scene_dir
from kubric.io.scene_writer import write_scene
from kubric.io.schema import Feature, Schema, SchemaError
from kubric.io.stored_schema import check_declared
from kubric.pipeline import Recipe
from kubric.pipeline.worker import run_scene
from kubric.recipes.bench import Bench

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = ROOT / "tests" / "no_bpy"
T, H, W = 2, 4, 6


def kubric(*args, cwd, pythonpath=(ROOT,)):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(map(str, pythonpath)))
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def spheres_scene(root: pathlib.Path, seed: int = 1) -> pathlib.Path:
    """A scene of docs/architecture.md's file recipe (raycast, no Blender); the recipe's file
    is removed afterwards, so no later process can import it."""
    from test_architecture_doc import blocks
    (root / "spheres.py").write_text(blocks()[("file", "spheres.py")])
    proc = kubric("worker", "spheres.py:Spheres", "--seed", seed, "--set", "num_frames=2",
                  "--out", "out", cwd=root, pythonpath=(NO_BPY, ROOT))
    assert proc.returncode == 0, proc.stderr[-3000:]
    (root / "spheres.py").unlink()
    return root / "out" / scene_dir.scene_name(seed)


def _one_line_failure(proc) -> str:
    assert proc.returncode == 1, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    line, = proc.stderr.strip().splitlines()
    return line


def test_file_recipe_scene_stores_its_schema_and_exports_in_a_fresh_process(tmp_path):
    scene = spheres_scene(tmp_path)
    doc = json.loads((scene / scene_dir.SCHEMA_FILE).read_text())
    meta = json.loads((scene / scene_dir.METADATA_FILE).read_text())
    # the document is the recipe's schema, its options and files, as the page describes
    assert doc["name"] == doc["recipe"] == meta["flags"]["recipe"] == "spheres"
    assert doc["options"] == {k: v for k, v in meta["flags"].items() if k not in ("recipe",
                                                                                  "seed")}
    assert doc["options"]["num_frames"] == 2 and doc["files"] == [] and doc["variants"] == []
    assert doc["layers"] == {"height": {"template": "height_{:05d}.tiff", "channels": 1,
                                        "kind": "tiff"}}
    assert [f["name"] for f in doc["features"]][-3:] == ["height", "instances/positions",
                                                         "instances/bboxes"]
    # COCO export in a fresh process: every frame, the instances' masks
    out = tmp_path / "coco.json"
    proc = kubric("export", "coco", "out", "--out", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    coco = json.loads(out.read_text())
    assert len(coco["images"]) == 2
    labels = {a["id"] % 10_000 for a in coco["annotations"]}
    assert labels == set(range(1, len(meta["instances"]) + 1)) - {
        k + 1 for k, inst in enumerate(meta["instances"]) if not any(inst["visibility"])}


def test_older_scenes_pack_by_recipe_name_identically(tmp_path):
    for seed in range(3):
        run_scene(Bench(), seed, tmp_path / "new")
    shutil.copytree(tmp_path / "new", tmp_path / "old")
    for scene in (tmp_path / "old").iterdir():
        (scene / scene_dir.SCHEMA_FILE).unlink()
    runs = {}
    for kind in ("new", "old"):
        runs[kind] = kubric("pack", kind, "--out", f"ds_{kind}", "--splits", "train=1",
                            "--verify", "--no-progress", cwd=tmp_path)
        assert runs[kind].returncode == 0, runs[kind].stderr
    assert "schema: bench, stored by the scenes (schema.json)" in runs["new"].stdout
    assert "schema: bench, from the scenes' recipe 'bench' (no schema.json): written by an " \
        "older kubric, they do not store their schema, so their recipe was imported" in \
        runs["old"].stdout
    shards = sorted(p.name for p in (tmp_path / "ds_new").iterdir() if "array_record" in p.name)
    assert shards and all((tmp_path / "ds_new" / n).read_bytes()
                          == (tmp_path / "ds_old" / n).read_bytes() for n in shards)
    # an older scene whose metadata.json is broken is a corrupt scene, skipped by name
    (tmp_path / "old" / scene_dir.scene_name(1) / scene_dir.METADATA_FILE).write_text("[]")
    proc = kubric("pack", "old", "--out", "ds_broken", "--splits", "train=1", "--no-progress",
                  cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "packed 2 scenes" in proc.stdout
    assert "skipped corrupt scene old/scene_00000001: " in proc.stdout


def test_unknown_schema_fails_in_one_line_and_inspect_and_view_say_so(tmp_path):
    scene = spheres_scene(tmp_path)
    (scene / scene_dir.SCHEMA_FILE).unlink()  # as if written before scenes stored their schema
    line = _one_line_failure(kubric("pack", tmp_path / "out", "--out", "ds", "--splits", "train=1",
                                    cwd=tmp_path))
    assert f"{str(scene)!r} stores no schema.json" in line
    assert "its recipe 'spheres' is not known here (recipes: bench, " in line
    assert "its schema is unknown (pass --schema" in line
    assert not (tmp_path / "ds").exists()
    report = kubric("inspect", scene, "--sheet", tmp_path / "s.png", cwd=tmp_path)
    assert report.returncode == 0, report.stderr
    assert "  schema: none known: " in report.stdout and "'spheres' is not known" in report.stdout
    code = ("from kubric.viewer.source import DirectorySource;"
            f"print(DirectorySource({str(tmp_path / 'out')!r}).summary({scene.name!r})['layers'])")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                          capture_output=True, text=True, timeout=300)
    assert proc.stdout.strip() == "['rgba', 'depth', 'segmentation']", proc.stderr


def test_scenes_that_disagree_on_their_schema_fail_in_one_line(tmp_path):
    scene = spheres_scene(tmp_path)
    run_scene(Bench(), 7, tmp_path / "out")
    line = _one_line_failure(kubric("pack", tmp_path / "out", "--out", "ds", "--splits", "train=1",
                                    cwd=tmp_path))
    assert line.startswith("kubric pack: error: the scenes disagree on their schema: ")
    assert f"{str(scene)!r} has 'spheres' (from schema.json)" in line
    assert "scene_00000007' has 'bench' (from schema.json): pack them separately" in line
    # same name, one feature declared otherwise (e.g. a changed recipe between runs)
    shutil.rmtree(tmp_path / "out" / scene_dir.scene_name(7))
    twin = tmp_path / "out" / scene_dir.scene_name(2)
    shutil.copytree(scene, twin)
    doc = json.loads((twin / scene_dir.SCHEMA_FILE).read_text())
    doc["features"][4]["unit"] = "mm"
    (twin / scene_dir.SCHEMA_FILE).write_text(json.dumps(doc))
    line = _one_line_failure(kubric("pack", tmp_path / "out", "--out", "ds", "--splits", "train=1",
                                    cwd=tmp_path))
    assert "has 'spheres' with feature 'height' declared otherwise (from schema.json)" in line
    # a stored schema of a major version this code does not read
    doc["version"] = "2.0.0"
    (twin / scene_dir.SCHEMA_FILE).write_text(json.dumps(doc))
    line = _one_line_failure(kubric("pack", tmp_path / "out", "--out", "ds", "--splits", "train=1",
                                    cwd=tmp_path))
    assert f"{str(twin / 'schema.json')!r}: schema 'spheres' has version 2.0.0" in line


def test_schema_override_still_wins_and_checks_the_stored_name(tmp_path):
    for seed in range(2):
        run_scene(Bench(), seed, tmp_path / "scenes")
    doc_path = tmp_path / "scenes" / scene_dir.scene_name(1) / scene_dir.SCHEMA_FILE
    doc = json.loads(doc_path.read_text())
    doc.update(name="movi_a", recipe="movi_a", variants=["movi_a_tracks"])
    doc_path.write_text(json.dumps(doc))
    proc = kubric("pack", "scenes", "--out", "ds", "--splits", "train=1", "--schema", "bench",
                  "--no-progress", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "schema: bench (given)" in proc.stdout
    skipped, = [ln for ln in proc.stdout.splitlines() if "skipped corrupt scene" in ln]
    assert "scene_00000001' is a scene of recipe 'movi_a', not of the dataset's schema 'bench' " \
        "(its schemas: ['movi_a', 'movi_a_tracks']; pack it separately" in skipped, skipped


# ---------------------------------------------------------------- every file is declared
SMALL = Schema("test_declared", (
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png"),
))


def _documents(seed):
    rgba = np.random.RandomState(seed).randint(0, 256, (T, H, W, 4)).astype(np.uint8)
    meta = {"flags": {"recipe": SMALL.name, "seed": seed},
            "metadata": {"resolution": [W, H], "num_frames": T, "seed": seed}}
    return {"rgba": rgba}, meta


def test_writer_takes_moved_and_written_files_and_declares_them(tmp_path):
    made = tmp_path / "elsewhere" / "state.bin"
    made.parent.mkdir()
    made.write_bytes(b"\x00state")
    seen = {}

    def export(path):  # runs once the layers are written: reads one back
        from kubric.io.layers import read_image_dict
        seen["rgba"] = read_image_dict(tmp_path / "scene", ["rgba"])["rgba"]
        path.mkdir()
        (path / "x.txt").write_text("x")
    layers, meta = _documents(3)
    (tmp_path / "scene").mkdir()
    write_scene(SMALL, tmp_path / "scene", layers, meta,
                files={"state.bin": made, "export": export, "notes.json": {"a": 1}})
    np.testing.assert_array_equal(seen["rgba"], layers["rgba"])
    assert not made.exists() and (tmp_path / "scene" / "state.bin").read_bytes() == b"\x00state"
    doc = json.loads((tmp_path / "scene" / scene_dir.SCHEMA_FILE).read_text())
    assert doc["files"] == ["export", "notes.json", "state.bin"]
    check_declared(tmp_path / "scene")
    (tmp_path / "scene" / "stray.txt").write_text("")
    with pytest.raises(SchemaError, match=r"holds \['stray.txt'\], which nothing declares"):
        check_declared(tmp_path / "scene")


def test_writer_refuses_undeclared_files_and_bad_names(tmp_path):
    layers, meta = _documents(1)
    out = tmp_path / "a"
    out.mkdir()
    (out / "scene.bullet").write_bytes(b"written around the writer")
    with pytest.raises(SchemaError, match=r"'test_declared': the scene directory holds "
                       r"\['scene.bullet'\], which nothing declares"):
        write_scene(SMALL, out, layers, meta)
    for name in ("metadata.json", "sub/x.json", ".hidden", ""):
        with pytest.raises(SchemaError, match="must be a plain name"):
            write_scene(SMALL, tmp_path / "b", layers, meta, files={name: {}})
    with pytest.raises(SchemaError, match="'missing.bin': .* does not exist"):
        write_scene(SMALL, tmp_path / "c", layers, meta,
                    files={"missing.bin": tmp_path / "nope"})
    with pytest.raises(SchemaError, match="'x': its writer 'lazy' wrote nothing there"):
        def lazy(path):
            return None
        write_scene(SMALL, tmp_path / "d", layers, meta, files={"x": lazy})


class LateWriter(Recipe, name="test_declared"):
    """Writes a file after write_scene: the worker refuses the scene."""

    schema = SMALL

    def generate(self, seed, out_dir):
        layers, meta = _documents(seed)
        write_scene(self.schema, out_dir, layers, meta)
        (out_dir / "late.txt").write_text("too late")


def test_worker_refuses_a_file_written_after_the_writer(tmp_path):
    with pytest.raises(SchemaError, match=r"holds \['late.txt'\], which nothing declares"):
        run_scene(LateWriter(), 4, tmp_path)
    assert not (tmp_path / scene_dir.scene_name(4)).exists()
    assert not list(tmp_path.iterdir())


@pytest.mark.blender
def test_saved_state_goes_through_the_writer(tmp_path):
    """movi_a with save_state: scene.blend and scene.bullet are declared outputs (moved in by
    the writer), a .blend and a .bullet file that read back."""
    from test_every_recipe import MOVI
    sets = [a for o in MOVI + ["save_state=true"] for a in ("--set", o)]
    proc = kubric("worker", "movi_a", "--seed", 2, "--out", tmp_path / "out", *sets,
                  cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    scene = tmp_path / "out" / scene_dir.scene_name(2)
    doc = json.loads((scene / scene_dir.SCHEMA_FILE).read_text())
    assert doc["files"] == ["scene.blend", "scene.bullet"] and doc["options"]["save_state"]
    check_declared(scene)
    import bpy
    meta = json.loads((scene / scene_dir.METADATA_FILE).read_text())
    with bpy.data.libraries.load(str(scene / "scene.blend")) as (src, _):
        assert {i["asset_id"] for i in meta["instances"]} <= {o.split(".")[0]
                                                              for o in src.objects}
    import pybullet as pb
    client = pb.connect(pb.DIRECT)
    try:
        assert pb.loadBullet(str(scene / "scene.bullet"), physicsClientId=client)
    finally:
        pb.disconnect(client)
