"""Every export carries the licence of every asset its images show: a MOVi-C scene (raycast, 24 px)
and a toybox scene (3 views) whose objects come from an Objaverse-layout source (each object
under its own licence), whose objects and floor get PBR image sets from a material source with
two licences, over bpy's HDRI background. The expected (kind, asset, licence) triples are derived
here from the scene's own record of what it drew (instance ``asset_id``, each ``material``,
``metadata.background``) and the sources' manifests — never through
:mod:`kubric.datasets.exports.licences` — and read back from the COCO file, BOP's scene folder,
the TAP-Vid pickle, the NeRF transforms, LASR's export.json and the card of the hf and
webdataset exports."""

from __future__ import annotations

import hashlib
import json
import pickle
from pathlib import Path

import numpy as np
import pytest
from collection_fixtures import run_worker
from objaverse_fixtures import objaverse_source
from PIL import Image

from kubric.asset_tools.hdri import BPY_WORLD_LICENSE
from kubric.datasets.exports import exporter

OBJECTS = {"a1": ("000-000", "cc0", "mug", 1.0), "b2": ("000-000", "by", "bowl", 2.0),
           "c3": ("000-000", "by-sa", "mug", 1.5)}
MATERIALS = {"tiles": ((200, 40, 40), "CC0-1.0 (ambientCG, Lennart Demes)", ""),
             "bark": ((40, 160, 60), "CC-BY-4.0 (https://creativecommons.org/licenses/by/4.0/)",
                      "Bark by Jane Roe")}
TINY = ("renderer=raycast", "material_probability=1.0")
# the tests on the scenes are marked slow: the fixture takes about 20 s (once per module)


def write_materials(root: Path) -> Path:
    """A material source folder (materials.json and one base-colour PNG per set)."""
    entries = {}
    for material_id, (rgb, licence, attribution) in MATERIALS.items():
        rel = f"{material_id}/{material_id}_base_color.png"
        (root / material_id).mkdir(parents=True)
        Image.fromarray(np.full((8, 8, 3), rgb, np.uint8)).save(root / rel)
        data = (root / rel).read_bytes()
        entries[material_id] = {
            "maps": {"base_color": rel},
            "files": {rel: {"size": len(data), "md5": hashlib.md5(data).hexdigest()}},
            "license": licence, "attribution": attribution,
            "source_url": f"https://example.org/{material_id}"}
    (root / "materials.json").write_text(json.dumps({"name": "TestMaterials", "materials":
                                                     entries}))
    return root


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("licences")
    objects, manifest = objaverse_source(root, OBJECTS)
    materials = write_materials(root / "materials")
    shared = (*TINY, f"objects_source={objects}", f"material_source={materials}")
    run_worker("movi_c", 3, root / "movi", (*shared, "resolution=24", "frame_end=2",
                                            "min_num_objects=3", "max_num_objects=3",
                                            "tracks=8", "split=train"))
    run_worker("toybox", 4, root / "toybox", (*shared, "resolution=24", "num_views=3",
                                              "split_ratio=1,1,1", "num_categories=2",
                                              "min_num_objects=2", "max_num_objects=3"))
    return root, manifest


def expected(scene: Path, manifest: dict) -> set:
    """(kind, asset, licence) of every asset the scene drew, from its metadata and manifests."""
    meta = json.loads((scene / "metadata.json").read_text())
    out = {("object", i["asset_id"], manifest[i["asset_id"]]["license"])
           for i in meta["instances"]}
    drawn = [i["material"] for i in meta["instances"]] + [meta["metadata"]["floor_material"]]
    out |= {("material", m["material_id"], MATERIALS[m["material_id"]][1]) for m in drawn
            if m["source"] == "images"}
    out.add(("background", meta["metadata"]["background"], BPY_WORLD_LICENSE))
    return out


def triples(records) -> set:
    return {(r["kind"], r["asset"], r["license"]) for r in records}


def only_scene(root: Path) -> Path:
    (scene,) = root.glob("scene_*")
    return scene


@pytest.mark.slow
def test_the_scenes_draw_objects_materials_and_background(scenes):
    root, manifest = scenes
    for recipe in ("movi", "toybox"):
        want = expected(only_scene(root / recipe), manifest)
        kinds = {k for k, _, _ in want}
        assert kinds == {"object", "material", "background"}, (recipe, want)
        assert len({lic for k, _, lic in want if k == "object"}) >= 2 or recipe == "toybox"


@pytest.mark.slow
def test_coco_bop_tapvid_and_lasr_carry_every_licence(scenes, tmp_path):
    root, manifest = scenes
    scene = only_scene(root / "movi")
    want = expected(scene, manifest)
    exporter("coco")(root / "movi", tmp_path / "coco.json", progress=False)
    coco = json.loads((tmp_path / "coco.json").read_text())
    assert triples(coco["attribution"]) == want
    from pycocotools.coco import COCO
    assert COCO(str(tmp_path / "coco.json")).getAnnIds()  # still COCO to its readers
    names = {lic["id"]: lic["name"] for lic in coco["licenses"]}
    assert all(names[r["license_id"]] == r["license"] for r in coco["attribution"])
    exporter("bop")(root / "movi", tmp_path / "bop", progress=False)
    bop = json.loads((tmp_path / "bop" / "train_pbr" / "000003" / "licenses.json").read_text())
    assert triples(bop) == want
    exporter("tapvid")(root / "movi", tmp_path / "t.pkl")
    videos = pickle.loads((tmp_path / "t.pkl").read_bytes())
    assert triples(videos[scene.name]["licenses"]) == want
    exporter("lasr")(scene, tmp_path / "lasr", root=0)
    assert triples(json.loads((tmp_path / "lasr" / "export.json").read_text())["licenses"]) \
        == want
    # a material's attribution and source URL travel with it
    (bark,) = [r for r in coco["attribution"] if r["asset"] == "bark"]  # seed 3 draws it
    assert (bark["attribution"], bark["url"]) == ("Bark by Jane Roe", "https://example.org/bark")


@pytest.mark.slow
def test_nerf_transforms_carry_every_licence(scenes, tmp_path):
    root, manifest = scenes
    scene = only_scene(root / "toybox")
    want = expected(scene, manifest)
    exporter("nerf")(root / "toybox", tmp_path / "nerf")
    for split in ("train", "val", "test"):
        data = json.loads((tmp_path / "nerf" / scene.name / f"transforms_{split}.json")
                          .read_text())
        assert triples(data["licenses"]) == want
        assert data["frames"]  # still the transforms NeRF reads


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["hf", "webdataset"])
def test_hub_exports_card_carries_every_licence(scenes, tmp_path, fmt):
    root, manifest = scenes
    want = expected(only_scene(root / "movi"), manifest)
    exporter(fmt)(root / "movi", tmp_path / fmt, splits="train=1", progress=False)
    numbers = json.loads((tmp_path / fmt / "card" / "stats.json").read_text(),
                         parse_constant=float)
    assert triples(numbers["attribution"]) == want
    readme = (tmp_path / fmt / "README.md").read_text()
    for _, asset, licence in want:
        assert f"- `{asset}`" in readme and licence in readme


@pytest.mark.slow
def test_toybox_takes_objects_source_as_movi_does_and_not_both(scenes, tmp_path):
    from kubric.pipeline import OptionError, get_recipe

    root, _ = scenes
    meta = json.loads((only_scene(root / "toybox") / "metadata.json").read_text())
    assert meta["flags"]["objects"] == str(root / "objaverse")  # given as objects_source
    assert "objects_source" not in meta["flags"]
    (tmp_path / "a").mkdir()
    with pytest.raises(OptionError, match=r"^toybox: give objects or objects_source, not both "
                       r"\(objects='.*a', objects_source='.*objaverse'\)$"):
        get_recipe("toybox").from_assignments([f"objects={tmp_path / 'a'}",
                                               f"objects_source={root / 'objaverse'}"])


def test_people_and_an_hdri_source_are_attributed_from_their_manifests(tmp_path):
    """The kinds real scenes above do not draw: people (a procedural character, a motion clip
    of a source folder) and a background from an ``hdri_source`` folder; a procedural material
    holds no third-party data and is not listed."""
    from kubric.datasets.exports.licences import PROCEDURAL_LICENCE, scene_licences

    for name, asset, licence in (("motions", "walk_01", "CC-BY-4.0 (CMU mocap)"),
                                 ("hdris", "sunset", "CC0-1.0 (Poly Haven)")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "manifest.json").write_text(json.dumps(
            {"assets": {asset: {"id": asset, "license": licence}}}))
    meta = {"flags": {"recipe": "x", "character_source": "procedural",
                      "motion_source": str(tmp_path / "motions"),
                      "hdri_source": str(tmp_path / "hdris")},
            "metadata": {"background": "sunset", "material_licenses": {}},
            "instances": [{"character_id": "child_3", "motion_id": "walk_01",
                           "material": {"type": "ProceduralMaterial", "source": "procedural"}}]}
    assert {(a.kind, a.asset, a.license) for a in scene_licences(meta)} == {
        ("character", "child_3", PROCEDURAL_LICENCE),
        ("motion", "walk_01", "CC-BY-4.0 (CMU mocap)"),
        ("background", "sunset", "CC0-1.0 (Poly Haven)")}
