"""KuBasic assets through the project's own views: kb.simulator.PyBullet and kb.renderer.Blender."""

from __future__ import annotations

import numpy as np
import pytest

import kubric as kb
from kubric.asset_tools import ensure_kubasic


@pytest.fixture(scope="module")
def kubasic():
    """The KuBasic source in the cache (built on first use, as `make demo` does)."""
    return ensure_kubasic()


@pytest.mark.parametrize("asset_id", ["teapot", "torus"])
def test_kubasic_object_settles_in_pybullet_view(kubasic, asset_id):
    scene = kb.Scene(frame_end=96)
    simulator = kb.simulator.PyBullet(scene)
    scene += kb.Cube(name="floor", scale=(10, 10, 0.1), position=(0, 0, -0.1), static=True)
    obj = kubasic.create(asset_id, position=(0, 0, 1.5), restitution=0.0, friction=0.8)
    scene += obj
    assert obj.mass == pytest.approx(kubasic.db[asset_id]["kwargs"]["mass"])
    simulator.run()
    # at rest, the lowest vertex of the posed mesh touches the floor's top (z = 0)
    import trimesh

    verts = trimesh.load(obj.render_filename, force="mesh", process=False).vertices
    rot = kb.Quaternion(obj.get_value_at("quaternion", 96)).rotation_matrix
    lowest = (verts @ rot.T)[:, 2].min() + obj.get_value_at("position", 96)[2]
    assert lowest == pytest.approx(0.0, abs=0.05)  # V-HACD hulls, Bullet margin: ≤ 2.5 %
    assert np.linalg.norm(obj.get_value_at("velocity", 96)) < 0.05


@pytest.mark.blender
def test_kubasic_object_renders_in_blender_view(kubasic):
    scene = kb.Scene(resolution=(32, 32))
    renderer = kb.renderer.Blender(scene, samples_per_pixel=4, use_denoising=False)
    scene += kb.DirectionalLight(position=(0, -3, 3), look_at=(0, 0, 0), intensity=3)
    scene += kb.OrthographicCamera(position=(0, -10, 0), look_at=(0, 0, 0), orthographic_scale=2)
    obj = kubasic.create("cube", material=kb.PrincipledBSDFMaterial(color="red"))
    scene += obj
    frame = renderer.render_still()
    seg = frame["segmentation"][..., 0]
    # the unit cube (edge 1 m) covers half of the 2 m wide view: 16 × 16 of 32 × 32 pixels
    area = int((seg == scene.assets.index(obj) + 1).sum())
    assert abs(area - 256) <= 2 * 16 + 2 * 16 + 4, area
