"""A glTF folder converts with each part's PBR material kept (base colour texture, metallic-
roughness texture, normal map, alpha mask), checked on the archive's GLB bytes and in a tiny
Cycles render. The source GLB is written byte by byte by ``gltf_fixtures`` (nothing downloaded)."""

from __future__ import annotations

import io
import json
import struct
import tarfile

import numpy as np
import pytest
from gltf_fixtures import BLUE, FRONT_Y, GREEN, PARTS, RED, _images, textured_glb

from kubric.asset_tools.converter import convert_collection
from kubric.assets import AssetSource


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    root = tmp_path_factory.mktemp("gltf_pbr")
    (root / "src").mkdir()
    textured_glb(root / "src" / "parts.glb")
    report = convert_collection(root / "src", root / "out", "PBR", "CC0-1.0", workers=1,
                                progress=False)
    return root, report


def _glb(data: bytes):
    """(JSON document, binary chunk) of GLB bytes, read by hand."""
    length, kind = struct.unpack("<II", data[12:20])
    assert data[:4] == b"glTF" and kind == 0x4E4F534A
    doc = json.loads(data[20:20 + length])
    rest = data[20 + length:]
    blen, bkind = struct.unpack("<II", rest[:8])
    assert bkind == 0x004E4942
    return doc, rest[8:8 + blen]


def _image(doc, blob, texture_index) -> np.ndarray:
    from PIL import Image

    view = doc["bufferViews"][doc["images"][doc["textures"][texture_index]["source"]]["bufferView"]]
    data = blob[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]]
    return np.asarray(Image.open(io.BytesIO(data)))


def test_every_material_reaches_the_archive_glb(converted):
    root, report = converted
    assert report["converted"] == 1 and report["skipped"] == []
    with tarfile.open(root / "out" / "parts.tar.gz") as tar:
        doc, blob = _glb(tar.extractfile("visual_geometry.glb").read())
    by_name = {m["name"]: m for m in doc["materials"]}
    assert sorted(by_name) == ["masked", "matte", "mirror", "textured"]
    assert len(doc["meshes"]) == 4  # one primitive per material, not one baked atlas
    from PIL import Image

    source = {k: np.asarray(Image.open(io.BytesIO(v))) for k, v in _images().items()}
    pbr = {k: m["pbrMetallicRoughness"] for k, m in by_name.items()}
    np.testing.assert_array_equal(_image(doc, blob, pbr["textured"]["baseColorTexture"]["index"])
                                  [..., :3], source["colour"][..., :3])
    np.testing.assert_array_equal(_image(doc, blob, by_name["textured"]["normalTexture"]["index"]),
                                  source["normal"])
    assert pbr["textured"]["metallicFactor"] == 0.0
    for name in ("mirror", "matte"):
        got = _image(doc, blob, pbr[name]["metallicRoughnessTexture"]["index"])
        np.testing.assert_array_equal(got[..., :3], source[name][..., :3])
        assert pbr[name].get("metallicFactor", 1.0) == 1.0  # glTF default: the texture rules
        assert pbr[name].get("roughnessFactor", 1.0) == 1.0
    masked = by_name["masked"]
    assert masked["alphaMode"] == "MASK" and masked["alphaCutoff"] == 0.5
    assert masked["doubleSided"] is True
    np.testing.assert_array_equal(_image(doc, blob, pbr["masked"]["baseColorTexture"]["index"]),
                                  source["masked"])
    entry = AssetSource(root / "out").db["parts"]
    meta = entry["metadata"]
    assert meta["appearance"] == "gltf_pbr" and entry["license"] == "CC0-1.0"
    summary = {m["name"]: m for m in meta["materials"]}
    assert summary["masked"]["alpha_mode"] == "MASK" and summary["masked"]["alpha_cutoff"] == 0.5
    assert summary["textured"]["textures"] == ["base_color", "normal"]
    assert summary["mirror"]["textures"] == ["metallic_roughness"]
    # the source's extent (3.0 x 0.5 x 0.6 m) is kept
    np.testing.assert_allclose(np.ptp(np.asarray(entry["kwargs"]["bounds"]), axis=0),
                               [3.0, 0.5, 0.6], atol=1e-6)


@pytest.mark.blender
def test_cycles_shows_texture_metal_roughness_and_alpha_mask(converted, tmp_path):
    """Orthographic view of the front faces, lit by one sun from above the camera, black world:
    the base-colour texture's red and blue halves, the mirror part (metallic 1, roughness 0.05
    from its texture) dark — it reflects the black world —, the matte white part bright, and
    the alpha-masked half of the quad transparent."""
    import kubric as kb
    from kubric.renderer import base

    root, _ = converted
    obj = AssetSource(root / "out").create("parts")
    com = np.array([-1.6, FRONT_Y, 0.0]) - np.asarray(obj.bounds)[0]  # source → archive frame
    scene = kb.Scene(resolution=(32, 16), frame_start=0, frame_end=0)
    scene += obj
    scene += kb.DirectionalLight(position=(0, -3, 3), look_at=(0, 0, 0), intensity=3)
    centre = np.array([-0.1, 0, 0.3]) - com
    scene.camera = kb.OrthographicCamera(position=centre + (0, -5, 0), look_at=centre,
                                         orthographic_scale=3.2)
    rgba = base.create("blender", scene, tmp_path, samples_per_pixel=16,
                       background_transparency=True).render(return_layers=("rgba",))["rgba"][0]
    px = 3.2 / 32  # metres per pixel

    def block(x0, x1):
        """Pixels whose centres lie at least half a pixel inside x0..x1 and z 0.1..0.5 (source
        coordinates)."""
        cols = [c for c in range(32) if x0 + px / 2 < -1.7 + (c + 0.5) * px < x1 - px / 2]
        rows = [r for r in range(16) if 0.1 < 1.1 - (r + 0.5) * px < 0.5]
        return rgba[np.ix_(rows, cols)].reshape(-1, 4).astype(float)

    a0, a1, _, _ = PARTS["A"]
    red, blue = block(a0, (a0 + a1) / 2), block((a0 + a1) / 2, a1)
    assert (red[:, 0] > 2 * red[:, 2]).all() and (blue[:, 2] > 2 * blue[:, 0]).all()
    assert np.argmax(RED) == 0 and np.argmax(BLUE) == 2
    mirror, matte = block(*PARTS["B"][:2]), block(*PARTS["D"][:2])
    assert mirror[:, :3].max() < 30 and matte[:, :3].min() > 150  # metallic/roughness texture
    assert (mirror[:, 3] > 200).all() and (matte[:, 3] > 200).all()  # opaque (edges blend)
    c0, c1, _, _ = PARTS["C"]
    hole, leaf = block(c0, (c0 + c1) / 2), block((c0 + c1) / 2, c1)
    assert (hole[:, 3] < 30).all()                       # alpha 0 below the cutoff: not drawn
    assert (leaf[:, 3] > 200).all() and (leaf[:, 1] > 2 * leaf[:, 0]).all()
    assert np.argmax(GREEN) == 1


def test_a_gltf_with_its_buffer_and_images_in_files_converts_alike(tmp_path, converted):
    """The same model as ``.gltf`` JSON + ``.bin`` buffer + PNG files beside it."""
    root, _ = converted
    doc, blob = _glb(textured_glb(tmp_path / "x.glb").read_bytes())
    src = tmp_path / "src" / "sub"
    src.mkdir(parents=True)
    for i, image in enumerate(doc["images"]):
        view = doc["bufferViews"][image.pop("bufferView")]
        start = view.get("byteOffset", 0)
        (src / f"tex_{i}.png").write_bytes(blob[start:start + view["byteLength"]])
        image.pop("mimeType")
        image["uri"] = f"tex_{i}.png"
    doc["buffers"][0]["uri"] = "parts.bin"
    (src / "parts.bin").write_bytes(blob)
    (src / "parts.gltf").write_text(json.dumps(doc))
    report = convert_collection(tmp_path / "src", tmp_path / "out", "PBR", "CC0-1.0",
                                workers=1, progress=False)
    assert report["converted"] == 1, report
    ours = AssetSource(tmp_path / "out").db["sub/parts"]["metadata"]["materials"]
    assert ours == AssetSource(root / "out").db["parts"]["metadata"]["materials"]
