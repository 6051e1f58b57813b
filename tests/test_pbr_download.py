"""``kubric assets materials polyhaven|ambientcg`` through local servers that answer like the
services' APIs; a truncated or corrupted file is refused and resumed, never listed; the sets'
licences reach a MOVi-C scene's metadata (``material_source=DIR``)."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile

import numpy as np
import pytest
from collection_fixtures import LocalServer, run_worker
from PIL import Image

from kubric.asset_tools.pbr_download import build_materials
from kubric.assets.material_source import ImageSource, open_material_source
from kubric.errors import InputError


def _jpg(rgb) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.full((8, 8, 3), rgb, np.uint8)).save(buf, "JPEG")
    return buf.getvalue()


def _polyhaven_routes(base, corrupt_rust=True):
    routes, assets = {}, {}
    for asset_id, rgb in (("bricks", (180, 60, 40)), ("rust", (120, 70, 20))):
        files = {}
        for key in ("Diffuse", "Rough", "nor_gl", "Displacement", "arm"):
            data = _jpg(rgb if key == "Diffuse" else (128, 128, 255))
            path = f"/dl/{asset_id}_{key}_1k.jpg"
            routes[path] = data
            md5 = hashlib.md5(data).hexdigest()
            if corrupt_rust and asset_id == "rust" and key == "Rough":
                md5 = "0" * 32
            files[key] = {"1k": {"jpg": {"url": base + path, "size": len(data), "md5": md5}}}
        routes[f"/files/{asset_id}"] = json.dumps(files).encode()
        assets[asset_id] = {"name": asset_id.title(), "authors": {"Rob Tuytel": "All"}}
    routes["/assets?t=textures"] = json.dumps(assets).encode()
    return routes


@pytest.fixture(scope="module")
def polyhaven(tmp_path_factory):
    out = tmp_path_factory.mktemp("ph") / "materials"
    server = LocalServer({}, cut_once=["/dl/bricks_Diffuse_1k.jpg"])
    with server:
        server.routes.update(_polyhaven_routes(server.url))
        first = build_materials("polyhaven", out, base_url=server.url)
        requests_first = list(server.requests)
        assert not list(out.rglob("*rust_roughness*"))  # the corrupt file was not kept
        assert "rust" not in json.loads((out / "materials.json").read_text())["materials"]
        server.routes.update(_polyhaven_routes(server.url, corrupt_rust=False))
        server.requests.clear()
        second = build_materials("polyhaven", out, base_url=server.url)
        requests_second = list(server.requests)
    return out, first, requests_first, second, requests_second


def test_polyhaven_resumes_cut_refuses_corrupt_and_resumes_on_rerun(polyhaven):
    out, first, requests_first, second, requests_second = polyhaven
    assert first["converted"] == 1 and [s["id"] for s in first["skipped"]] == ["rust"]
    assert "MD5" in first["skipped"][0]["reason"]
    cut = [r for p, r in requests_first if p == "/dl/bricks_Diffuse_1k.jpg"]
    assert cut[0] is None and cut[1].startswith("bytes=") and cut[1] != "bytes=0-"
    assert second == {**second, "converted": 1, "reused": 1, "skipped": []}
    assert not any(p.startswith("/dl/bricks") or p == "/files/bricks"
                   for p, _ in requests_second)  # complete sets are not fetched again
    source = open_material_source(out)
    assert isinstance(source, ImageSource) and source.ids == ["bricks", "rust"]
    entry = json.loads((out / "materials.json").read_text())["materials"]["bricks"]
    assert set(entry["maps"]) == {"base_color", "roughness", "normal", "displacement"}
    material = source.create("bricks")
    assert material.license.startswith("CC0-1.0") and "Rob Tuytel" in material.attribution
    pixels = np.asarray(Image.open(material.base_color))
    assert abs(pixels[..., 0].mean() - 180) < 6


def _ambientcg_zip(asset_id, rgb, res="1K"):
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for suffix in ("Color", "Roughness", "NormalGL", "Displacement"):
            zf.writestr(f"{asset_id}_{res}-JPG_{suffix}.jpg",
                        _jpg(rgb if suffix == "Color" else (100, 100, 100)))
        zf.writestr(f"{asset_id}.usdc", b"x")
    return buf.getvalue()


def test_ambientcg_checks_size_and_crc(tmp_path):
    good = _ambientcg_zip("Ground001", (90, 80, 70))
    bad = bytearray(_ambientcg_zip("Metal002", (200, 200, 210)))
    member = bad.find(b"JFIF")
    bad[member + 40] ^= 0xFF  # a flipped byte inside the first member: its CRC fails
    server = LocalServer({"/z/Ground001.zip": good, "/z/Metal002.zip": bytes(bad)},
                         cut_once=["/z/Ground001.zip"])
    with server:
        def asset(asset_id, size):
            link = f"{server.url}/z/{asset_id}.zip"
            return {"assetId": asset_id, "displayName": asset_id, "downloadFolders": {
                "default": {"downloadFiletypeCategories": {"zip": {"downloads": [
                    {"attribute": "1K-JPG", "downloadLink": link, "fileName": "x.zip",
                     "size": size}]}}}}}
        listing = {"foundAssets": [asset("Ground001", len(good)), asset("Metal002", len(bad)),
                                   asset("Wood003", 10)]}
        server.routes["/full_json?type=Material&include=downloadData"] = \
            json.dumps(listing).encode()
        report = build_materials("ambientcg", tmp_path / "acg", base_url=server.url)
    reasons = {s["id"]: s["reason"] for s in report["skipped"]}
    assert report["converted"] == 1 and set(reasons) == {"Metal002", "Wood003"}
    assert "CRC" in reasons["Metal002"] and "HTTP 404" in reasons["Wood003"]
    source = open_material_source(tmp_path / "acg")
    assert source.ids == ["Ground001"]
    assert source.create("Ground001").license.startswith("CC0-1.0 (ambientCG")
    (tmp_path / "acg" / "Ground001" / "Ground001_roughness.jpg").write_bytes(b"short")
    with pytest.raises(InputError, match="Ground001_roughness.jpg.*missing or not"):
        open_material_source(tmp_path / "acg")


def test_movi_c_records_each_objects_material_and_licence(polyhaven, tmp_path):
    out_dir = tmp_path / "scenes"
    run_worker("movi_c", 3, out_dir, (
        "renderer=raycast", "resolution=32", "frame_end=2", "min_num_objects=3",
        "max_num_objects=3", "collection_limit=8", f"material_source={polyhaven[0]}",
        "material_probability=0.7"))
    meta = json.loads(next(out_dir.glob("scene_*/metadata.json")).read_text())
    materials = [inst["material"] for inst in meta["instances"]]
    assert materials and all("source" in m for m in materials)
    drawn = [m for m in materials if m["source"] == "images"] + \
        ([meta["metadata"]["floor_material"]] if meta["metadata"]["floor_material"]["source"]
         == "images" else [])
    assert drawn, "probability 0.7 over 4 draws with this seed gives at least one set"
    for m in drawn:
        assert m["license"].startswith("CC0-1.0")
        assert meta["metadata"]["material_licenses"][m["material_id"]]["license"] == m["license"]
    assert meta["flags"]["material_probability"] == 0.7
