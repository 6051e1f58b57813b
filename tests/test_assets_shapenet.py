"""ShapeNetCore v2: a two-synset tree in the original layout, with the artefacts the paper fixes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from asset_checks import assert_rests_on_floor, blender_import_bounds, drop_test
from collection_fixtures import box_obj, mtl_text, two_colour_png

from kubric.asset_tools.shapenet import LICENSE, build_shapenet, repair_mesh
from kubric.assets import AssetSource

HALF = (0.15, 0.3, 0.1)  # x, y (ShapeNet's up), z


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


def _flip_faces(obj_text: str, which: list[int]) -> str:
    """Reverse the winding of the given (0-based) faces of an OBJ."""
    out, k = [], 0
    for line in obj_text.splitlines():
        if line.startswith("f "):
            if k in which:
                line = "f " + " ".join(reversed(line.split()[1:]))
            k += 1
        out.append(line)
    return "\n".join(out) + "\n"


def _add_faces(obj_text: str, extra: list[str]) -> str:
    return obj_text + "\n".join(extra) + "\n"


def _model(root, synset, model, obj_text, texture=True):
    folder = root / synset / model / "models"
    folder.mkdir(parents=True)
    (folder / "model_normalized.obj").write_text(obj_text)
    (folder / "model_normalized.mtl").write_text(mtl_text("../images/texture0.png"))
    if texture:
        (root / synset / model / "images").mkdir()
        (root / synset / model / "images" / "texture0.png").write_bytes(two_colour_png())


@pytest.fixture(scope="module")
def shapenet(tmp_path_factory):
    root = tmp_path_factory.mktemp("shapenet")
    src = root / "ShapeNetCore.v2"
    src.mkdir()
    (src / "taxonomy.json").write_text(json.dumps([
        {"synsetId": "02691156", "name": "airplane,aeroplane,plane", "children": [],
         "numInstances": 2},
        {"synsetId": "03001627", "name": "chair", "children": [], "numInstances": 1},
        {"synsetId": "04379243", "name": "table", "children": [], "numInstances": 1}]))
    box = box_obj(HALF, mtllib="model_normalized.mtl")
    _model(src, "02691156", "clean", box)
    _model(src, "02691156", "flipped", _flip_faces(box, [0, 1, 7]))
    # a double-sided wall inside the box (both windings) plus an exact duplicate face
    wall = ["v 0 -0.2 -0.05", "v 0 0.2 -0.05", "v 0 0.2 0.05", "v 0 -0.2 0.05"]
    n = 25
    faces = [f"f {n}/1 {n + 1}/2 {n + 2}/3", f"f {n}/1 {n + 2}/3 {n + 3}/4",
             f"f {n + 2}/3 {n + 1}/2 {n}/1", f"f {n + 3}/4 {n + 2}/3 {n}/1", "f 1/1 2/2 3/3"]
    with_wall = box.replace("usemtl", "\n".join(wall) + "\nusemtl", 1)
    _model(src, "03001627", "double", _add_faces(with_wall, faces))
    _model(src, "04379243", "skipped_synset", box)
    out = root / "out"
    report = build_shapenet(src, out, synsets=["02691156", "03001627"], workers=1,
                            progress=False)
    return src, out, report


def test_categories_synsets_and_repairs_in_manifest(shapenet):
    _, out, report = shapenet
    assert report["skipped"] == [] and report["converted"] == 3
    source = AssetSource(out)
    assert source.all_asset_ids == ["02691156/clean", "02691156/flipped", "03001627/double"]
    assert source.categories == ["airplane", "chair"]
    meta = source.db["02691156/flipped"]["metadata"]
    assert meta["synset_id"] == "02691156" and meta["category_names"][1] == "aeroplane"
    assert source.db["03001627/double"]["license"] == LICENSE
    reps = {i: source.db[i]["metadata"]["repairs"] for i in source.all_asset_ids}
    assert reps["02691156/clean"] == {"duplicate_faces_removed": 0, "double_sided_faces": 0,
                                      "flipped_faces": 0}
    assert reps["02691156/flipped"]["flipped_faces"] == 3
    assert reps["03001627/double"] == {"duplicate_faces_removed": 1, "double_sided_faces": 4,
                                       "flipped_faces": 0}
    assert report["repairs"]["flipped_faces"] == 3
    assert report["repairs"]["double_sided_faces"] == 4
    assert report["repairs"]["assets_repaired"] == 2
    # y up turned z up: the 0.6 m tall axis is z now
    bounds = np.asarray(source.db["02691156/clean"]["kwargs"]["bounds"])
    np.testing.assert_allclose(bounds[1] - bounds[0], [0.3, 0.2, 0.6], atol=1e-6)
    assert source.db["02691156/clean"]["metadata"]["appearance"] == "texture"


def test_repaired_faces_point_outwards_and_walls_separate():
    import trimesh

    box = trimesh.creation.box((1, 1, 1))
    faces = box.faces.copy()
    faces[[0, 5]] = faces[[0, 5]][:, ::-1]
    broken = trimesh.Trimesh(box.vertices, faces, process=False)
    fixed, counts = repair_mesh(broken)
    assert counts["flipped_faces"] == 2 and fixed.is_winding_consistent and fixed.volume > 0
    np.testing.assert_allclose(fixed.face_normals, box.face_normals, atol=1e-12)
    inside_out = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)
    fixed, counts = repair_mesh(inside_out)
    assert counts["flipped_faces"] == 12 and fixed.volume > 0
    # a two-sided square: the two sides end up DISPLACEMENT apart along their own normals
    sq = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                         [[0, 1, 2], [0, 2, 3], [2, 1, 0], [3, 2, 0]], process=False)
    fixed, counts = repair_mesh(sq)
    assert counts["double_sided_faces"] == 4
    z = fixed.vertices[fixed.faces][:, :, 2]
    np.testing.assert_allclose(z[:2], 1e-4)
    np.testing.assert_allclose(z[2:], -1e-4)


def test_shapenet_assets_load_in_both_views(shapenet):
    _, out, _ = shapenet
    source = AssetSource(out)
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        state = drop_test(obj.simulation_filename, obj.bounds, obj.mass)
        assert_rests_on_floor(state, obj.mass)


@pytest.mark.blender
def test_shapenet_assets_import_in_blender(shapenet):
    pytest.importorskip("bpy")
    _, out, _ = shapenet
    source = AssetSource(out)
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        got = blender_import_bounds(obj.render_filename, dict(obj.render_import_kwargs))
        np.testing.assert_allclose(got, np.asarray(obj.bounds), atol=1e-4, err_msg=asset_id)


def test_unknown_synset_and_missing_taxonomy_are_clear(shapenet, tmp_path, capsys):
    from kubric.cli import main

    src, _, _ = shapenet
    assert main(["assets", "shapenet", str(src), "--out", str(tmp_path / "cli"), "--synsets",
                 "04379243", "--workers", "1"]) == 0
    assert AssetSource(tmp_path / "cli").categories == ["table"]
    assert "flipped_faces 0" in capsys.readouterr().out
    with pytest.raises(ValueError, match=r"unknown synset ids \['99999999'\]"):
        build_shapenet(src, tmp_path / "o", synsets=["99999999"], progress=False)
    with pytest.raises(FileNotFoundError, match="no taxonomy.json"):
        build_shapenet(tmp_path, tmp_path / "o", progress=False)


def test_missing_or_broken_textures_are_reported(tmp_path):
    src = tmp_path / "sn"
    src.mkdir()
    (src / "taxonomy.json").write_text(json.dumps([{"synsetId": "02691156",
                                                    "name": "airplane", "children": []}]))
    box = box_obj(HALF, mtllib="model_normalized.mtl")
    _model(src, "02691156", "good", box)
    _model(src, "02691156", "missing", box, texture=False)
    _model(src, "02691156", "broken", box)
    (src / "02691156" / "broken" / "images" / "texture0.png").write_bytes(b"GIF89a junk")
    report = build_shapenet(src, tmp_path / "out", workers=1, progress=False)
    reasons = {s["id"]: s["reason"] for s in report["skipped"]}
    assert report["converted"] == 1 and report["total"] == 3
    assert "texture '../images/texture0.png' named by model_normalized.mtl is missing" in \
        reasons["02691156/missing"]
    assert "is not a readable image" in reasons["02691156/broken"]
