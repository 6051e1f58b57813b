"""KuBasic: generated offline, measured, loads in PyBullet and Blender, deterministic."""

from __future__ import annotations

import filecmp
import json

import numpy as np
import pytest
from asset_checks import (
    assert_rests_on_floor,
    blender_import_bounds,
    blender_silhouette,
    drop_test,
)

from kubric.asset_tools.kubasic import SHAPES, VERSION, build_kubasic, ensure_kubasic
from kubric.assets import AssetSource

EXPECTED = {"cone", "cube", "cylinder", "gear", "sphere", "sponge", "spot", "suzanne", "teapot",
            "torus", "torus_knot", "dome"}


@pytest.fixture(scope="module")
def kubasic():
    """KuBasic from the test session's cache (built on the first run; its build time is measured
    by benchmarks/bench_assets.py). test_kubasic_generation_is_byte_identical checks that fresh
    builds equal it."""
    return ensure_kubasic()


def test_kubasic_builds_all_shapes(kubasic):
    source = kubasic
    assert set(source.all_asset_ids) == EXPECTED == set(SHAPES)


def test_kubasic_physical_properties(kubasic):
    source = kubasic
    manifest = json.loads(source.manifest_path.read_text())
    assert manifest["version"] == VERSION and "unit-sized" in manifest["description"]
    cube = source.db["cube"]
    assert cube["kwargs"]["mass"] == pytest.approx(1.0, rel=1e-9)  # unit cube, density 1
    np.testing.assert_allclose(cube["kwargs"]["bounds"], [[-.5, -.5, -.5], [.5, .5, .5]], atol=1e-9)
    sponge = source.db["sponge"]["metadata"]
    assert sponge["volume"] == pytest.approx((20 / 27) ** 2, rel=1e-9)
    assert sponge["surface_area"] > source.db["cube"]["metadata"]["surface_area"]
    for asset_id, entry in source.db.items():
        meta, kw = entry["metadata"], entry["kwargs"]
        for key in ("nr_faces", "nr_vertices", "volume", "surface_area", "category",
                    "description"):
            assert key in meta, (asset_id, key)
        if asset_id == "dome":
            assert kw["static"] is True and kw["mass"] == 0.0
            continue
        assert kw["mass"] == pytest.approx(meta["volume"]) and kw["mass"] > 0.01
        lo, hi = np.asarray(kw["bounds"])
        assert np.all(lo < 0) and np.all(hi > 0), asset_id  # the centre of mass is inside
        assert (hi - lo).max() == pytest.approx(1.0, abs=0.1), asset_id  # fits a 1 m cube
        inertia = np.asarray(meta["inertia"])
        assert np.all(np.linalg.eigvalsh(inertia) > 0), asset_id


def test_kubasic_meshes_centred_on_centre_of_mass(kubasic):
    import trimesh

    source = kubasic
    for asset_id in ("cone", "gear", "torus_knot", "spot"):  # closed meshes
        path = source.create(asset_id).render_filename
        mesh = trimesh.load(path, force="mesh", process=True)
        np.testing.assert_allclose(mesh.center_mass, 0.0, atol=1e-6, err_msg=asset_id)


def test_kubasic_urdf_drop_comes_to_rest(kubasic):
    source = kubasic
    for asset_id in source.all_asset_ids:
        if asset_id == "dome":
            continue
        obj = source.create(asset_id)
        state = drop_test(obj.simulation_filename, obj.bounds, obj.mass)
        assert_rests_on_floor(state, obj.mass)


def test_dome_catches_a_ball(kubasic):
    import pybullet as pb

    source = kubasic
    dome = source.create("dome")
    assert dome.static
    client = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(0, 0, -10, physicsClientId=client)
        pb.loadURDF(dome.simulation_filename, useFixedBase=True, physicsClientId=client)
        ball_shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.5, physicsClientId=client)
        ball = pb.createMultiBody(1.0, ball_shape, basePosition=(3.0, 2.0, 3.0),
                                  physicsClientId=client)
        for _ in range(3 * 240):
            pb.stepSimulation(physicsClientId=client)
        pos, _ = pb.getBasePositionAndOrientation(ball, physicsClientId=client)
    finally:
        pb.disconnect(client)
    assert pos[2] == pytest.approx(0.5, abs=0.02)  # resting on the dome's floor (z = 0)


def test_kubasic_generation_is_byte_identical(kubasic, tmp_path):
    """Two more builds: their manifests and archives equal each other and the fixture's build
    (spot goes through V-HACD in a subprocess, so that step is deterministic too; it is the cheapest
    V-HACD shape: 1 s of CPU against 11 s for gear)."""
    source = kubasic
    a = build_kubasic(tmp_path / "a", workers=2, shapes=["cube", "spot"])
    b = build_kubasic(tmp_path / "b", workers=1, shapes=["cube", "dome"])
    manifest_a, manifest_b = json.loads(a.read_text()), json.loads(b.read_text())
    full = json.loads(source.manifest_path.read_text())
    for manifest, built in ((manifest_a, a), (manifest_b, b)):
        for name, entry in manifest["assets"].items():
            assert entry == full["assets"][name], name
            assert filecmp.cmp(built.parent / f"{name}.tar.gz",
                               source.data_dir / f"{name}.tar.gz", shallow=False), name
    c = build_kubasic(tmp_path / "c", workers=1, shapes=["cube", "dome"])
    assert c.read_bytes() == b.read_bytes()
    assert manifest_a["name"] == "KuBasic" and sorted(manifest_a["assets"]) == ["cube", "spot"]


def test_ensure_kubasic_reuses_the_cache(kubasic):
    source = kubasic
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in source.data_dir.iterdir()}
    again = ensure_kubasic(cache=source.manifest_path.parent.parent)
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in again.data_dir.iterdir()}
    assert after == before  # the same files, untouched: nothing was rebuilt
    assert again.all_asset_ids == source.all_asset_ids
    assert isinstance(again, AssetSource)


@pytest.mark.blender
def test_kubasic_in_blender_bounds_and_silhouette(kubasic):
    pytest.importorskip("bpy")
    source = kubasic
    for asset_id in source.all_asset_ids:
        obj = source.create(asset_id)
        bounds = np.asarray(obj.bounds, dtype=np.float64)
        got = blender_import_bounds(obj.render_filename, dict(obj.render_import_kwargs))
        np.testing.assert_allclose(got, bounds, atol=1e-4 * np.ptp(bounds), err_msg=asset_id)
        # front view: image x = world x, image up = world z; the view is centred on the origin
        ortho = 2.2 * np.abs(bounds).max()
        mask = blender_silhouette(obj.render_filename, dict(obj.render_import_kwargs), ortho)
        res = mask.shape[0]
        cols, rows = np.flatnonzero(mask.any(axis=0)), np.flatnonzero(mask.any(axis=1))
        width_px = (cols.max() - cols.min() + 1) * ortho / res
        height_px = (rows.max() - rows.min() + 1) * ortho / res
        px = ortho / res
        assert abs(width_px - np.ptp(bounds[:, 0])) < 2.5 * px, (asset_id, width_px)
        assert abs(height_px - np.ptp(bounds[:, 2])) < 2.5 * px, (asset_id, height_px)
