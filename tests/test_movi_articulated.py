"""MOVi-C with an articulated object (``articulated_objects=1``): every URDF link is an instance
with its own segmentation label, and each link's pixels lie inside the projection of its URDF
mesh box at the link's recorded pose; with the option at 0 nothing about the scene changes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from collection_fixtures import run_worker

from kubric.io.layers import read_segmentation
from kubric.pipeline import OptionError, get_recipe

OPTIONS = ("resolution=64", "frame_end=3", "samples=2", "denoise=false", "min_num_objects=1",
           "max_num_objects=1", "collection_limit=8", "articulated_objects=1",
           "articulated_models=r2d2", "size_range=2,2.5")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    root = tmp_path_factory.mktemp("movi_articulated")
    run_worker("movi_c", 0, root, OPTIONS)
    return root / "scene_00000000"


def _rot(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.blender
def test_each_links_pixels_lie_inside_its_projected_urdf_box(scene):
    from kubric.assets.articulated import link_visuals
    from kubric.recipes.articulated_models import model_path

    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["flags"]["articulated_objects"] == 1
    seg = read_segmentation(scene)[..., 0]
    parts = [(k, inst) for k, inst in enumerate(meta["instances"])
             if "urdf" in inst or "articulated_link" in inst]
    (base,) = [inst for _, inst in parts if "urdf" in inst]
    assert base["urdf"] == "r2d2" and len(base["articulated_links"]) == 15
    assert {inst["articulated_base"] for _, inst in parts if inst is not base} == \
        {base["asset_id"]}
    assert all(inst["is_dynamic"] and 2 <= inst["scale"] <= 2.5 for _, inst in parts)
    meshes = link_visuals(model_path("r2d2"))
    box = np.asarray(base["bboxes_3d"][0])  # corners (x, y, z) in {min, max}^3, z fastest
    scale = np.linalg.norm(box[1] - box[0]) / np.ptp(meshes["base_link"].bounds[:, 2])
    k_pix = np.asarray(meta["camera"]["intrinsics_pixels"])
    checked, labels = 0, set()
    for k, inst in parts:
        mesh = meshes[inst.get("articulated_link", "base_link")]
        corners = np.array([[x, y, z] for x in mesh.bounds[:, 0] for y in mesh.bounds[:, 1]
                            for z in mesh.bounds[:, 2]]) * scale
        for t in range(seg.shape[0]):
            rows, cols = np.nonzero(seg[t] == k + 1)
            if len(rows) == 0:
                continue
            labels.add(k + 1)
            world = corners @ _rot(inst["quaternions"][t]).T + np.asarray(inst["positions"][t])
            m = np.asarray(meta["camera"]["matrices_world"][t])
            cam = (world - m[:3, 3]) @ m[:3, :3]
            x = k_pix[0, 0] * cam[:, 0] / -cam[:, 2] + k_pix[0, 2]
            y = -k_pix[1, 1] * cam[:, 1] / -cam[:, 2] + k_pix[1, 2]
            # pixel (row, col) covers [col, col + 1) x [row, row + 1); one pixel of slack
            assert cols.min() >= np.floor(x.min()) - 1 and cols.max() <= np.ceil(x.max()), (k, t)
            assert rows.min() >= np.floor(y.min()) - 1 and rows.max() <= np.ceil(y.max()), (k, t)
            checked += 1
    assert len(labels) >= 5 and checked >= 12  # several links, each with a label of its own


@pytest.mark.blender
def test_every_written_field_is_documented(scene):
    from kubric.docgen import undocumented_scene_fields

    assert undocumented_scene_fields(scene) == []


def test_the_option_at_zero_leaves_the_flags_as_before():
    movi_c = get_recipe("movi_c")
    flags = movi_c(collection_limit=8).flags(0)
    assert "articulated_objects" not in flags and "articulated_models" not in flags
    flags = movi_c(articulated_objects=2, articulated_models="a1,r2d2").flags(0)
    assert flags["articulated_objects"] == 2 and flags["articulated_models"] == ("a1", "r2d2")
    for recipe in ("movi_d", "movi_e", "movi_f"):
        assert "articulated_objects" in get_recipe(recipe).options
    for recipe in ("movi_a", "movi_b"):  # their schemas label every instance with a shape
        assert "articulated_objects" not in get_recipe(recipe).options
    with pytest.raises(OptionError, match="articulated_models"):
        movi_c(articulated_models="r2d2,humanoid")
