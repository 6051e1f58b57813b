"""Upstream scripts' Blender call patterns (issue #24): default node names, appending one object
from a .blend with upstream's keyword arguments, and ``Blender(custom_scene=...)``.

Each test builds real Blender data, renders a few pixels where the claim is about what is seen,
and checks the result against the geometry it set up.
"""

import numpy as np
import pytest

import kubric as kb

pytestmark = pytest.mark.blender


def _blender(scene, **kw):
    from kubric.renderer.blender import Blender
    kw.setdefault("samples_per_pixel", 4)
    kw.setdefault("use_denoising", False)
    return Blender(scene, **kw)


def _write_blend(path, objects):
    """Save a .blend holding mesh cubes ``{name: (half size, location)}`` (nothing else)."""
    import bpy  # noqa: I001  (before bmesh, which bpy provides)
    import bmesh
    bpy.ops.wm.read_factory_settings(use_empty=True)
    for name, (half, location) in objects.items():
        mesh = bpy.data.meshes.new(name)
        bm = bmesh.new()
        bmesh.ops.create_cube(bm, size=2 * half)
        bm.to_mesh(mesh)
        bm.free()
        obj = bpy.data.objects.new(name, mesh)
        obj.location = location
        bpy.context.scene.collection.objects.link(obj)
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_principled_bsdf_node_has_blenders_name_and_a_script_can_rewire_it(tmp_path):
    """texture_structure_nerf / video_based_reconstruction: look up
    active_material.node_tree.nodes["Principled BSDF"], add an Image Texture and link its Color
    to "Base Color". The render then shows the texture's colour."""
    import bpy
    scene = kb.Scene(resolution=(16, 16), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0, 0, 6), look_at=(0, 0, 0))
    scene += kb.DirectionalLight(position=(0, 0, 5), look_at=(0, 0, 0), intensity=3)
    renderer = _blender(scene)
    cube = kb.Cube(name="cube", scale=(3, 3, 0.1),
                   material=kb.PrincipledBSDFMaterial(color=kb.Color(1, 1, 1), roughness=1))
    scene += cube
    material = renderer.blender_scene.objects["cube"].active_material
    tree = material.node_tree
    assert {"Principled BSDF", "Material Output"} <= set(tree.nodes.keys())
    node = tree.nodes["Principled BSDF"]
    assert node.type == "BSDF_PRINCIPLED"
    assert tree.nodes["Material Output"].inputs["Surface"].links[0].from_node == node
    green = tmp_path / "green.png"
    kb.write_png(np.tile(np.array([0, 255, 0], np.uint8), (4, 4, 1)), green)
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = bpy.data.images.load(str(green))
    tree.links.new(node.inputs["Base Color"], texture.outputs["Color"])
    rgba = renderer.render()["rgba"][0].astype(np.float64)
    centre = rgba[4:12, 4:12, :3].mean(axis=(0, 1))
    assert centre[1] > 60 and centre[0] < 0.2 * centre[1] and centre[2] < 0.2 * centre[1], centre
    # flat materials keep Blender's default node names as upstream's did
    flat = kb.FlatMaterial(color=kb.Color(1, 0, 0))
    scene += flat
    names = set(flat.linked_objects[renderer].node_tree.nodes.keys())
    assert {"Emission", "Holdout", "Transparent BSDF", "Light Path", "Mix Shader",
            "Material Output"} <= names


def test_file_based_object_appends_one_object_from_a_blend_with_upstreams_kwargs(tmp_path):
    """multiview_matting / kb.assets.utils.add_hdri_dome: FileBasedObject(render_filename=X.blend,
    render_import_kwargs={"filepath": X/Object/Dome, "directory": X/Object, "filename": "Dome"})
    appends the object "Dome" only."""
    path = _write_blend(tmp_path / "dome.blend", {"Dome": (2.0, (0, 0, 7)), "Other": (0.5, (3, 0, 0))})
    scene = kb.Scene(resolution=(8, 8))
    renderer = _blender(scene)
    dome = kb.FileBasedObject(
        name="BackgroundDome", position=(0, 0, 0.01), static=True, background=True,
        simulation_filename=None, render_filename=str(path),
        render_import_kwargs={"filepath": str(path / "Object" / "Dome"),
                              "directory": str(path / "Object"), "filename": "Dome"})
    scene.add(dome)
    obj = dome.linked_objects[renderer]
    assert obj.name == "BackgroundDome" and obj.type == "MESH"
    verts = np.array([v.co[:] for v in obj.data.vertices])
    # the file's transform is baked in: a cube of half-size 2 centred at z = 7 in the file
    np.testing.assert_allclose(verts.min(axis=0), (-2, -2, 5), atol=1e-5)
    np.testing.assert_allclose(verts.max(axis=0), (2, 2, 9), atol=1e-5)
    np.testing.assert_allclose(obj.location, (0, 0, 0.01), atol=1e-6)
    assert "Other" not in renderer.blender_scene.objects
    assert [o.name for o in renderer.blender_scene.objects if o.type == "MESH"] == \
        ["BackgroundDome"]
    for kwargs, match in [
        ({"directory": str(path / "Object")}, "directory= .* and filename="),
        ({"directory": str(tmp_path / "x.blend" / "Object"), "filename": "Dome"}, "must be"),
        ({"directory": str(path / "Object"), "filename": "Nope"}, "has no object 'Nope'"),
        ({"directory": str(path / "Object"), "filename": "Dome", "link": True}, "got"),
    ]:
        with pytest.raises(ValueError, match=match):
            scene.add(kb.FileBasedObject(render_filename=str(path), render_import_kwargs=kwargs))


def test_custom_scene_renders_the_users_blend_around_the_model(tmp_path):
    """examples/animation.py: Blender(scene, custom_scene=PATH) starts from a user's .blend. A
    wall from the file stands 5 m behind the origin: depth shows it where the model's cube does
    not cover it, segmentation labels it background (0), the model's cube keeps its label."""
    _write_blend(tmp_path / "room.blend", {"Wall": (4.0, (0, 9, 0))})  # front face y = 5
    scene = kb.Scene(resolution=(16, 16), frame_start=1, frame_end=1)
    camera = kb.PerspectiveCamera(position=(0, -5, 0), look_at=(0, 0, 0), focal_length=35)
    scene += camera
    scene += kb.PointLight(position=(0, -3, 2), intensity=300)
    cube = kb.Cube(name="cube", scale=0.5)
    scene += cube
    renderer = _blender(scene, custom_scene=tmp_path / "room.blend")
    assert "Wall" in renderer.blender_scene.objects and "cube" in renderer.blender_scene.objects
    out = renderer.render(return_layers=("rgba", "depth", "segmentation"))
    depth, seg = out["depth"][0, ..., 0], out["segmentation"][0, ..., 0]
    label = scene.assets.index(cube) + 1  # segmentation labels index scene.assets
    assert seg[8, 8] == label and 4.4 < depth[8, 8] < 4.6  # the cube's front face at y = -0.5
    wall = (seg == 0) & (depth < 1000)  # label 0 where a surface is hit: the file's wall
    assert wall[8, 2] and wall[2, 8] and wall.sum() > 100
    # the wall plane y = 5 seen from y = -5: distance 10 along the axis, more off-axis
    assert np.all(depth[wall] > 9.99) and np.all(depth[wall] < 12)
    assert np.all(seg[depth > 1000] == 0)  # beyond the wall's edges: nothing
    with pytest.raises(ValueError, match="custom_scene must be the path of a .blend"):
        _blender(kb.Scene(), custom_scene=tmp_path / "room.txt")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        _blender(kb.Scene(), custom_scene=tmp_path / "missing.blend")
