"""svr: asset k of the source in random views on a transparent background, pose and category
in the metadata."""

from __future__ import annotations

import json

import numpy as np
import pytest
from collection_fixtures import run_worker
from PIL import Image

from kubric import file_io

pytestmark = pytest.mark.blender
VIEWS = 4


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("svr")
    out = {}
    for seed in (0, 1):
        run_worker("svr", seed, root, ("resolution=32", f"num_views={VIEWS}",
                                       "split_ratio=1,0,0", "samples=4", "denoise=false"))
        out[seed] = root / f"scene_{seed:08d}"
    return out


def _grow(mask):
    """``mask`` grown by one pixel (3 x 3 neighbourhood)."""
    out = mask.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out |= np.roll(np.roll(mask, dy, axis=0), dx, axis=1)
    return out


def test_asset_k_in_every_view_on_a_transparent_background(scenes):
    from kubric.asset_tools import ensure_kubasic

    ids = [i for i in ensure_kubasic().all_asset_ids if i != "dome"]
    for seed, scene_dir in scenes.items():
        meta = json.loads((scene_dir / "metadata.json").read_text())
        (inst,) = meta["instances"]
        assert inst["asset_id"] == ids[seed] and inst["asset_index"] == seed
        assert "category" in inst and len(inst["quaternions"]) == VIEWS
        q = np.asarray(inst["quaternions"])
        assert np.allclose(q, q[0])  # the object keeps one pose, the cameras move
        cams = np.asarray(meta["camera"]["positions"])
        np.testing.assert_allclose(np.linalg.norm(cams, axis=1), 2.5, atol=1e-6)
        seg = file_io.read_segmentation(scene_dir)[..., 0]
        for view in range(VIEWS):
            alpha = np.asarray(Image.open(scene_dir / f"rgba_{view:05d}.png"))[..., 3]
            assert (seg[view] > 0).sum() > 20  # the object is in every view
            near = _grow(seg[view] > 0)  # the object and its antialiased rim
            assert np.all(alpha[~near] == 0)  # transparent wherever no object is
            assert np.all(alpha[~_grow(seg[view] == 0)] == 255)  # opaque inside the object


def test_every_written_field_is_documented(scenes):
    from kubric.docgen import undocumented_scene_fields

    assert undocumented_scene_fields(scenes[0]) == []
