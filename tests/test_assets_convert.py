"""Mesh-collection converter on a real third-party collection (pybullet_data) and on edge cases."""

from __future__ import annotations

import json

import numpy as np
import pytest
from asset_checks import assert_rests_on_floor, blender_import_bounds, drop_test

from kubric.asset_tools.converter import convert_collection, discover_jobs
from kubric.asset_tools.pybullet_collection import build_pybullet_collection
from kubric.assets import AssetSource

SUBSET = [f"random_urdfs/{i:03d}" for i in (0, 3, 23, 101, 257, 512, 700, 999)] + ["duck",
                                                                                    "teddy"]


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def pybullet_subset(tmp_path_factory):
    out = tmp_path_factory.mktemp("pybullet_objects")
    report = build_pybullet_collection(out, workers=2, progress=False, only=SUBSET)
    source = AssetSource(out, scratch_dir=tmp_path_factory.mktemp("extracted"))
    return source, report


def test_pybullet_subset_converts_completely(pybullet_subset):
    source, report = pybullet_subset
    assert report["skipped"] == [] and report["converted"] == len(SUBSET)
    assert source.all_asset_ids == sorted(SUBSET)
    assert source.categories == ["random_urdfs", "textured_models"]
    duck = source.db["duck"]
    assert duck["metadata"]["category"] == "textured_models"
    assert "SCEA" in duck["license"]
    assert duck["kwargs"]["render_filename"] == "{asset_dir}/visual_geometry.glb"
    for entry in source.db.values():
        assert entry["kwargs"]["mass"] > 0
        assert entry["metadata"]["nr_faces"] > 0 and entry["metadata"]["volume"] > 0


def test_pybullet_subset_loads_and_rests_in_pybullet(pybullet_subset):
    source, _ = pybullet_subset
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        state = drop_test(obj.simulation_filename, obj.bounds, obj.mass)
        assert_rests_on_floor(state, obj.mass)


def test_duck_keeps_its_texture(pybullet_subset):
    import trimesh

    source, _ = pybullet_subset
    scene = trimesh.load(source.create("duck").render_filename)
    mesh = next(iter(scene.geometry.values()))
    image = mesh.visual.material.baseColorTexture
    assert image is not None and image.size == (512, 512)


@pytest.mark.blender
def test_pybullet_subset_loads_in_blender(pybullet_subset):
    pytest.importorskip("bpy")
    import bpy

    source, _ = pybullet_subset
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        bounds = np.asarray(obj.bounds, dtype=np.float64)
        got = blender_import_bounds(obj.render_filename, dict(obj.render_import_kwargs))
        np.testing.assert_allclose(got, bounds, atol=1e-5 + 1e-4 * np.ptp(bounds),
                                   err_msg=asset_id)
        if asset_id == "duck":
            images = [n.image for m in bpy.data.materials if m.node_tree
                      for n in m.node_tree.nodes if n.type == "TEX_IMAGE"]
            assert images and images[0].size[:] == (512, 512)


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_unit_cube_and_broken_meshes(tmp_path):
    import trimesh

    src = tmp_path / "meshes"
    src.mkdir()
    trimesh.creation.box(extents=(1, 1, 1)).export(src / "unit_cube.obj")
    _write(src / "unit_cube.json", json.dumps({"category": "box", "description": "a 1 m cube"}))
    (src / "nested").mkdir()
    trimesh.creation.box(extents=(1, 2, 3)).export(src / "nested" / "brick.stl")
    _write(src / "garbage.obj", "v 0 0 0\nv 1 0 0\nf 1 2 7\nthis is not an obj\n")
    _write(src / "empty.ply", "")
    _write(src / "flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = tmp_path / "source"
    report = convert_collection(src, out, "Test", license="CC0-1.0", workers=2, progress=False)
    skipped = {s["id"]: s["reason"] for s in report["skipped"]}
    assert sorted(skipped) == ["empty", "flat", "garbage"], report
    assert all(reason for reason in skipped.values())
    assert "flat" in skipped["flat"] or "degenerate" in skipped["flat"]
    assert report["converted"] == 2 and report["total"] == 5
    on_disk = json.loads((out / "conversion_report.json").read_text())
    assert on_disk["skipped"] == report["skipped"]
    for broken in skipped:  # never half-written
        assert not list(out.glob(f"{broken}*"))
    assert not list(out.rglob("*.tmp")) and not list(out.rglob(".stage_*"))

    source = AssetSource(out)
    assert source.all_asset_ids == ["nested/brick", "unit_cube"]
    cube = source.db["unit_cube"]
    assert cube["kwargs"]["mass"] == pytest.approx(1.0, abs=1e-6)
    assert cube["metadata"]["volume"] == pytest.approx(1.0, abs=1e-6)
    assert cube["metadata"]["surface_area"] == pytest.approx(6.0, abs=1e-6)
    assert cube["metadata"]["category"] == "box"
    assert cube["metadata"]["description"] == "a 1 m cube"
    np.testing.assert_allclose(cube["metadata"]["inertia"], np.eye(3) / 6.0, atol=1e-9)
    np.testing.assert_allclose(cube["kwargs"]["bounds"], [[-0.5] * 3, [0.5] * 3], atol=1e-9)
    assert source.db["nested/brick"]["kwargs"]["mass"] == pytest.approx(6.0, abs=1e-6)
    obj = source.create("unit_cube")
    assert_rests_on_floor(drop_test(obj.simulation_filename, obj.bounds, obj.mass), 1.0)

    # re-running converts only what is missing (the broken ones are retried and skipped again)
    before = (out / "unit_cube.tar.gz").stat().st_mtime_ns
    again = convert_collection(src, out, "Test", license="CC0-1.0", workers=1, progress=False)
    assert again["reused"] == 2 and again["converted"] == 0 and len(again["skipped"]) == 3
    assert (out / "unit_cube.tar.gz").stat().st_mtime_ns == before
    (out / "unit_cube.tar.gz").unlink()
    third = convert_collection(src, out, "Test", license="CC0-1.0", workers=1, progress=False)
    assert third["reused"] == 1 and third["converted"] == 1


def test_discover_jobs_ids_and_errors(tmp_path):
    _write(tmp_path / "a" / "a.obj", "")
    _write(tmp_path / "b" / "mesh.glb", "")
    _write(tmp_path / "b" / "notes.txt", "")
    jobs = discover_jobs(tmp_path, license="x")
    assert [j.asset_id for j in jobs] == ["a", "b/mesh"]
    with pytest.raises(FileNotFoundError, match="does not exist"):
        discover_jobs(tmp_path / "missing", license="x")


def test_decomposition_method_choice(tmp_path):
    import importlib.util

    import trimesh

    from kubric.asset_tools import physics

    src = tmp_path / "m"
    src.mkdir()
    a = trimesh.creation.box(extents=(2, 1, 1))
    b = trimesh.creation.box(extents=(1, 1, 1))
    b.apply_translation((0.5, 1.0, 0.0))
    verts = np.concatenate([a.vertices, b.vertices])
    with pytest.raises(ValueError, match="must be one of"):
        physics.decompose(a, "bogus")
    # a convex mesh is its own decomposition under "auto"; "vhacd" forces V-HACD
    hulls, method = physics.decompose(trimesh.Trimesh(verts).convex_hull, "auto")
    assert method == "convex parts of the source mesh" and len(hulls) == 1
    hulls, method = physics.decompose(a, "vhacd")
    assert method.startswith("V-HACD")
    assert sum(h.volume for h in hulls) == pytest.approx(2.0, rel=0.1)  # voxel-level error
    a.export(src / "block.obj")
    if importlib.util.find_spec("coacd") is None:
        with pytest.raises(ImportError, match="pip install coacd"):
            convert_collection(src, tmp_path / "out", "T", license="x", progress=False,
                               decomposition="coacd")
    else:
        convert_collection(src, tmp_path / "out", "T", license="x", progress=False,
                           decomposition="coacd")
        entry = AssetSource(tmp_path / "out").db["block"]
        assert entry["metadata"]["collision_method"].startswith("CoACD")
