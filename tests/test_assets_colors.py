"""The converter keeps the source's appearance: texture, MTL Kd colours, URDF visual colour."""

from __future__ import annotations

import json
import tarfile

import numpy as np
import pytest

from kubric.asset_tools import pybullet_collection as pbc
from kubric.asset_tools.converter import (
    CONVERTER_VERSION,
    ConvertJob,
    as_rgba,
    convert_collection,
    convert_jobs,
)
from kubric.assets import AssetSource

URDF_IDS = ["random_urdfs/000", "random_urdfs/003"]


@pytest.fixture(autouse=True)
def _isolated_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KUBRIC_CACHE_DIR", str(tmp_path / "cache"))


def _glb_json(archive) -> tuple[dict, bytes]:
    """(glTF JSON, binary chunk) of the visual GLB inside an asset archive."""
    with tarfile.open(archive, "r:gz") as tar:
        glb = tar.extractfile("visual_geometry.glb").read()
    n = int.from_bytes(glb[12:16], "little")
    return json.loads(glb[20:20 + n]), glb[20 + n + 8:]


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _box_obj_lines(center, offset):
    import trimesh

    box = trimesh.creation.box(extents=(1, 1, 1))
    box.apply_translation(center)
    lines = ["v {} {} {}".format(*v) for v in box.vertices]
    return lines, ["f {} {} {}".format(*(f + 1 + offset)) for f in box.faces]


@pytest.fixture(scope="module")
def urdf_source(tmp_path_factory):
    out = tmp_path_factory.mktemp("pb_colors")
    report = pbc.build_pybullet_collection(out, workers=1, progress=False, only=URDF_IDS)
    assert report["skipped"] == []
    return out


@pytest.fixture(scope="module")
def mtl_source(tmp_path_factory):
    """Hand-written OBJ/MTL sources: two Kd materials, one Kd material (+ a json colour that
    must lose to it), a textured material whose map refers to ``../``, a textured next to an
    untextured material, a PLY with vertex colours and a bare mesh."""
    import trimesh
    from PIL import Image

    src = tmp_path_factory.mktemp("mtl_meshes")
    (src / "two.mtl").write_text("newmtl red\nKd 0.9 0.1 0.1\nNs 50\n"
                                 "newmtl green\nKd 0.1 0.8 0.2\n")
    va, fa = _box_obj_lines((-0.6, 0, 0), 0)
    vb, fb = _box_obj_lines((0.6, 0, 0), 8)
    (src / "two.obj").write_text("\n".join(["mtllib two.mtl", *va, *vb, "usemtl red", *fa,
                                            "usemtl green", *fb]) + "\n")
    (src / "one.mtl").write_text("newmtl blue\nKd 0.2 0.3 0.7\n")
    (src / "one.obj").write_text("\n".join(["mtllib one.mtl", *va, "usemtl blue", *fa]) + "\n")
    (src / "one.json").write_text(json.dumps({"color": [1, 1, 0]}))
    (src / "bare.obj").write_text("\n".join(va + fa) + "\n")
    (src / "bare.json").write_text(json.dumps({"color": [0.3, 0.6, 0.1, 1.0]}))
    Image.fromarray(np.full((8, 8, 3), (200, 40, 10), np.uint8)).save(src / "tex.png")
    (src / "sub").mkdir()
    (src / "sub" / "tex.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd ../tex.png\n")
    lines = ["mtllib tex.mtl", *va, "vt 0 0", "vt 1 0", "vt 1 1", "usemtl t"]
    lines += [f"f {f[0] + 1}/1 {f[1] + 1}/2 {f[2] + 1}/3"
              for f in trimesh.creation.box(extents=(1, 1, 1)).faces]
    (src / "sub" / "tex.obj").write_text("\n".join(lines) + "\n")
    # a textured material (Kd 0.5 halves its linear colour) next to an untextured one
    (src / "mix.mtl").write_text("newmtl t\nKd 0.5 0.5 0.5\nmap_Kd tex.png\n"
                                 "newmtl g\nKd 0.1 0.8 0.2\n")
    lines = ["mtllib mix.mtl", *va, *vb, "vt 0 0", "vt 1 0", "vt 1 1", "usemtl t"]
    lines += [f"f {f[0] + 1}/1 {f[1] + 1}/2 {f[2] + 1}/3"
              for f in trimesh.creation.box(extents=(1, 1, 1)).faces]
    lines += ["usemtl g", *fb]
    (src / "mix.obj").write_text("\n".join(lines) + "\n")
    painted = trimesh.creation.box(extents=(1, 1, 1))
    painted.visual.vertex_colors = np.tile((10, 200, 30, 255), (len(painted.vertices), 1))
    painted.export(src / "painted.ply")
    out = tmp_path_factory.mktemp("mtl_source")
    report = convert_collection(src, out, "Colours", license="CC0-1.0", workers=1,
                                progress=False)
    assert report["skipped"] == [] and report["converted"] == 6
    return out


def test_urdf_color_is_the_glb_base_color(urdf_source):
    import pybullet_data

    data = json.loads((urdf_source / "manifest.json").read_text())
    assert data["version"] == pbc.VERSION
    for asset_id in URDF_IDS:
        urdf = f"{pybullet_data.getDataPath()}/{asset_id}/{asset_id.split('/')[1]}.urdf"
        rgba = pbc.urdf_visual_color(urdf)
        meta = data["assets"][asset_id]["metadata"]
        assert meta["appearance"] == "urdf_color"
        assert meta["converter_version"] == CONVERTER_VERSION
        np.testing.assert_allclose(meta["base_color"], rgba, atol=1e-9)
        gltf, _ = _glb_json(urdf_source / f"{asset_id}.tar.gz")
        (mat,) = gltf["materials"]
        pbr = mat["pbrMetallicRoughness"]
        np.testing.assert_allclose(pbr["baseColorFactor"], rgba, atol=0.5 / 255 + 1e-9)
        assert pbr["metallicFactor"] == 0.0 and "baseColorTexture" not in pbr
    # the first one is written in the URDF as 0.04 0.07 0.91 (a blue blob)
    np.testing.assert_allclose(pbc.urdf_visual_color(
        f"{pybullet_data.getDataPath()}/random_urdfs/000/000.urdf"), (0.04, 0.07, 0.91, 1.0))


def test_urdf_color_parsing_named_material_and_errors(tmp_path):
    urdf = tmp_path / "r.urdf"
    urdf.write_text('<robot name="r"><material name="m"><color rgba="0.1 0.2 0.3 0.5"/>'
                    '</material><link name="l"><visual><geometry><mesh filename="x.obj"/>'
                    '</geometry><material name="m"/></visual></link></robot>')
    assert pbc.urdf_visual_color(urdf) == pytest.approx((0.1, 0.2, 0.3, 0.5))
    urdf.write_text('<robot name="r"><link name="l"><visual/></link></robot>')
    assert pbc.urdf_visual_color(urdf) is None
    urdf.write_text('<robot name="r"><link name="l"><visual><material name="m">'
                    '<color rgba="1 2 0 1"/></material></visual></link></robot>')
    with pytest.raises(ValueError, match=r"color rgba.*\[0, 1\].*'?1\.0, 2\.0"):
        pbc.urdf_visual_color(urdf)
    urdf.write_text("<robot")
    with pytest.raises(ValueError, match="not valid XML"):
        pbc.urdf_visual_color(urdf)
    assert as_rgba((0.5, 0.25, 1), "c") == (0.5, 0.25, 1.0, 1.0)
    with pytest.raises(ValueError, match="3 or 4 numbers"):
        as_rgba("red", "c")


def test_mtl_kd_colours_per_material(mtl_source):
    db = AssetSource(mtl_source).db
    one = db["one"]["metadata"]
    assert one["appearance"] == "mtl"  # the json colour is only a fallback
    np.testing.assert_allclose(one["base_color"], (0.2, 0.3, 0.7, 1.0), atol=0.5 / 255)
    gltf, _ = _glb_json(mtl_source / "one.tar.gz")
    pbr = gltf["materials"][0]["pbrMetallicRoughness"]
    np.testing.assert_allclose(pbr["baseColorFactor"], (0.2, 0.3, 0.7, 1.0), atol=0.5 / 255)
    assert pbr["metallicFactor"] == 0.0

    two = db["two"]["metadata"]
    assert two["appearance"] == "mtl" and "base_color" not in two
    np.testing.assert_allclose(sorted(two["palette"]), [(0.1, 0.8, 0.2, 1), (0.9, 0.1, 0.1, 1)],
                               atol=0.5 / 255)
    vertices, linear = _sample_texture(mtl_source / "two.tar.gz")
    # glTF is y up: source x is kept, so the red box is at negative x
    x = vertices[:, 0]
    np.testing.assert_allclose(linear[x < 0], np.tile((0.9, 0.1, 0.1), ((x < 0).sum(), 1)),
                               atol=0.01)
    np.testing.assert_allclose(linear[x > 0], np.tile((0.1, 0.8, 0.2), ((x > 0).sum(), 1)),
                               atol=0.01)

    assert db["painted"]["metadata"]["appearance"] == "vertex_color"
    assert db["bare"]["metadata"]["appearance"] == "json_color"
    np.testing.assert_allclose(db["bare"]["metadata"]["base_color"], (0.3, 0.6, 0.1, 1.0))


def test_texture_is_kept_and_found_through_parent_folder(mtl_source):
    import trimesh

    meta = AssetSource(mtl_source).db["sub/tex"]["metadata"]
    assert meta["appearance"] == "texture" and "base_color" not in meta
    with tarfile.open(mtl_source / "sub/tex.tar.gz", "r:gz") as tar:
        scene = trimesh.load(tar.extractfile("visual_geometry.glb"), file_type="glb")
    mat = next(iter(scene.geometry.values())).visual.material
    image = np.asarray(mat.baseColorTexture.convert("RGB"))
    assert image.shape == (8, 8, 3)
    np.testing.assert_array_equal(image[4, 4], (200, 40, 10))
    gltf, _ = _glb_json(mtl_source / "sub/tex.tar.gz")
    assert gltf["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] == 0.0


def _sample_texture(archive):
    """(vertices, linear RGB of the texel under each vertex's UV) of an archive's visual GLB."""
    import trimesh

    with tarfile.open(archive, "r:gz") as tar:
        scene = trimesh.load(tar.extractfile("visual_geometry.glb"), file_type="glb")
    mesh = next(iter(scene.geometry.values()))
    image = np.asarray(mesh.visual.material.baseColorTexture.convert("RGBA"))
    h, w = image.shape[:2]
    cols = np.clip((mesh.visual.uv[:, 0] * w).astype(int), 0, w - 1)
    rows = np.clip(((1 - mesh.visual.uv[:, 1]) * h).astype(int), 0, h - 1)
    return mesh.vertices, _srgb_to_linear(image[rows, cols, :3])


def test_textured_and_coloured_materials_share_one_atlas(mtl_source):
    meta = AssetSource(mtl_source).db["mix"]["metadata"]
    assert meta["appearance"] == "texture"
    gltf, _ = _glb_json(mtl_source / "mix.tar.gz")
    (mat,) = gltf["materials"]
    assert mat["pbrMetallicRoughness"]["metallicFactor"] == 0.0
    assert "baseColorFactor" not in mat["pbrMetallicRoughness"]  # baked into the atlas
    vertices, linear = _sample_texture(mtl_source / "mix.tar.gz")
    x = vertices[:, 0]
    want = 0.5 * _srgb_to_linear(np.array([200, 40, 10]))
    np.testing.assert_allclose(linear[x < 0], np.tile(want, ((x < 0).sum(), 1)), atol=0.01)
    np.testing.assert_allclose(linear[x > 0], np.tile((0.1, 0.8, 0.2), ((x > 0).sum(), 1)),
                               atol=0.01)


def test_stale_archives_and_manifests_are_rebuilt(tmp_path, monkeypatch):
    import pybullet_data

    from kubric.asset_tools.writer import Collision, package_object

    real_jobs = pbc.pybullet_jobs
    monkeypatch.setattr(pbc, "pybullet_jobs",
                        lambda limit=None, textured=True: real_jobs(limit=1, textured=False))
    cache = tmp_path / "kc"
    target = cache / f"{pbc.NAME}-1"
    # a collection written before appearance was kept: manifest 1.0, entry without the version
    mesh_path = f"{pybullet_data.getDataPath()}/random_urdfs/000/000.obj"
    from kubric.asset_tools.converter import load_mesh

    old = load_mesh(mesh_path, scale=0.015)
    entry = package_object("random_urdfs/000", old, target,
                           collision=Collision("hulls", hulls=[old.convex_hull], method="x"),
                           license="x", metadata={"category": "random_urdfs"},
                           visual_format="glb")
    assert "converter_version" not in entry["metadata"]
    (target / "manifest.json").write_text(json.dumps(
        {"name": pbc.NAME, "version": "1.0", "assets": {"random_urdfs/000": entry}}))
    source = pbc.ensure_pybullet_collection(limit=1, cache=cache, workers=1)
    assert source.version == pbc.VERSION != "1.0"
    meta = source.db["random_urdfs/000"]["metadata"]
    assert meta["appearance"] == "urdf_color" and meta["converter_version"] == CONVERTER_VERSION
    assert not list(target.rglob("*.tmp")) and not list(target.rglob(".stage_*"))
    # complete and current: nothing is converted again
    stamp = (target / "random_urdfs/000.tar.gz").stat().st_mtime_ns
    pbc.ensure_pybullet_collection(limit=1, cache=cache, workers=1)
    assert (target / "random_urdfs/000.tar.gz").stat().st_mtime_ns == stamp
    # convert_jobs itself reuses current archives only
    job = ConvertJob("random_urdfs/000", mesh_path, "x", (0.015,) * 3, color=(1, 0, 0))
    report = convert_jobs([job], target, pbc.NAME, pbc.VERSION, workers=1, progress=False)
    assert report["reused"] == 1 and report["converted"] == 0


@pytest.mark.blender
def test_blender_imports_and_renders_the_colours(urdf_source, mtl_source):
    """The imported Principled BSDF has the URDF colour; a 32x32 render is tinted like it, and
    the two-material box renders red on one side and green on the other."""
    pytest.importorskip("bpy")
    import bpy
    import pybullet_data

    import kubric as kb

    source = AssetSource(urdf_source)
    obj = source.create("random_urdfs/000")
    rgba = pbc.urdf_visual_color(f"{pybullet_data.getDataPath()}/random_urdfs/000/000.urdf")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=obj.render_filename)
    (bsdf,) = [n for m in bpy.data.materials if m.node_tree for n in m.node_tree.nodes
               if n.type == "BSDF_PRINCIPLED"]
    np.testing.assert_allclose(bsdf.inputs["Base Color"].default_value[:], rgba,
                               atol=0.5 / 255 + 1e-6)
    assert bsdf.inputs["Metallic"].default_value == 0.0

    two = AssetSource(mtl_source).create("two")
    results = {}
    for name, asset, dist in (("urdf", obj, 0.25), ("two", two, 4.0)):
        scene = kb.Scene(resolution=(32, 32), frame_start=1, frame_end=1,
                         ambient_illumination=kb.Color(0.6, 0.6, 0.6))
        scene += kb.PerspectiveCamera(position=(0, -dist, 0.0), look_at=(0, 0, 0))
        asset.position = (0, 0, 0)
        scene += asset
        scene += kb.DirectionalLight(position=(0, -3, 3), look_at=(0, 0, 0), intensity=2.0)
        out = kb.renderer.Blender(scene, samples_per_pixel=4, use_denoising=False).render(
            return_layers=("rgba", "segmentation"))
        results[name] = out["rgba"][0, ..., :3].astype(float), out["segmentation"][0, ..., 0]
    image, seg = results["urdf"]
    assert (seg > 0).sum() > 30
    mean = image[seg > 0].mean(0)
    assert np.argmax(mean) == np.argmax(rgba[:3]) == 2  # blue
    assert mean[2] > 2 * max(mean[0], mean[1])
    image, seg = results["two"]
    cols = np.nonzero(seg.any(0))[0]
    left = image[:, :cols.mean().astype(int)][seg[:, :cols.mean().astype(int)] > 0].mean(0)
    right = image[:, cols.mean().astype(int) + 1:][seg[:, cols.mean().astype(int) + 1:] > 0]
    right = right.mean(0)
    assert np.argmax(left) == 0 and left[0] > 2 * left[1]  # red box at -x (image left)
    assert np.argmax(right) == 1 and right[1] > 2 * right[0]  # green box at +x
