"""HDRI sources: the bpy wheel's world HDRIs (default) and any folder of .hdr/.exr files."""

from __future__ import annotations

import json

import numpy as np
import pytest

import kubric as kb
from kubric.asset_tools import ensure_hdri_source, hdri
from kubric.asset_tools.hdri import bpy_world_hdri_dir, build_hdri_source
from kubric.assets import AssetSource


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


def test_bpy_world_hdris_become_a_texture_source(tmp_path):
    source = ensure_hdri_source()
    assert source.manifest_path.parent == tmp_path / "cache" / f"HDRIs-{hdri.VERSION}"
    expected = sorted(p.stem for p in bpy_world_hdri_dir().glob("*.exr")
                      if p.stem not in hdri.NOT_BACKGROUNDS)
    assert "studio" in hdri.NOT_BACKGROUNDS and (bpy_world_hdri_dir() / "studio.exr").is_file()
    assert len(expected) >= 7 and source.all_asset_ids == expected
    _, held_out = source.get_test_split(fraction=0.25, seed=0)
    assert len(held_out) == 2
    tex = source.create("sunset")
    assert isinstance(tex, kb.Texture) and tex.mapping == "environment"
    assert "CC0" in tex.metadata["license"]
    assert tex.metadata["resolution"] == [1024, 512]
    import OpenEXR
    with OpenEXR.File(tex.filename, separate_channels=True) as f:
        channels = f.channels()
        red = np.asarray(channels["R"].pixels, dtype=np.float32)
    assert red.shape == (512, 1024) and np.isfinite(red).all() and red.max() > 1.0  # HDR
    # built once: a second call reuses the cached source
    assert ensure_hdri_source().manifest_path == source.manifest_path


def test_hdri_folder_needs_a_licence_and_images(tmp_path):
    src = tmp_path / "maps"
    src.mkdir()
    with pytest.raises(ValueError, match="holds no"):
        build_hdri_source(src, tmp_path / "out")
    hdr = src / "Sky Noon.hdr"
    hdr.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 4\n" + bytes(32))
    with pytest.raises(ValueError, match="no licence given"):
        build_hdri_source(src, tmp_path / "out")
    (src / "license.txt").write_text("CC-BY-4.0 someone\nmore text\n")
    manifest = build_hdri_source(src, tmp_path / "out", name="Skies")
    entry = json.loads(manifest.read_text())["assets"]["sky_noon"]
    assert entry["license"] == "CC-BY-4.0 someone"
    assert entry["metadata"]["resolution"] == [4, 2]
    tex = AssetSource(tmp_path / "out").create("sky_noon")
    assert open(tex.filename, "rb").read().startswith(b"#?RADIANCE")


@pytest.mark.blender
def test_hdri_lights_the_world_and_textures_the_dome(tmp_path):
    """An HDRI asset as world light + background, and as the colour of the KuBasic dome."""
    from kubric.asset_tools.kubasic import build_kubasic

    hdri = ensure_hdri_source().create("courtyard")
    kubasic = AssetSource(build_kubasic(tmp_path / "kb", workers=1, shapes=["dome"]))
    scene = kb.Scene(resolution=(16, 16))
    renderer = kb.renderer.Blender(scene, samples_per_pixel=2, use_denoising=False)
    scene.background = hdri
    scene.ambient_illumination = hdri
    scene += kb.PerspectiveCamera(position=(0, -5, 3), look_at=(0, 20, 10))
    sky = renderer.render_still(return_layers=["rgba"])["rgba"][..., :3].astype(float)
    assert sky.mean() > 5 and sky.std() > 1  # the HDRI is visible, not a constant colour
    dome = kubasic.create("dome", material=kb.FlatMaterial(color=hdri), background=True)
    scene += dome
    frame = renderer.render_still(return_layers=["rgba", "segmentation"])
    assert (frame["segmentation"][..., 0] == scene.assets.index(dome) + 1).mean() > 0.9
    rgb = frame["rgba"][..., :3].astype(float)
    assert rgb.mean() > 5 and rgb.std() > 1


def test_cli_builds_and_lists_a_source(tmp_path, capsys):
    from kubric.cli import main

    assert main(["assets", "hdri", "--out", str(tmp_path / "h")]) == 0
    assert main(["assets", "list", str(tmp_path / "h")]) == 0
    printed = capsys.readouterr().out
    assert f"HDRIs {hdri.VERSION}: 8 assets" in printed and "sunset" in printed
    assert main(["assets", "cache"]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "cache")
