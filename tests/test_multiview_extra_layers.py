"""The opt-in layers on the multi-view recipes (``klevr --set extra_layers=...``), each view
checked against an independent derivation, as tests/test_scene_model_layers.py does for MOVi:

* each amodal mask equals a raycast render of a scene holding that object alone, and contains the
  object's visible pixels;
* the occlusion boundaries equal the definition applied pixel by pixel to an independent render;
* every instance's pixels carry one material id and one part id, distinct per instance;
* the transforms files name every view's extra files, and the scene packs with ``--verify``;
* scene flow is refused (the views show one instant).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from test_scene_model_layers import _boundaries_by_loop, _independent

from kubric.core import camera_geometry as geo
from kubric.io.bitmask import unpack_masks
from kubric.io.layers import read_image_dict
from kubric.io.scene_dir import scene_name
from kubric.pipeline import OptionError, get_recipe
from kubric.recipes import multiview_base

OPTIONS = ["resolution=40x32", "num_views=4", "split_ratio=2,1,1", "renderer=raycast",
           "min_num_objects=6", "max_num_objects=7",
           "extra_layers=amodal,occlusion_boundaries,material_ids,part_ids"]
SEED = 3


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """(scene directory, what the recipe saw + independent renders) of one klevr scene."""
    seen = {}
    original = multiview_base.extra.add_after_relabel

    def spy(scene, layers, names, instances):
        seen.update(instances=list(instances), **_independent(scene, instances))
        return original(scene, layers, names, instances)

    patch = pytest.MonkeyPatch()
    patch.setattr(multiview_base.extra, "add_after_relabel", spy)
    try:
        out = tmp_path_factory.mktemp("klevr") / scene_name(SEED)
        get_recipe("klevr").from_assignments(OPTIONS).generate(SEED, out)
    finally:
        patch.undo()
    return out, seen


def test_each_view_s_amodal_mask_equals_a_render_of_that_object_alone(made):
    out, seen = made
    layers = read_image_dict(out)
    meta = json.loads((out / "metadata.json").read_text())
    n = len(meta["instances"])
    assert n == len(seen["instances"]) >= 2
    masks = unpack_masks(layers["amodal_segmentation"], n)
    seg = layers["segmentation"][..., 0]
    occluded = 0
    for k in range(n):
        assert (seen["alone"][:, k] == masks[:, k]).all(), f"instance {k}"
        assert not ((seg == k + 1) & ~masks[:, k]).any()
        occluded += int((masks[:, k] & (seg != k + 1)).sum())
        np.testing.assert_array_equal(meta["instances"][k]["amodal_area"],
                                      masks[:, k].sum(axis=(1, 2)))
    assert occluded > 0


def test_occlusion_boundaries_and_ids_per_view(made):
    out, seen = made
    layers = read_image_dict(out)
    meta = json.loads((out / "metadata.json").read_text())
    raw = seen["raw"]
    expect = _boundaries_by_loop(raw["segmentation"][..., 0], raw["depth"][..., 0])
    got = layers["occlusion_boundaries"][..., 0]
    assert (got == expect).all(), int((got != expect).sum())
    assert got.any()
    seg = layers["segmentation"][..., 0]
    hit = layers["depth"][..., 0] < geo.BACKGROUND_DEPTH
    assert ((layers["material_ids"][..., 0] > 0) == hit).all()
    parts = set()
    for k, inst in enumerate(meta["instances"]):
        mids = np.unique(layers["material_ids"][..., 0][seg == k + 1])
        pids = np.unique(layers["part_ids"][..., 0][seg == k + 1])
        assert len(mids) == 1 and len(pids) == 1, (k, mids, pids)
        entry = meta["metadata"]["materials"][mids[0] - 1]
        np.testing.assert_allclose(entry["color"], inst["color"][:3], atol=1e-5)
        parts.add(int(pids[0]))
    assert len(parts) == len(meta["instances"])


def test_transforms_name_the_extra_files_and_the_scene_packs(made, tmp_path):
    out, _ = made
    for split in ("train", "val", "test"):
        for frame in json.loads((out / f"transforms_{split}.json").read_text())["frames"]:
            for name in ("amodal_segmentation", "occlusion_boundaries", "material_ids",
                         "part_ids"):
                assert (out / frame[f"{name}_file"]).is_file(), (split, name)
    (out / "_SUCCESS").write_text("")
    proc = subprocess.run([sys.executable, "-m", "kubric", "pack", str(out.parent), "--out",
                           str(tmp_path / "ds"), "--splits", "train=1", "--verify",
                           "--no-progress"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "verified: every example equals its scene directory" in proc.stdout


def test_scene_flow_is_refused_on_a_static_scene():
    with pytest.raises(OptionError, match=r"extra_layers.*scene_flow.*one instant"):
        get_recipe("klevr").from_assignments(["extra_layers=amodal,scene_flow"])
    assert get_recipe("toybox").extra_layers.default == ()
