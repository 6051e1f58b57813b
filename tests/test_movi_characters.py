"""MOVi-C with people (``characters=1``, the procedural person): the person is an instance with
keypoints and boxes; objects are placed around it; at 0 nothing about the scene changes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from collection_fixtures import run_worker

from kubric.pipeline import get_recipe

OPTIONS = ("resolution=64", "frame_end=8", "samples=2", "denoise=false", "min_num_objects=2",
           "max_num_objects=3", "collection_limit=8", "characters=1",
           "character_source=procedural", "motion_source=procedural")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("movi_characters")
    run_worker("movi_c", 1, root, OPTIONS)
    return root / "scene_00000001"


@pytest.mark.blender
def test_the_person_is_an_instance_with_keypoints(scene):
    from kubric.docgen import undocumented_scene_fields
    assert undocumented_scene_fields(scene) == []
    meta = json.loads((scene / "metadata.json").read_text())
    people = [i for i in meta["instances"] if i.get("character_id") == "tube_person"]
    assert len(people) == 1 and meta["flags"]["characters"] == 1
    person = people[0]
    assert person["is_dynamic"] and 1.6 < person["scale"] < 1.8
    cam = meta["camera"]
    k = np.asarray(cam["intrinsics_pixels"])
    kp3, kp2 = np.asarray(person["keypoints_3d"]), np.asarray(person["keypoints_2d"])
    for t, m in enumerate(np.asarray(cam["matrices_world"])):
        c = (kp3[t] - m[:3, 3]) @ m[:3, :3]
        p = np.stack([c[:, 0], -c[:, 1], -c[:, 2]], -1) @ k.T
        np.testing.assert_allclose(p[:, :2] / p[:, 2:], kp2[t], atol=1e-3)
    # the person walks: its keypoints move between frames
    assert np.abs(kp3[-1] - kp3[0]).max() > 0.05
    # the object dropped above the person hits it (collisions with the person's instance)
    k = meta["instances"].index(person)
    dropped = [i for i, inst in enumerate(meta["instances"]) if inst.get("dropped_on")]
    assert len(dropped) == 1
    events = json.loads((scene / "events.json").read_text())["collisions"]
    assert any(sorted(e["instances"]) == sorted([k, dropped[0]]) for e in events), events


def test_zero_characters_leaves_flags_unchanged():
    movi_c = get_recipe("movi_c")
    flags = movi_c(collection_limit=8).flags(0)
    assert not {"characters", "character_source", "motion_source"} & set(flags)
    flags = movi_c(characters=2, character_source="procedural").flags(0)
    assert flags["characters"] == 2 and flags["character_source"] == "procedural"


def test_characters_render_on_both_backends():
    for renderer in ("blender", "raycast"):  # raycast: the skinned mesh, Lambert RGB
        get_recipe("movi_c")(characters=1, renderer=renderer).check()
        get_recipe("pose_estimation")(renderer=renderer).check()


@pytest.mark.blender
def test_coco_export_adds_the_person_category(scene, tmp_path):
    import subprocess
    import sys
    out = tmp_path / "movi_people.json"
    proc = subprocess.run([sys.executable, "-m", "kubric", "export", "coco", str(scene),
                           "--out", str(out), "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    data = json.loads(out.read_text())
    cats = data["categories"]
    assert cats[-1]["name"] == "person" and len(cats[-1]["keypoints"]) == 17
    assert len(cats) > 1 and data["info"]["categories_from"] == "asset category + person"
    meta = json.loads((scene / "metadata.json").read_text())
    for ann in data["annotations"]:
        is_person = "keypoints_2d" in meta["instances"][ann["instance"]]
        assert (ann["category_id"] == cats[-1]["id"]) == is_person
        assert ("keypoints" in ann) == is_person
