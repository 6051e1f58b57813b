"""MOVi-C with a cloth sheet and a soft toy (``cloths=1``, ``soft_objects=1``, the toy a
tetrahedralised KuBasic cone: ``soft_shapes=cone``; raycast backend, tiny): each is an
instance, their tracks stay on them where visible and move with the written flow; at 0 nothing
changes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from collection_fixtures import run_worker

from kubric.pipeline import get_recipe

OPTIONS = ("resolution=48", "frame_end=14", "renderer=raycast", "min_num_objects=2",
           "max_num_objects=2", "collection_limit=8", "cloths=1", "soft_objects=1",
           "soft_shapes=cone",
           "tracks=256",
           "track_stride=2",
           "track_max_fraction=0.5")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    pytest.importorskip("embreex")
    root = tmp_path_factory.mktemp("movi_cloths")
    run_worker("movi_c", 1, root, OPTIONS)
    return root / "scene_00000001"


@pytest.mark.parametrize("kind", ["cloth", "soft"])
def test_each_deformable_is_an_instance_with_tracks_that_stay_on_it(scene, kind):
    from kubric.docgen import undocumented_scene_fields
    from kubric.io.layers import read_image_dict
    assert undocumented_scene_fields(scene) == []
    meta = json.loads((scene / "metadata.json").read_text())
    assert meta["flags"]["cloths"] == meta["flags"]["soft_objects"] == 1
    cloths = [k for k, inst in enumerate(meta["instances"], start=1) if inst.get(kind)]
    assert len(cloths) == 1
    label = cloths[0]
    assert meta["instances"][label - 1]["is_dynamic"]
    if kind == "soft":
        assert meta["instances"][label - 1]["shape"] == "cone"
        assert meta["flags"]["soft_shapes"] == ["cone"]
    # (the cone, about 0.5 m, shows fewer pixels at 48² than the sheet)
    assert max(meta["instances"][label - 1]["visibility"]) > (20 if kind == "cloth" else 10)
    tracks = np.load(scene / "tracks.npz")
    on = np.flatnonzero(tracks["instance_id"] == label)
    assert len(on) >= 5
    layers = read_image_dict(scene, ("segmentation", "forward_flow"))
    seg, flow = layers["segmentation"][..., 0], layers["forward_flow"]
    steps = []
    for i in on:
        for t in np.flatnonzero(~tracks["occluded"][i]):
            x, y = tracks["target_points"][i, t]
            assert seg[t, int(y), int(x)] == label
        t, r, c = (int(v) for v in tracks["query_points"][i])
        if t + 1 < seg.shape[0]:
            step = tracks["target_points"][i, t + 1] - tracks["target_points"][i, t]
            steps.append(np.abs(step[::-1] - flow[t, r, c]).max())
    # the written flow is quantised to 16 bits over the scene's flow range
    rng = json.loads((scene / "data_ranges.json").read_text())["forward_flow"]
    assert np.median(steps) < max(1e-3, 2 * (rng["max"] - rng["min"]) / 65535)


def test_zero_deformables_leave_flags_unchanged():
    movi_c = get_recipe("movi_c")
    assert not {"cloths", "soft_objects"} & set(movi_c(collection_limit=8).flags(0))
    assert movi_c(cloths=2).flags(0)["cloths"] == 2
    assert movi_c(soft_objects=1).flags(0)["soft_objects"] == 1
    assert "soft_shapes" not in movi_c(soft_objects=1).flags(0)  # the boxes: as before
    assert movi_c(soft_objects=1, soft_shapes="box,sphere").flags(0)["soft_shapes"] == (
        "box", "sphere")
