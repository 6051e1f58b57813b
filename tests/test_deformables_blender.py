"""Deformable cloth and soft solids in Blender: the shape-keyed mesh equals the model's simulated
vertices, and every exact layer agrees with the raycast backend (the oracle) on the same simulated scene."""

import numpy as np
import pytest

from tests.test_deformables import FRAMES, cloth_scene, soft_scene

pytestmark = pytest.mark.blender

LAYERS = ("segmentation", "depth", "forward_flow", "backward_flow", "object_coordinates", "uv",
          "normal")


@pytest.fixture(scope="module", params=["cloth", "soft"])
def both(request):
    pytest.importorskip("embreex")
    from kubric.renderer.blender import Blender
    from kubric.renderer.raycast import Raycast
    scene, _, cloth = (cloth_scene if request.param == "cloth" else soft_scene)()
    blender = Blender(scene, samples_per_pixel=1, use_denoising=False)
    frames = [1, 3, 5]
    ours = blender.render(frames=frames, return_layers=LAYERS)
    oracle = Raycast(scene).render(frames=frames, return_layers=LAYERS)
    return scene, cloth, blender, frames, ours, oracle


def test_blender_mesh_is_the_simulated_mesh_at_and_between_frames(both):
    from kubric.renderer.blender_characters import evaluated_vertices
    _, cloth, blender, _, _, _ = both
    for f in range(FRAMES):
        got = evaluated_vertices(blender, cloth, f)
        assert np.abs(got - cloth.deformed_vertices(f)).max() < 1e-5, f
    # between frames: the linear blend of the two frames' vertices (the model's interpolation)
    import bpy
    blender.bpy_scene.frame_set(2, subframe=0.5)
    obj = cloth.linked_objects[blender]
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
    assert np.abs(co.reshape(-1, 3) - cloth.deformed_vertices(2.5)).max() < 1e-5


def test_exact_layers_agree_with_the_raycast_oracle(both):
    scene, cloth, _, _, ours, oracle = both
    label = scene.assets.index(cloth) + 1
    seg_b, seg_r = ours["segmentation"][..., 0], oracle["segmentation"][..., 0]
    on = (seg_b == label) & (seg_r == label)
    assert ((seg_b == label) != (seg_r == label)).sum() <= max(3, 0.02 * on.sum())
    assert on.sum() > 200
    assert np.abs(ours["depth"][on] - oracle["depth"][on]).max() < 1e-3
    for name in ("forward_flow", "backward_flow"):
        diff = np.abs(ours[name][on] - oracle[name][on]).max(axis=-1)
        assert np.median(diff) < 1e-3 and np.percentile(diff, 95) < 1e-2, name
        assert np.abs(oracle[name][on]).max() > 0.3  # the cloth moves on screen
    for name in ("object_coordinates", "uv"):
        assert np.median(np.abs(ours[name][on] - oracle[name][on])) < 1e-4, name
    cos = np.sum(ours["normal"][on] * oracle["normal"][on], axis=-1)
    assert np.median(cos) > 0.999
