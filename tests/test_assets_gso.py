"""Google Scanned Objects: zips as distributed, the Fuel listing served by a local server."""

from __future__ import annotations

import json
import urllib.parse

import numpy as np
import pytest
from collection_fixtures import LocalServer, box_obj, gso_files, write_zip

import kubric as kb
from kubric.asset_tools.gso import (
    LICENSE,
    build_gso,
    download_gso,
    listing_url,
    model_zip_url,
)
from kubric.assets import AssetSource


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


def _listing(names_cats):
    return [{"name": n, "owner": "GoogleResearch", "description": f"{n} from the listing",
             "categories": [c] if c else [], "filesize": 1234,
             "thumbnail_url": f"/1.0/GoogleResearch/models/{n}/tip/files/thumbnails/1.jpg"}
            for n, c in names_cats]


def test_listing_and_zip_urls_follow_fuel():
    url = listing_url("https://fuel.gazebosim.org", 2)
    assert url == ("https://fuel.gazebosim.org/1.0/models?page=2&per_page=100"
                   "&q=collections%3AScanned%20Objects%20by%20Google%20Research")
    assert model_zip_url("https://fuel.gazebosim.org", "Android Figure") == \
        "https://fuel.gazebosim.org/1.0/GoogleResearch/models/Android%20Figure.zip"


@pytest.fixture(scope="module")
def gso_download(tmp_path_factory):
    """Three models (one in two listing pages), downloaded through a local Fuel-like server
    whose first answer for one zip is cut half-way."""
    root = tmp_path_factory.mktemp("gso")
    names = [("Box_A", "Toys"), ("Box_B", "Shoe"), ("Box_C", None)]
    zips = {}
    for name, _ in names:
        path = write_zip(root / f"{name}.zip.src", gso_files(name, category=None))
        zips[name] = path.read_bytes()
    listing = _listing(names)
    routes = {}
    for page, models in ((1, listing[:2]), (2, listing[2:])):
        routes[listing_url("", page)] = json.dumps(models).encode()
    for name, data in zips.items():
        routes[urllib.parse.urlsplit(model_zip_url("http://x", name)).path] = data
    cut = urllib.parse.urlsplit(model_zip_url("http://x", "Box_B")).path
    src = root / "download"
    with LocalServer(routes, cut_once=[cut]) as server:
        report = build_gso(src, root / "out", download=True, base_url=server.url, workers=1,
                           progress=False)
        requests = list(server.requests)
    return root, src, report, requests, zips


def test_download_resumes_and_builds_the_source(gso_download):
    root, src, report, requests, zips = gso_download
    assert report["skipped"] == [] and report["converted"] == 3
    for name, data in zips.items():
        assert (src / f"{name}.zip").read_bytes() == data
    cut_path = urllib.parse.urlsplit(model_zip_url("http://x", "Box_B")).path
    ranges = [r for p, r in requests if p == cut_path]
    assert ranges[0] is None and ranges[1] == f"bytes={len(zips['Box_B']) // 2}-"
    pages = [p for p, _ in requests if p.startswith("/1.0/models")]
    assert len(pages) == 3  # two pages with models, the third answers 404
    catalogue = json.loads((src / "gso_catalogue.json").read_text())
    assert sorted(m["name"] for m in catalogue) == ["Box_A", "Box_B", "Box_C"]

    source = AssetSource(root / "out")
    assert source.all_asset_ids == ["Box_A", "Box_B", "Box_C"]
    assert source.categories == ["Shoe", "Toys"]
    assert source.asset_ids_in("Toys") == ["Box_A"]
    entry = source.db["Box_A"]
    assert entry["license"] == LICENSE and "CC-BY-4.0" in LICENSE
    assert entry["metadata"]["description"] == "Box_A from the listing"
    assert entry["metadata"]["appearance"] == "texture"
    assert "category" not in source.db["Box_C"]["metadata"]
    # mass and inertia of the 0.3 x 0.2 x 0.2 m box at density 1
    assert entry["kwargs"]["mass"] == pytest.approx(0.012, rel=1e-6)
    ixx = 0.012 * (0.2**2 + 0.2**2) / 12
    assert np.diag(entry["metadata"]["inertia"])[0] == pytest.approx(ixx, rel=1e-5)
    np.testing.assert_allclose(entry["kwargs"]["bounds"], [[-0.15, -0.1, -0.1],
                                                           [0.15, 0.1, 0.1]], atol=1e-6)
    # nothing but the source (and the downloaded zips in their own folder) was written
    assert not list((root / "out").glob(".gso_unpacked*"))


def test_second_run_downloads_nothing(gso_download):
    root, src, _, _, _ = gso_download
    with LocalServer({}) as server:  # answers 404 to everything
        catalogue, errors = download_gso(src, server.url, progress=False)
        assert errors == [] and len(catalogue) == 3 and server.requests == []


def test_catalogue_or_own_metadata_give_categories(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    write_zip(src / "Own_Meta.zip", gso_files("Own_Meta", category="Kitchen",
                                              description="described by model.config"))
    unpacked = src / "Unpacked"
    for member, data in gso_files("Unpacked", category="Bag").items():
        (unpacked / member).parent.mkdir(parents=True, exist_ok=True)
        (unpacked / member).write_bytes(data)
    from kubric.asset_tools.cli import main

    assert main(["assets", "gso", str(src), "--out", str(tmp_path / "out"), "--workers", "1"]) == 0
    report = json.loads((tmp_path / "out" / "conversion_report.json").read_text())
    assert report["converted"] == 2, report
    source = AssetSource(tmp_path / "out")
    assert source.db["Own_Meta"]["metadata"]["category"] == "Kitchen"
    assert source.db["Own_Meta"]["metadata"]["description"] == "described by model.config"
    assert source.db["Unpacked"]["metadata"]["categories"] == ["Bag"]


def test_hostile_models_are_reported_and_the_rest_converted(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    write_zip(src / "Good.zip", gso_files("Good"))
    write_zip(src / "Escape.zip", {**gso_files("Escape"), "../../evil.txt": b"x"})
    write_zip(src / "Link.zip", gso_files("Link"), symlinks={"meshes/evil": "/etc/passwd"})
    write_zip(src / "NaN.zip", gso_files("NaN", obj=box_obj(
        vertices_override=lambda v: np.where(np.arange(len(v))[:, None] == 3, np.nan, v))))
    write_zip(src / "NoFaces.zip", gso_files("NoFaces", obj="mtllib model.mtl\nv 0 0 0\n"
                                             "v 1 0 0\nv 0 1 0\n"))
    write_zip(src / "BadTexture.zip", gso_files("BadTexture", texture=b"not an image at all"))
    (src / "Corrupt.zip").write_bytes(b"PK\x03\x04 truncated")
    linked = src / "Linked_Folder"
    for member, data in gso_files("Linked_Folder").items():
        (linked / member).parent.mkdir(parents=True, exist_ok=True)
        (linked / member).write_bytes(data)
    (linked / "meshes" / "secret").symlink_to("/etc/hostname")
    out = tmp_path / "out"
    report = build_gso(src, out, workers=1, progress=False)
    reasons = {s["id"]: s["reason"] for s in report["skipped"]}
    assert report["converted"] == 1 and set(reasons) == {"Escape", "Link", "NaN", "NoFaces",
                                                         "BadTexture", "Corrupt",
                                                         "Linked_Folder"}
    assert "leaves the extraction directory" in reasons["Escape"]
    assert "is a link" in reasons["Link"]
    assert "non-finite vertex coordinates in vertex 4" in reasons["NaN"]
    assert "not a triangle mesh (got PointCloud" in reasons["NoFaces"]
    assert "not a readable image" in reasons["BadTexture"]
    assert "cannot read zip" in reasons["Corrupt"]
    assert "symbolic link" in reasons["Linked_Folder"]
    assert AssetSource(out).all_asset_ids == ["Good"]
    assert not (tmp_path / "evil.txt").exists() and not (out.parent / "evil.txt").exists()
    written = {p.relative_to(out).as_posix() for p in out.rglob("*")}
    assert written == {"manifest.json", "conversion_report.json", "Good.tar.gz"}


def test_wrong_size_answer_is_refused(tmp_path):
    from kubric.assets.download import DownloadError, fetch_file

    with LocalServer({"/f.bin": b"0123456789"}) as server:
        with pytest.raises(DownloadError, match="got 10 bytes, the listing says 12"):
            fetch_file(server.url + "/f.bin", tmp_path / "f.bin", size=12)
        with pytest.raises(DownloadError, match="MD5"):
            fetch_file(server.url + "/f.bin", tmp_path / "f.bin", md5="0" * 32)
    assert list(tmp_path.iterdir()) == []  # neither the file nor a partial one is left


@pytest.mark.blender
def test_gso_texture_appears_in_the_render(gso_download):
    root = gso_download[0]
    source = AssetSource(root / "out")
    scene = kb.Scene(resolution=(32, 32))
    renderer = kb.renderer.Blender(scene, samples_per_pixel=4, use_denoising=False)
    scene.ambient_illumination = kb.Color(1.0, 1.0, 1.0)
    scene += kb.OrthographicCamera(position=(0, -2, 0), look_at=(0, 0, 0),
                                   orthographic_scale=0.4)
    obj = source.create("Box_A")
    scene += obj
    frame = renderer.render_still()
    rgba = frame["rgba"].astype(float)
    seg = frame["segmentation"][..., 0] == scene.assets.index(obj) + 1
    # the front face spans x in [-0.15, 0.15]: the texture's left half (red) on the left
    cols = np.nonzero(seg.any(axis=0))[0]
    left = rgba[:, cols[0] + 1: cols[0] + 6][seg[:, cols[0] + 1: cols[0] + 6]]
    right = rgba[:, cols[-1] - 5: cols[-1]][seg[:, cols[-1] - 5: cols[-1]]]
    assert len(left) > 10 and len(right) > 10
    assert np.all(left[:, 0] > 3 * left[:, 2]), left[:4]
    assert np.all(right[:, 2] > 3 * right[:, 0]), right[:4]
