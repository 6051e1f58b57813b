"""Poly Haven HDRIs through a local server that answers like Poly Haven's API."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from collection_fixtures import LocalServer, write_exr, write_hdr

import kubric as kb
from kubric.asset_tools.converter import srgb_bytes
from kubric.asset_tools.polyhaven import build_polyhaven
from kubric.assets import AssetSource

SKY = {"alpha": (0.2, 0.4, 0.8), "beta": (0.5, 0.5, 0.5), "gamma": (0.9, 0.1, 0.1),
       "delta": (0.1, 0.9, 0.1)}


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


def _api(tmp_path, base_url):
    """Routes of a Poly Haven-like API: alpha is good (its first transfer is cut), beta's listed
    size is wrong, gamma's md5 is wrong, delta has no 2k file; every one also has a 1k exr."""
    routes, assets = {}, {}

    def spec(path, data):
        routes[path] = data
        return {"url": base_url + path, "size": len(data), "md5": hashlib.md5(data).hexdigest()}

    for asset_id, rgb in SKY.items():
        img = np.broadcast_to(np.asarray(rgb), (8, 16, 3))
        hdr = write_hdr(tmp_path / f"{asset_id}.hdr", img).read_bytes()
        exr = write_exr(tmp_path / f"{asset_id}.exr", img).read_bytes()
        files = {"hdri": {"1k": {"exr": spec(f"/dl/{asset_id}_1k.exr", exr)}},
                 "tonemapped": {"url": base_url + "/x.jpg", "size": 1, "md5": "0"}}
        if asset_id != "delta":
            files["hdri"]["2k"] = {"hdr": spec(f"/dl/{asset_id}_2k.hdr", hdr)}
        if asset_id == "beta":
            files["hdri"]["2k"]["hdr"]["size"] += 7
        if asset_id == "gamma":
            files["hdri"]["2k"]["hdr"]["md5"] = "0" * 32
        routes[f"/files/{asset_id}"] = json.dumps(files).encode()
        assets[asset_id] = {"name": asset_id.title() + " Sky", "type": 0,
                            "authors": {"Greg Zaal": "All"}, "categories": ["outdoor", "skies"],
                            "tags": ["test"]}
    routes["/assets?t=hdris"] = json.dumps(assets).encode()
    return routes


@pytest.fixture(scope="module")
def polyhaven(tmp_path_factory):
    root = tmp_path_factory.mktemp("polyhaven")
    server = LocalServer({}, cut_once=["/dl/alpha_2k.hdr"])
    with server:
        server.routes.update(_api(root, server.url))
        report = build_polyhaven(root / "out", resolution="2k", base_url=server.url,
                                 progress=False)
        requests = list(server.requests)
    return root, report, requests


def test_downloads_resume_verify_and_record_licence(polyhaven):
    root, report, requests = polyhaven
    reasons = {s["id"]: s["reason"] for s in report["skipped"]}
    assert report["converted"] == 1 and set(reasons) == {"beta", "gamma", "delta"}
    assert "the listing says" in reasons["beta"]
    assert "MD5" in reasons["gamma"]
    assert "no '2k' HDRI file (available: ['1k'])" in reasons["delta"]
    alpha = [r for p, r in requests if p == "/dl/alpha_2k.hdr"]
    assert alpha[0] is None and alpha[1].startswith("bytes=") and alpha[1] != "bytes=0-"
    source = AssetSource(root / "out")
    assert source.all_asset_ids == ["alpha"]
    entry = source.db["alpha"]
    assert entry["asset_type"] == "Texture" and entry["license"].startswith("CC0-1.0")
    assert entry["metadata"]["authors"] == ["Greg Zaal"] and "Greg Zaal" in entry["license"]
    assert entry["metadata"]["categories"] == ["outdoor", "skies"]
    assert entry["metadata"]["resolution"] == [16, 8]
    # nothing but the source is left in the output folder (downloads are deleted once packed)
    names = sorted(p.name for p in (root / "out").iterdir())
    assert names == ["alpha.tar.gz", "conversion_report.json", "manifest.json"]


def test_rerun_reuses_verified_archives_and_exr_format(polyhaven, tmp_path):
    root, _, _ = polyhaven
    with LocalServer({}) as server:
        server.routes.update(_api(tmp_path, server.url))
        again = build_polyhaven(root / "out", base_url=server.url, progress=False)
        assert again["reused"] == 1 and again["converted"] == 0
        assert not any(p.startswith("/dl/alpha") for p, _ in server.requests)
        from kubric.cli import main

        assert main(["assets", "polyhaven", "--out", str(tmp_path / "exr"), "--resolution",
                     "1k", "--format", "exr", "--limit", "2", "--base-url", server.url]) == 0
    exr = json.loads((tmp_path / "exr" / "conversion_report.json").read_text())
    assert exr["converted"] == 2 and exr["skipped"] == []
    source = AssetSource(tmp_path / "exr")
    assert source.all_asset_ids == ["alpha", "beta"]
    assert source.create("beta").filename.endswith("texture.exr")


def test_bad_arguments_are_one_line_errors(tmp_path):
    with pytest.raises(ValueError, match="resolution must be one of"):
        build_polyhaven(tmp_path, resolution="3k")
    with pytest.raises(ValueError, match="format must be one of"):
        build_polyhaven(tmp_path, fmt="jpg")


@pytest.mark.blender
def test_downloaded_hdri_is_the_rendered_background(polyhaven):
    root = polyhaven[0]
    hdri = AssetSource(root / "out").create("alpha")
    scene = kb.Scene(resolution=(8, 8))
    renderer = kb.renderer.Blender(scene, samples_per_pixel=2, use_denoising=False)
    scene.background = hdri
    scene.ambient_illumination = hdri
    scene += kb.PerspectiveCamera(position=(0, 0, 0), look_at=(0, 1, 0))
    rgb = renderer.render_still(return_layers=["rgba"])["rgba"][..., :3].astype(float)
    expected = srgb_bytes(SKY["alpha"])  # RGBE keeps 8 bits of mantissa: < 0.5 % off
    np.testing.assert_allclose(rgb.reshape(-1, 3).mean(axis=0), expected, atol=4)
