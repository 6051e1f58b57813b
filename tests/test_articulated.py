"""A multi-link URDF from pybullet_data (R2-D2, 15 jointed links): every link is simulated and
rendered, and each link's rendered pixels lie inside the projection of its simulated pose."""

from __future__ import annotations

import os

import numpy as np
import pytest

import kubric as kb
from kubric.assets.articulated import add_articulated, link_visuals
from kubric.core.camera_geometry import project_to_pixels

pybullet_data = pytest.importorskip("pybullet_data")
URDF = os.path.join(pybullet_data.getDataPath(), "r2d2.urdf")
FRAME = 12


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def fallen(tmp_path_factory):
    scene = kb.Scene(frame_end=FRAME, frame_rate=24, resolution=(64, 64))
    simulator = kb.simulator.PyBullet(scene)
    scene += kb.Cube(name="floor", scale=(5, 5, 0.1), position=(0, 0, -0.1), static=True)
    base, links = add_articulated(scene, simulator, URDF, tmp_path_factory.mktemp("links"),
                                  name="r2d2", position=(0, 0, 1.0), mass=10.0)
    simulator.run()
    return scene, base, links


def test_every_link_falls_with_the_base_and_wheels_reach_the_floor(fallen):
    scene, base, links = fallen
    assert len(links) == 15  # 16 links with visuals; the base link is the object itself
    meshes = link_visuals(URDF)
    for name, obj in [("base_link", base), *links.items()]:  # bounds: the link's visuals
        np.testing.assert_allclose(obj.bounds, meshes[name].bounds, atol=1e-9)
    drop = base.get_value_at("position", 0)[2] - base.get_value_at("position", FRAME)[2]
    assert drop > 0.4
    for name, obj in links.items():
        z0, z1 = obj.get_value_at("position", 0)[2], obj.get_value_at("position", FRAME)[2]
        assert z0 - z1 == pytest.approx(drop, abs=0.05), name  # the robot falls as one
    for wheel in ("right_front_wheel", "left_back_wheel"):  # cylinder radius 0.035 m
        assert links[wheel].get_value_at("position", FRAME)[2] == pytest.approx(0.035, abs=0.01)


def _posed_box_pixels(scene, obj, mesh, frame):
    corners = np.array([[x, y, z] for x in mesh.bounds[:, 0] for y in mesh.bounds[:, 1]
                        for z in mesh.bounds[:, 2]])
    rot = kb.Quaternion(obj.get_value_at("quaternion", frame)).rotation_matrix
    world = corners @ rot.T + obj.get_value_at("position", frame)
    xy, _ = project_to_pixels(scene.camera, world, frame=frame)
    return xy.min(axis=0), xy.max(axis=0)


@pytest.mark.blender
def test_each_links_pixels_lie_inside_its_projected_box(fallen):
    scene, base, links = fallen
    renderer = kb.renderer.Blender(scene, samples_per_pixel=1, use_denoising=False)
    scene += kb.PerspectiveCamera(position=(2.2, -2.2, 1.2), look_at=(0, 0, 0.4))
    scene += kb.DirectionalLight(position=(1, -1, 3), look_at=(0, 0, 0), intensity=2)
    seg = renderer.render_still(frame=FRAME, return_layers=["segmentation"])["segmentation"]
    seg = seg[..., 0]
    meshes = link_visuals(URDF)
    seen = 0
    for name, obj in [("base_link", base), *links.items()]:
        rows, cols = np.nonzero(seg == scene.assets.index(obj) + 1)
        if len(rows) == 0:
            continue
        seen += 1
        lo, hi = _posed_box_pixels(scene, obj, meshes[name], FRAME)
        # pixel (row, col) covers [col, col+1) x [row, row+1); allow one pixel of antialiasing
        assert cols.min() >= np.floor(lo[0]) - 1 and cols.max() <= np.ceil(hi[0]) + 1, name
        assert rows.min() >= np.floor(lo[1]) - 1 and rows.max() <= np.ceil(hi[1]) + 1, name
    assert seen >= 10  # most of the 16 links are visible from this side
