"""``kubric assets objaverse`` against a local server that answers like the Hugging Face Hub
serving ``allenai/objaverse`` (redirects, X-Linked-Size / X-Linked-Etag, Range)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from objaverse_fixtures import HubServer, objaverse_files

from kubric.asset_tools.objaverse import LAYOUT, build_objaverse, parse_licenses
from kubric.assets import AssetSource
from kubric.errors import UsageError

#: uid → (metadata chunk, licence, LVIS category, scale of the 3 m wide fixture)
OBJECTS = {"a1": ("000-000", "cc0", "mug", 1.0), "b2": ("000-000", "by", "mug", 10.0),
           "c3": ("000-000", "by-nc", "chair", 1.0), "d4": ("000-001", "by-sa", None, 0.5)}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return objaverse_files(tmp_path_factory.mktemp("glbs"), OBJECTS)


def test_licence_names():
    assert parse_licenses("cc0,cc-by") == {"cc0", "by"}
    assert parse_licenses("CC-BY-NC-4.0, by-sa") == {"by-nc", "by-sa"}
    assert parse_licenses(None) is None
    with pytest.raises(UsageError, match=r"unknown licence 'gpl'; allowed: \[.*'cc-by'"):
        parse_licenses("cc0,gpl")


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory, files):
    """Run 1: LVIS mug + chair, licences cc0 + cc-by; b2's GLB is cut half-way once (resumed),
    a1's arrives corrupted once (refused). Run 2 on the same folder."""
    out = tmp_path_factory.mktemp("objaverse") / "out"
    a1, b2 = "glbs/000-000/a1.glb", "glbs/000-000/b2.glb"
    with HubServer(files, cut_once=[b2], corrupt_once=[a1]) as hub:
        first = build_objaverse(out, categories=["mug", "chair"], licenses="cc0,cc-by",
                                base_url=hub.url, workers=1, progress=False)
        requests1 = list(hub.requests)
        cache = out / ".objaverse" / LAYOUT
        a1_after_first = (cache / a1).exists(), sorted(p.name for p in cache.rglob("*.part"))
        second = build_objaverse(out, categories=["mug", "chair"], licenses="cc0,cc-by",
                                 base_url=hub.url, workers=1, progress=False)
        requests2 = hub.requests[len(requests1):]
        fetched = {rel: hub.fetched(rel) for rel in files}
    return out, first, second, requests1, requests2, a1_after_first, fetched


def test_corrupted_download_is_refused_then_fetched_again(two_runs):
    out, first, second, _, requests2, a1_after_first, fetched = two_runs
    assert [s["id"] for s in first["skipped"]] == ["a1"]
    assert "SHA-256" in first["skipped"][0]["reason"]
    assert a1_after_first == (False, [])      # nothing kept where a complete file belongs
    assert first["converted"] == 1            # b2
    assert second["converted"] == 1 and second["reused"] == 1 and second["skipped"] == []
    assert fetched["glbs/000-000/a1.glb"] == 2 and fetched["glbs/000-000/b2.glb"] == 2
    # the second run asked only for a1 (the listing files and b2 are in the layout already)
    assert {p for _, p, _ in requests2 if not p.startswith("/lfs/")} == \
        {"/datasets/allenai/objaverse/resolve/main/glbs/000-000/a1.glb"}


def test_cut_transfer_resumes_with_a_range(two_runs, files):
    _, _, _, requests1, _, _, _ = two_runs
    b2 = files["glbs/000-000/b2.glb"]
    ranges = [r for m, p, r in requests1 if m == "GET" and p == "/lfs/glbs/000-000/b2.glb"]
    assert ranges == [None, f"bytes={len(b2) // 2}-"]
    # licence filtering read only the chunk holding the candidates
    assert not any("metadata/000-001" in p for _, p, _ in requests1)


def test_source_has_licences_categories_and_normalised_size(two_runs, files):
    out, *_ = two_runs
    source = AssetSource(out)
    assert source.all_asset_ids == ["a1", "b2"]   # c3 is by-nc: filtered out
    assert source.categories == ["mug"]
    a1, b2 = source.db["a1"], source.db["b2"]
    assert a1["license"].startswith("CC0-1.0 (https://creativecommons.org/publicdomain/zero/")
    assert b2["license"] == ('CC-BY-4.0 (https://creativecommons.org/licenses/by/4.0/); '
                             '"Thing b2" by AuthorB2, https://sketchfab.com/3d-models/b2')
    meta = b2["metadata"]
    assert meta["author"] == "AuthorB2" and meta["objaverse_license"] == "by"
    assert meta["source_url"] == "https://sketchfab.com/3d-models/b2"
    assert meta["sha256"] == hashlib.sha256(files["glbs/000-000/b2.glb"]).hexdigest()
    assert meta["appearance"] == "gltf_pbr" and len(meta["materials"]) == 4
    for entry, scale in ((a1, 1.0), (b2, 10.0)):  # b2's GLB nests its parts under a z-up root
        extent = np.ptp(np.asarray(entry["kwargs"]["bounds"]), axis=0)
        assert extent.max() == pytest.approx(1.0, abs=1e-6)       # largest side 1 m
        np.testing.assert_allclose(extent, np.array([3.0, 0.5, 0.6]) / 3.0, atol=1e-6)
        assert entry["metadata"]["normalised_scale"] == pytest.approx(1.0 / (3.0 * scale))
    obj = source.create("b2")
    assert obj.metadata["license"] == b2["license"] and obj.metadata["category"] == "mug"


def test_cli_by_uid_and_count(tmp_path, files):
    from kubric.asset_tools.cli import main

    with HubServer(files) as hub:
        assert main(["assets", "objaverse", "--out", str(tmp_path / "a"), "--uids", "d4",
                     "--base-url", hub.url, "--workers", "1"]) == 0
        entry = json.loads((tmp_path / "a" / "manifest.json").read_text())["assets"]["d4"]
        assert entry["license"].startswith("CC-BY-SA-4.0 ") and "category" not in \
            entry["metadata"]
        report = build_objaverse(tmp_path / "b", licenses="by-nc", count=1, base_url=hub.url,
                                 workers=1, progress=False)
        assert report["converted"] == 1
        assert list(json.loads((tmp_path / "b" / "manifest.json").read_text())["assets"]) == \
            ["c3"]


def test_bad_selections_are_one_line(tmp_path, files):
    with HubServer(files) as hub:
        with pytest.raises(UsageError, match=r"unknown LVIS category 'mugs'; close: \['mug'\]"):
            build_objaverse(tmp_path, categories=["mugs"], base_url=hub.url, progress=False)
        with pytest.raises(UsageError, match=r"1 uid\(s\) not in object-paths.json.gz, e.g. 'zz'"):
            build_objaverse(tmp_path, uids=["a1", "zz"], base_url=hub.url, progress=False)
        with pytest.raises(UsageError, match="refusing to convert all of Objaverse"):
            build_objaverse(tmp_path, base_url=hub.url, progress=False)


def test_toybox_takes_the_source_with_lvis_classes(two_runs, tmp_path):
    """ToyBox (raycast, 3 views of 32 px) on the Objaverse source: the LVIS category is the
    semantic class, each instance carries its object's licence, and so does each annotation of
    the COCO export."""
    from collection_fixtures import run_worker

    out, *_ = two_runs
    run_worker("toybox", 1, tmp_path, (f"objects={out}", "num_categories=1", "resolution=32",
                                       "num_views=3", "split_ratio=1,1,1", "renderer=raycast",
                                       "max_num_objects=4"))
    meta = json.loads((tmp_path / "scene_00000001" / "metadata.json").read_text())
    assert meta["metadata"]["semantic_classes"] == ["background", "mug"]
    manifest = json.loads((out / "manifest.json").read_text())["assets"]
    assert meta["instances"]
    for inst in meta["instances"]:
        assert inst["license"] == manifest[inst["asset_id"]]["license"]
        assert inst["category"] == "mug"
    from kubric.datasets.exports.coco import export_coco

    export_coco(tmp_path, tmp_path / "coco.json", progress=False)
    coco = json.loads((tmp_path / "coco.json").read_text())
    names = {lic["id"]: lic["name"] for lic in coco["licenses"]}
    assert coco["annotations"] and len(names) == len(set(names.values()))
    for ann in coco["annotations"]:
        assert names[ann["license"]] == manifest[ann["asset_id"]]["license"]
