"""A MOVi-C scene whose objects come from Objaverse-layout GLBs (downloaded from a local Hub-like
server by ``kubric assets objaverse``) and whose objects and floor get random procedural PBR
materials (``material_source=procedural``): rendered by Cycles at 32 px, packed with
``--verify``, exported to COCO and BOP and given a dataset card — every object's licence and
attribution reach metadata.json, the COCO file, BOP's models index and the card."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from objaverse_fixtures import objaverse_source

pytestmark = [pytest.mark.blender, pytest.mark.slow]
ROOT = Path(__file__).resolve().parents[1]
OBJECTS = {"a1": ("000-000", "cc0", "mug", 1.0), "b2": ("000-000", "by", "bowl", 2.0)}


def kubric(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    return proc


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("objaverse_movi")
    objects, manifest = objaverse_source(root, OBJECTS)
    options = ["resolution=32", "frame_end=1", "samples=2", "denoise=false",
               "min_num_objects=3", "max_num_objects=3", f"objects_source={objects}",
               "split=train", "material_source=procedural"]
    kubric("worker", "movi_c", "--seed", 5, "--out", root / "scenes",
           *[a for o in options for a in ("--set", o)])
    return root, manifest


def test_metadata_coco_and_card_carry_each_objects_licence(scene):
    root, manifest = scene
    from kubric.docgen import undocumented_scene_fields

    assert undocumented_scene_fields(root / "scenes" / "scene_00000005") == []
    meta = json.loads((root / "scenes" / "scene_00000005" / "metadata.json").read_text())
    assert len(meta["instances"]) >= 1
    # every object and the floor drew a procedural material (probability 1), recorded
    assert meta["flags"]["material_source"] == "procedural"
    assert meta["metadata"]["floor_material"]["type"] == "ProceduralMaterial"
    for inst in meta["instances"]:
        assert inst["material"]["type"] == "ProceduralMaterial", inst["material"]
        entry = manifest[inst["asset_id"]]
        assert inst["license"] == entry["license"]
        assert inst["author"] == entry["metadata"]["author"]
        assert inst["source_url"] == f"https://sketchfab.com/3d-models/{inst['asset_id']}"
    kubric("pack", root / "scenes", "--out", root / "ds", "--splits", "train=1", "--verify",
           "--no-progress")
    kubric("export", "coco", root / "scenes", "--out", root / "coco.json", "--no-progress")
    coco = json.loads((root / "coco.json").read_text())
    by_id = {lic["id"]: lic for lic in coco["licenses"]}
    assert coco["annotations"]
    for ann in coco["annotations"]:
        entry = manifest[ann["asset_id"]]
        assert by_id[ann["license"]]["name"] == entry["license"]
        assert by_id[ann["license"]]["url"] == entry["metadata"]["license_url"]
    kubric("export", "bop", root / "scenes", "--out", root / "bop", "--no-progress")
    index = json.loads((root / "bop" / "models" / "models_index.json").read_text())
    assert index and all(m["license"] == manifest[m["asset_id"]]["license"]
                         for m in index.values())
    kubric("datasets", "card", root / "ds", "--out", root / "card", "--scenes", root / "scenes",
           "--no-progress")
    readme = (root / "card" / "README.md").read_text()
    for inst in meta["instances"]:
        assert manifest[inst["asset_id"]]["license"] in readme
