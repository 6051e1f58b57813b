"""Upstream-Kubric compatibility of the asset layer: ``kb.assets.utils.get_clevr_lights``,
``AssetSource._assets`` / ``create(add_metadata=...)`` / ``close()`` / ``with``, and the KuBasic
dome's imported material with its replaceable ``"Image Texture"`` node."""

from __future__ import annotations

import json
import subprocess
import sys
import tarfile

import numpy as np
import pytest

import kubric as kb
from kubric.asset_tools.writer import Collision, package_object
from kubric.assets.asset_source import AssetSource
from kubric.core import rng as rng_policy
from kubric.randomness import WorkerRandomState, bind_worker_rng

BASE = {"sun": (11.6608, -6.62799, 25.8232), "lamp_back": (-1.1685, 2.64602, 5.81574),
        "lamp_key": (6.44671, -2.90517, 4.2584), "lamp_fill": (-4.67112, -4.0136, 3.01122)}


# ------------------------------------------------------------------------ get_clevr_lights
def test_kb_assets_utils_reachable_without_heavy_imports():
    code = ("import sys, kubric as kb; f = kb.assets.utils.get_clevr_lights; "
            "assert not {'bpy', 'pybullet', 'trimesh'} & set(sys.modules), 'heavy import'; "
            "print(f.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "kubric.assets.utils"


def test_clevr_lights_values_and_jitter():
    lights = kb.assets.utils.get_clevr_lights(light_jitter=0.0, rng=np.random.RandomState(0))
    assert [light.name for light in lights] == ["sun", "lamp_back", "lamp_key", "lamp_fill"]
    sun, back, key, fill = lights
    assert isinstance(sun, kb.DirectionalLight)
    assert all(isinstance(light, kb.RectAreaLight) for light in (back, key, fill))
    assert sun.intensity == pytest.approx(0.45) and sun.shadow_softness == pytest.approx(0.2)
    assert (back.intensity, key.intensity, fill.intensity) == (50.0, 100.0, 30.0)
    assert (key.width, key.height, fill.width, fill.height) == (0.5, 0.5, 0.5, 0.5)
    np.testing.assert_allclose(key.color.rgb, np.array([0xff, 0xed, 0xd0]) / 255.0, atol=1e-6)
    np.testing.assert_allclose(fill.color.rgb, np.array([0xc2, 0xd0, 0xff]) / 255.0, atol=1e-6)
    for light in lights:
        np.testing.assert_allclose(light.position, BASE[light.name], atol=1e-5)
        # each looks at the origin: its local −z axis points from its position to (0, 0, 0)
        rot = kb.Quaternion(light.quaternion).rotation_matrix
        want = -np.asarray(light.position, np.float64)
        np.testing.assert_allclose(-rot[:, 2], want / np.linalg.norm(want), atol=1e-5)

    jitter = 2.0
    got = kb.assets.utils.get_clevr_lights(light_jitter=jitter, rng=np.random.RandomState(7))
    draws = np.random.RandomState(7).rand(4, 3) * jitter  # three numbers per light, in order
    for light, d in zip(got, draws, strict=True):
        np.testing.assert_allclose(light.position, np.add(BASE[light.name], d), atol=1e-5)
    again = kb.assets.utils.get_clevr_lights(light_jitter=jitter, rng=np.random.RandomState(7))
    assert [tuple(a.position) for a in again] == [tuple(b.position) for b in got]


def test_clevr_lights_rng_none_rule():
    # without a kb.setup rng: upstream's unseeded default (warns once; not reproducible)
    rng_policy._warned.discard("kb.assets.utils.get_clevr_lights")
    with pytest.warns(UserWarning, match="get_clevr_lights called without rng="):
        kb.assets.utils.get_clevr_lights()
    rng = WorkerRandomState(3)
    bind_worker_rng(rng)  # what kb.setup(flags) does
    lights = kb.assets.utils.get_clevr_lights(light_jitter=1.0)
    want = np.add(BASE["sun"], np.random.RandomState(3).rand(3))
    np.testing.assert_allclose(lights[0].position, want, atol=1e-5)
    with pytest.raises(ValueError, match="light_jitter"):
        kb.assets.utils.get_clevr_lights(light_jitter=-1.0, rng=np.random.RandomState(0))


def test_movi_workers_use_the_shared_light_table():
    from kubric.recipes import movi
    scene = kb.Scene()
    lights = movi.add_clevr_lights(scene, np.random.RandomState(5))
    ref = kb.assets.utils.get_clevr_lights(rng=np.random.RandomState(5))
    assert [(a.name, tuple(a.position)) for a in lights] == [(b.name, tuple(b.position))
                                                             for b in ref]
    assert all(light in scene.assets for light in lights)


# ------------------------------------------------------------------------ AssetSource
@pytest.fixture
def cube_source(tmp_path):
    import trimesh
    box = trimesh.creation.box((1.0, 1.0, 1.0))
    entry = package_object("box", box, tmp_path / "src", collision=Collision("box", (1, 1, 1)),
                           license="CC0", metadata={"category": "crate", "colour": "brown"})
    (tmp_path / "src" / "manifest.json").write_text(json.dumps(
        {"name": "Mini", "version": "1", "assets": {"box": entry}}))
    return tmp_path / "src" / "manifest.json", tmp_path / "scratch"


def test_asset_source_assets_alias_and_add_metadata(cube_source):
    manifest, scratch = cube_source
    src = AssetSource(manifest, scratch_dir=scratch)
    assert src._assets is src.db and list(src._assets) == ["box"]
    assert src._assets["box"]["metadata"]["category"] == "crate"
    full = src.create("box")
    assert full.metadata["category"] == "crate" and full.metadata["license"] == "CC0"
    assert full.metadata["asset_id"] == "box"
    bare = src.create("box", add_metadata=False)
    assert bare.metadata == {}
    assert bare.asset_id == "box" and bare.mass == pytest.approx(full.mass)
    assert src.create("box", add_metadata=False, metadata={"k": 1}).metadata == {"k": 1}
    with pytest.raises(TypeError, match="add_metadata"):
        src.create("box", add_metadata="no")


def test_asset_source_close_and_context_manager(cube_source, tmp_path):
    manifest, scratch = cube_source
    with AssetSource.from_manifest(manifest, scratch_dir=scratch) as src:
        folder = src.fetch("box")
        assert (folder / "object.urdf").is_file()
    assert not folder.exists() and not scratch.exists()
    # folders found already extracted (by another instance) are not deleted by close()
    first = AssetSource(manifest, scratch_dir=scratch)
    folder = first.fetch("box")
    second = AssetSource(manifest, scratch_dir=scratch)
    assert second.fetch("box") == folder
    second.close()
    assert (folder / "object.urdf").is_file()
    first.close()
    first.close()  # idempotent
    assert not folder.exists()
    assert (first.fetch("box") / "object.urdf").is_file()  # usable again: extracts afresh
    first.close()


def test_close_keeps_folders_another_instance_still_uses(cube_source):
    manifest, scratch = cube_source
    first = AssetSource(manifest, scratch_dir=scratch)
    folder = first.fetch("box")  # first extracts
    second = AssetSource(manifest, scratch_dir=scratch)
    assert second.fetch("box") == folder  # second reuses it and may still be rendering with it
    first.close()
    assert (folder / "object.urdf").is_file()
    second.close()
    assert (folder / "object.urdf").is_file()  # the last closer did not extract it: kept
    third = AssetSource(manifest, scratch_dir=scratch)
    third.cleanup()  # the forced variant removes everything
    assert not scratch.exists()


def test_close_keeps_folders_another_process_still_uses(cube_source):
    import subprocess
    import sys
    import textwrap

    manifest, scratch = cube_source
    first = AssetSource(manifest, scratch_dir=scratch)
    folder = first.fetch("box")
    code = textwrap.dedent(f"""
        import sys
        from kubric.assets import AssetSource
        src = AssetSource({str(manifest)!r}, scratch_dir={str(scratch)!r})
        print(src.fetch("box"), flush=True)
        sys.stdin.readline()  # hold the source open until the parent says so
        print((src.fetch("box") / "object.urdf").is_file(), flush=True)
        src.close()
    """)
    child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == str(folder)
        first.close()  # another process holds the source: nothing may be deleted
        assert (folder / "object.urdf").is_file()
        out, _ = child.communicate("go\n", timeout=60)
    finally:
        child.kill()
    assert out.strip() == "True" and child.returncode == 0
    # nobody holds it now and the child extracted nothing: the folder stays in the cache
    assert (folder / "object.urdf").is_file()


# ------------------------------------------------------------------------ the dome
@pytest.fixture(scope="module")
def dome_source(tmp_path_factory):
    from kubric.asset_tools.kubasic import build_kubasic
    root = tmp_path_factory.mktemp("kubasic_dome")
    return AssetSource(build_kubasic(root, workers=1, shapes=["dome"]),
                       scratch_dir=root / "scratch")


def test_dome_archive_ships_textured_material(dome_source):
    from kubric.asset_tools.kubasic import DOME_TEXTURE_GREY, DOME_TEXTURE_SIZE, dome_texture_png
    with tarfile.open(dome_source.archive_path("dome")) as tar:
        names = sorted(tar.getnames())
        mtl = tar.extractfile("visual_geometry.mtl").read().decode()
        obj_head = tar.extractfile("visual_geometry.obj").read(200).decode()
        png_bytes = tar.extractfile("texture.png").read()
    assert {"texture.png", "visual_geometry.mtl", "visual_geometry.obj"} <= set(names)
    assert "map_Kd texture.png" in mtl.splitlines() and "Kd 1 1 1" in mtl.splitlines()
    assert obj_head.startswith("mtllib visual_geometry.mtl\n")
    assert png_bytes == dome_texture_png()
    import png
    w, h, rows, _ = png.Reader(bytes=png_bytes).asRGB8()
    assert (w, h) == (DOME_TEXTURE_SIZE, DOME_TEXTURE_SIZE)
    assert set(np.asarray(list(rows)).ravel()) == {DOME_TEXTURE_GREY}


def _dome_scene(dome_source):
    scene = kb.Scene(resolution=(16, 16))
    scene += kb.PerspectiveCamera(position=(0, 0, 12), look_at=(0, 0, 0))
    scene.ambient_illumination = kb.Color(1.0, 1.0, 1.0)
    dome = dome_source.create("dome", name="dome", static=True, background=True)
    assert isinstance(dome.material, kb.UndefinedMaterial)
    return scene, dome


@pytest.mark.blender
def test_dome_image_texture_node_can_be_replaced_and_renders(dome_source, tmp_path):
    bpy = pytest.importorskip("bpy")
    import png

    from kubric.renderer.blender import Blender

    scene, dome = _dome_scene(dome_source)
    renderer = Blender(scene, samples_per_pixel=2, use_denoising=False)
    scene += dome
    # the lines of upstream's MOVi-C–F workers, unchanged:
    dome_blender = dome.linked_objects[renderer]
    texture_node = dome_blender.data.materials[0].node_tree.nodes["Image Texture"]
    assert texture_node.image is not None
    assert texture_node.image.filepath.endswith("texture.png")
    grey = renderer.render(return_layers=("rgba",))["rgba"][0, ..., :3].astype(float)
    assert grey.mean() > 60  # the lit placeholder texture, not black
    assert np.ptp(grey.mean(axis=(0, 1))) < 3  # grey: r ≈ g ≈ b

    red_path = tmp_path / "red.png"
    with open(red_path, "wb") as fh:
        png.Writer(2, 2, greyscale=False).write(fh, [[230, 20, 20] * 2] * 2)
    texture_node.image = bpy.data.images.load(str(red_path))
    red = renderer.render(return_layers=("rgba",))["rgba"][0, ..., :3].astype(float)
    r, g, b = red.mean(axis=(0, 1))
    assert r > 3 * g and r > 3 * b and r > 60, (r, g, b)


def test_stale_kubasic_cache_is_discarded(tmp_path):
    """A cached KuBasic from another generator version (e.g. 1.0, whose dome had no texture) is
    removed so that ensure_kubasic rebuilds it; the current version is kept."""
    from kubric.asset_tools.kubasic import NAME, VERSION, _discard_if_stale
    assert VERSION != "1.0"
    target = tmp_path / NAME
    target.mkdir()
    (target / "manifest.json").write_text(json.dumps({"name": NAME, "version": VERSION,
                                                      "assets": {}}))
    _discard_if_stale(target)
    assert (target / "manifest.json").is_file()
    (target / "manifest.json").write_text(json.dumps({"name": NAME, "version": "1.0",
                                                      "assets": {}}))
    (target / "dome.tar.gz").write_bytes(b"old")
    _discard_if_stale(target)
    assert not target.exists() and list(tmp_path.iterdir()) == []
