"""The README's recipe: MOVi-C on a GSO source and a Poly Haven source (both built here from
fixtures in their original layouts), restricted to one object category."""

from __future__ import annotations

import json

import pytest
from collection_fixtures import LocalServer, gso_files, run_worker, write_zip
from test_assets_polyhaven import _api

from kubric.asset_tools.gso import build_gso
from kubric.asset_tools.polyhaven import build_polyhaven
from kubric.assets import AssetSource

pytestmark = [pytest.mark.blender, pytest.mark.slow]


def test_movi_c_on_gso_and_polyhaven_with_a_category(tmp_path):
    # the suite's shared asset cache (conftest): KuBasic is built once, not once per test
    zips = tmp_path / "gso_zips"
    zips.mkdir()
    for name, cat in (("Toy_1", "Toys"), ("Toy_2", "Toys"), ("Shoe_1", "Shoe")):
        write_zip(zips / f"{name}.zip", gso_files(name, category=cat))
    assert build_gso(zips, tmp_path / "gso", workers=1, progress=False)["converted"] == 3
    with LocalServer({}) as server:
        server.routes.update(_api(tmp_path, server.url))
        build_polyhaven(tmp_path / "hdri", base_url=server.url, limit=1, progress=False)
    out = tmp_path / "scene"
    run_worker("movi_c", 3, out, ("resolution=48x32", "frame_end=3", "samples=2",
                                  "denoise=false", "min_num_objects=3", "max_num_objects=3",
                                  f"objects_source={tmp_path / 'gso'}",
                                  f"hdri_source={tmp_path / 'hdri'}", "object_categories=Toys"))
    from kubric.docgen import undocumented_scene_fields

    assert undocumented_scene_fields(out / "scene_00000003") == []
    meta = json.loads((out / "scene_00000003" / "metadata.json").read_text())
    used = {inst["asset_id"] for inst in meta["instances"]}
    assert used and used <= {"Toy_1", "Toy_2"}
    assert meta["metadata"]["background"] == "alpha"
    licences = {AssetSource(tmp_path / "gso").db[a]["license"] for a in used}
    assert all("CC-BY-4.0" in lic for lic in licences)
    assert meta["metadata"]["num_instances"] == len(meta["instances"]) == 3
    assert {inst["category"] for inst in meta["instances"]} == {"Toys"}


def test_unknown_category_is_an_option_error(tmp_path):
    from kubric.pipeline import OptionError, get_recipe

    zips = tmp_path / "z"
    zips.mkdir()
    write_zip(zips / "Toy_1.zip", gso_files("Toy_1", category="Toys"))
    build_gso(zips, tmp_path / "gso", workers=1, progress=False)
    recipe = get_recipe("movi_c").from_assignments([f"objects_source={tmp_path / 'gso'}",
                                                    "object_categories=Hats"])
    with pytest.raises(OptionError, match=r"object_categories: .*no categories \['Hats'\]"):
        recipe.open_sources()
