"""Blender renderer: options, mapping tables, materials, lights, world, files, save_state."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import kubric as kb

HDRI_DIR = Path(sys.prefix) / "lib/python3.11/site-packages/bpy/5.0/datafiles/studiolights/world"


def _blender(scene, **kw):
    from kubric.renderer.blender import Blender
    kw.setdefault("samples_per_pixel", 1)
    kw.setdefault("use_denoising", False)
    return Blender(scene, **kw)


def _scene(w=32, h=24, frames=1):
    scene = kb.Scene(resolution=(w, h), frame_start=1, frame_end=frames)
    scene += kb.PerspectiveCamera(position=(0, -6, 4), look_at=(0, 0, 0))
    return scene


@pytest.mark.blender
def test_import_renderer_does_not_import_bpy():
    code = ("import sys, kubric, kubric.renderer; assert 'bpy' not in sys.modules; "
            "kubric.renderer.Blender; assert 'bpy' in sys.modules; print('ok')")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0 and "ok" in res.stdout, res.stderr


@pytest.mark.blender
@pytest.mark.parametrize("kwargs,match", [
    ({"samples_per_pixel": 0}, "samples_per_pixel"),
    ({"samples_per_pixel": 2.5}, "samples_per_pixel"),
    ({"use_denoising": "yes"}, "use_denoising"),
    ({"device": "TPU"}, "device"),
    ({"motion_blur": -1}, "motion_blur"),
    ({"max_bounces": -2}, "max_bounces"),
])
def test_options_are_validated(kwargs, match):
    with pytest.raises((ValueError, TypeError), match=match):
        _blender(_scene(), **kwargs)


@pytest.mark.blender
def test_render_argument_errors_and_missing_camera():
    r = _blender(_scene())
    with pytest.raises(ValueError, match="unknown layers"):
        r.render(return_layers=("rgba", "flow"))
    with pytest.raises(TypeError, match="integers"):
        r.render(frames=[1.5])
    with pytest.raises(ValueError, match="frames ≥ 0"):
        r.render(frames=[-1, 0])
    no_cam = kb.Scene(resolution=(8, 8))
    no_cam += kb.Cube()
    with pytest.raises(ValueError, match="no camera"):
        _blender(no_cam).render()


@pytest.mark.blender
def test_settings_reach_blender_through_tables():
    import bpy
    scene = _scene(40, 30, frames=5)
    scene.frame_rate = 12
    cam = scene.camera
    cam.shift_x, cam.focal_length, cam.use_dof, cam.focus_distance = 0.1, 28.0, True, 3.0
    sun = kb.DirectionalLight(shadow_softness=0.3, intensity=2.0)
    spot = kb.SpotLight(spot_size=0.7, spot_blend=0.2, intensity=50)
    area = kb.RectAreaLight(width=2.0, height=0.5, intensity=30)
    point = kb.PointLight(color=(1, 0.5, 0.25), intensity=10)
    scene += [sun, spot, area, point]
    r = _blender(scene, samples_per_pixel=7, motion_blur=True, max_bounces=3)
    s = bpy.context.scene
    assert (s.render.resolution_x, s.render.resolution_y) == (40, 30)
    assert (s.frame_start, s.frame_end, s.render.fps) == (1, 5, 12)
    assert s.view_settings.view_transform == "Standard"
    bc = cam.linked_objects[r].data
    assert bc.sensor_fit == "HORIZONTAL" and bc.lens == pytest.approx(28.0)
    assert bc.shift_x == pytest.approx(0.1) and bc.dof.use_dof
    assert bc.dof.focus_distance == pytest.approx(3.0)
    assert sun.linked_objects[r].data.angle == pytest.approx(0.3)
    assert spot.linked_objects[r].data.spot_size == pytest.approx(0.7)
    a = area.linked_objects[r].data
    assert (a.shape, a.size, a.size_y) == ("RECTANGLE", pytest.approx(2.0), pytest.approx(0.5))
    assert tuple(point.linked_objects[r].data.color) == pytest.approx((1, 0.5, 0.25))
    # later changes arrive through on_change
    scene.resolution = (20, 10)
    area.width = 3.0
    assert s.render.resolution_x == 20 and a.size == pytest.approx(3.0)
    r._configure_rgb(r.scratch_dir / "x")
    assert s.cycles.samples == 7 and s.render.use_motion_blur and s.cycles.max_bounces == 3


@pytest.mark.blender
def test_keyframes_are_linear_and_match_the_model():
    import bpy
    scene = _scene(frames=10)
    cube = kb.Cube()
    scene += cube
    for f, x in ((1, 0.0), (4, 3.0), (10, -3.0)):
        cube.position = (x, 2 * x, 0.5)
        cube.keyframe_insert("position", f)
    r = _blender(scene)
    r._sync()
    obj = cube.linked_objects[r]
    for f in (1, 2, 3, 5, 7, 9, 10):
        bpy.context.scene.frame_set(f)
        np.testing.assert_allclose(tuple(obj.location), cube.get_value_at("position", f),
                                   atol=1e-5)
    from kubric.renderer.blender import _action_fcurves
    curves = _action_fcurves(obj.animation_data.action)
    assert len(curves) == 3
    assert all(k.interpolation == "LINEAR" for c in curves for k in c.keyframe_points)


@pytest.mark.blender
def test_flat_material_colours_and_holdout():
    scene = _scene()
    scene.background = kb.Color(0.0, 0.0, 1.0)
    red = kb.Cube(scale=(1.5, 1.5, 1.5), material=kb.FlatMaterial(color=(1, 0, 0)))
    scene += red
    out = _blender(scene).render()
    rgba, seg = out["rgba"][0], out["segmentation"][0, ..., 0]
    label = scene.assets.index(red) + 1
    assert rgba.dtype == np.uint8 and rgba.shape == (24, 32, 4)
    inner = seg == label
    assert inner.sum() > 50 and (seg == 0).sum() > 50
    np.testing.assert_array_equal(np.median(rgba[inner], 0), [255, 0, 0, 255])
    np.testing.assert_array_equal(np.median(rgba[seg == 0], 0), [0, 0, 255, 255])
    relabelled = kb.adjust_segmentation_idxs(out["segmentation"], scene.assets, [red])
    np.testing.assert_array_equal(relabelled[0, ..., 0], inner.astype(np.uint32))
    red.material.holdout = True
    out = _blender(scene, background_transparency=True).render()
    assert np.all(out["rgba"][0][inner][:, 3] == 0)
    assert np.all(out["segmentation"][0, ..., 0][inner] == label)  # still annotated


@pytest.mark.blender
def test_principled_material_lit_by_lights():
    import bpy
    scene = _scene()
    mat = kb.PrincipledBSDFMaterial(color=(0.1, 0.8, 0.1), roughness=0.6, metallic=0.2,
                                    specular=0.3, ior=1.3, transmission=0.0)
    ball = kb.Sphere(material=mat)
    scene += [ball, kb.PointLight(position=(0, -3, 3), intensity=300)]
    r = _blender(scene, samples_per_pixel=4)
    bsdf = mat.linked_objects[r].node_tree.nodes["Principled BSDF"]
    assert bsdf.inputs["Specular IOR Level"].default_value == pytest.approx(0.3)
    assert bsdf.inputs["IOR"].default_value == pytest.approx(1.3)
    rgba = r.render(return_layers=("rgba", "segmentation"))
    m = rgba["segmentation"][0, ..., 0] > 0
    col = rgba["rgba"][0][m][:, :3].mean(0)
    assert col[1] > 2 * col[0] and col[1] > 40  # green and lit
    assert bpy.context.scene.cycles.filter_width == pytest.approx(1.5)


@pytest.mark.blender
def test_hdri_background_and_lighting():
    import bpy
    hdri = str(HDRI_DIR / "forest.exr")
    scene = _scene()
    scene.background = kb.Texture(filename=hdri, mapping="environment")
    scene.ambient_illumination = kb.Texture(filename=hdri, mapping="environment",
                                            strength=2.0, rotation=(0, 0, 1.0))
    ball = kb.Sphere(material=kb.PrincipledBSDFMaterial(color=(0.8, 0.8, 0.8)))
    scene += ball
    r = _blender(scene, samples_per_pixel=2)
    nodes = bpy.context.scene.world.node_tree.nodes
    assert tuple(nodes["ambient:Mapping"].inputs["Rotation"].default_value) == \
        pytest.approx((0, 0, 1.0))
    assert nodes["ambient"].inputs["Strength"].default_value == pytest.approx(2.0)
    out = r.render(return_layers=("rgba", "segmentation"))
    rgba, seg = out["rgba"][0], out["segmentation"][0, ..., 0]
    assert rgba[seg == 0][:, :3].std() > 3  # a textured backdrop, not a flat colour
    assert rgba[seg > 0][:, :3].mean() > 20  # the HDRI lights the sphere
    scene.ambient_illumination = kb.Color(0, 0, 0)
    dark = _blender(scene, samples_per_pixel=2).render(return_layers=("rgba",))["rgba"][0]
    assert dark[seg > 0][:, :3].mean() < rgba[seg > 0][:, :3].mean() / 3


@pytest.mark.blender
def test_texture_on_uv_and_environment_dome(tmp_path):
    from PIL import Image
    img = np.zeros((16, 16, 3), np.uint8)
    img[:, :8] = (255, 0, 0)
    img[:, 8:] = (0, 255, 0)
    path = tmp_path / "tex.png"
    Image.fromarray(img).save(path)
    scene = _scene()
    tex = kb.Texture(filename=str(path), mapping="uv")
    cube = kb.Cube(scale=1.5, material=kb.FlatMaterial(color=tex))
    scene += cube
    renderer = _blender(scene)
    rgba = renderer.render(return_layers=("rgba",))["rgba"][0]
    reds = (rgba[..., 0] > 150) & (rgba[..., 1] < 50)
    greens = (rgba[..., 1] > 150) & (rgba[..., 0] < 50)
    assert reds.sum() > 10 and greens.sum() > 10
    # changing the Texture after it was assigned re-renders with the new image
    blue = np.zeros_like(img)
    blue[..., 2] = 255
    Image.fromarray(blue).save(tmp_path / "blue.png")
    tex.filename = str(tmp_path / "blue.png")
    rgba = renderer.render(return_layers=("rgba",))["rgba"][0]
    blues = (rgba[..., 2] > 150) & (rgba[..., 0] < 50) & (rgba[..., 1] < 50)
    assert blues.sum() >= (reds | greens).sum() and not (rgba[..., :2] > 150).any()
    scene = _scene()
    env = kb.Texture(filename=str(HDRI_DIR / "city.exr"), mapping="environment")
    scene += kb.Sphere(scale=30, material=kb.FlatMaterial(color=env))
    rgba = _blender(scene).render(return_layers=("rgba",))["rgba"][0]
    assert rgba[..., :3].std() > 3


def _write_mesh_files(tmp_path):
    import trimesh
    a = trimesh.creation.box(extents=(1, 1, 1))
    b = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    b.apply_translation((0, 0, 1.0))
    both = trimesh.util.concatenate([a, b])
    scene = trimesh.Scene()
    scene.add_geometry(a, node_name="a")
    scene.add_geometry(b, node_name="b")
    obj = tmp_path / "two.obj"
    both.export(obj)
    glb = tmp_path / "two.glb"
    scene.export(glb)
    stl = tmp_path / "two.stl"
    both.export(stl)
    return {"obj": obj, "glb": glb, "stl": stl}, both.bounds


@pytest.mark.blender
@pytest.mark.parametrize("ext", ["obj", "glb", "stl"])
def test_file_based_object_is_one_labelled_object(tmp_path, ext):
    import bpy
    files, bounds = _write_mesh_files(tmp_path)
    scene = _scene()
    obj = kb.FileBasedObject(render_filename=str(files[ext]), bounds=bounds,
                             position=(0, 0, 0.2), scale=1.2)
    scene += obj
    r = _blender(scene)
    assert len([o for o in bpy.data.objects if o.type == "MESH"]) == 1
    out = r.render(return_layers=("segmentation", "object_coordinates"))
    seg = out["segmentation"][0, ..., 0]
    label = scene.assets.index(obj) + 1
    assert set(np.unique(seg)) == {0, label}
    oc = out["object_coordinates"][0][seg == label]
    assert oc.min() >= 0 and oc.max() <= 1 and oc.std() > 0.1
    if ext != "glb":  # glTF is Y-up: the importer turns it to Blender's Z-up
        np.testing.assert_allclose(np.asarray(r.backend_object(obj).dimensions),
                                   (bounds[1] - bounds[0]) * 1.2, rtol=1e-5)


@pytest.mark.blender
def test_file_based_object_errors(tmp_path):
    scene = _scene()
    scene += kb.FileBasedObject(render_filename=str(tmp_path / "x.xyz"))
    with pytest.raises(ValueError, match="extension"):
        _blender(scene)


@pytest.mark.blender
def test_multiple_cameras_without_resimulating():
    scene = kb.Scene(resolution=(24, 16), frame_start=1, frame_end=2)
    cams = [kb.PerspectiveCamera(name=f"cam{i}", position=(0, 0, d)) for i, d in
            enumerate((4.0, 6.0))]
    scene += kb.Cube(position=(0, 0, -1), scale=(30, 30, 1))
    for c in cams:
        scene += c
    r = _blender(scene)
    for c, d in zip(cams, (4.0, 6.0), strict=True):
        scene.camera = c
        z = r.render(frames=[2, 1], return_layers=("z",))["z"]
        assert z.shape == (2, 16, 24, 1)
        np.testing.assert_allclose(z, d, atol=1e-4)


@pytest.mark.blender
def test_save_state_writes_an_animated_blend(tmp_path):
    import bpy
    scene = _scene(frames=3)
    cube = kb.Cube(name="mover")
    scene += cube
    for f in (1, 3):
        cube.position = (f, 0, 0)
        cube.keyframe_insert("position", f)
    r = _blender(scene)
    path = r.save_state(tmp_path / "scene.blend")
    assert path.is_file()
    with bpy.data.libraries.load(str(path)) as (src, dst):
        assert "mover" in src.objects and "PerspectiveCamera" in src.objects
        assert len(src.worlds) == 1 and len(src.scenes) == 1
        dst.objects = ["mover"]
    loaded = dst.objects[0]
    from kubric.renderer.blender import _action_fcurves
    curves = _action_fcurves(loaded.animation_data.action)
    assert all(k.interpolation == "LINEAR" for c in curves for k in c.keyframe_points)
    assert sorted({k.co[0] for c in curves for k in c.keyframe_points}) == [1.0, 3.0]


@pytest.mark.blender
def test_verbose_flag_controls_console_output(tmp_path):
    code = ("import kubric as kb\nfrom kubric.renderer.blender import Blender\n"
            "s = kb.Scene(resolution=(8, 8), frame_start=1, frame_end=1)\n"
            "s += kb.PerspectiveCamera(position=(0, 0, 5))\ns += kb.Cube()\n"
            "import sys\nr = Blender(s, samples_per_pixel=1, verbose=sys.argv[1] == '1')\n"
            "r.render(return_layers=('rgba',))\nprint('DONE')\n")
    outs = []
    for flag in ("0", "1"):
        res = subprocess.run([sys.executable, "-c", code, flag], capture_output=True,
                             text=True, timeout=120)
        assert res.returncode == 0, res.stderr
        outs.append(res.stdout + res.stderr)
    assert "Fra:" not in outs[0] and "DONE" in outs[0] and "| WARNING" not in outs[0]
    assert "Fra:" in outs[1] or "Saved" in outs[1]


@pytest.mark.blender
def test_gpu_request_without_gpu_is_a_clear_error(monkeypatch):
    import bpy
    prefs = bpy.context.preferences.addons["cycles"].preferences
    prefs.get_devices()
    if any(d.type != "CPU" for d in prefs.devices):
        pytest.skip("this machine has a GPU for Cycles")
    with pytest.raises(RuntimeError, match="GPU"):
        _blender(_scene(), device="GPU")
    monkeypatch.setenv("KUBRIC_USE_GPU", "1")
    with pytest.raises(RuntimeError, match="KUBRIC_USE_GPU"):
        _blender(_scene())


@pytest.mark.blender
def test_quaternion_keys_are_sign_continuous():
    import bpy
    scene = _scene(frames=2)
    cube = kb.Cube()
    scene += cube
    q1 = np.array(kb.Quaternion.from_euler((0, 0, 0.2)))
    q2 = np.array(kb.Quaternion.from_euler((0, 0, 0.4)))
    cube.quaternion = q1
    cube.keyframe_insert("quaternion", 1)
    cube.quaternion = -q2  # the same rotation as q2, opposite sign
    cube.keyframe_insert("quaternion", 2)
    r = _blender(scene)
    r._sync()
    bpy.context.scene.frame_set(1, subframe=0.5)
    obj = cube.linked_objects[r]
    rot = np.array(obj.matrix_world.to_3x3())
    np.testing.assert_allclose(rot, kb.Quaternion.from_euler((0, 0, 0.3)).rotation_matrix,
                               atol=2e-3)


@pytest.mark.blender
def test_removed_asset_disappears_from_render():
    scene = _scene()
    cube = kb.Cube(scale=1.5)
    scene += cube
    r = _blender(scene)
    assert (r.render(return_layers=("segmentation",))["segmentation"] == 2).sum() > 50
    scene.remove(cube)
    assert r.render(return_layers=("segmentation",))["segmentation"].max() == 0
    scene += kb.Sphere(scale=1.5)
    seg = r.render_still(return_layers=("segmentation",))["segmentation"]
    assert seg.shape == (24, 32, 1) and (seg == 2).sum() > 50  # the sphere is asset 2 now


@pytest.mark.blender
def test_deleted_model_keyframes_leave_blender_too():
    import bpy

    scene = kb.Scene(resolution=(8, 8), frame_start=0, frame_end=4)
    renderer = kb.renderer.Blender(scene, samples_per_pixel=1)
    cube = kb.Cube()
    scene += cube
    for frame in range(5):
        cube.position = (frame, 0, 0)
        cube.keyframe_insert("position", frame)
    obj = cube.linked_objects[renderer]
    cube.keyframe_delete("position", 4)
    bpy.context.scene.frame_set(4)
    # with frame 4's key gone, Blender holds the last remaining key (frame 3), like the model
    assert obj.location[0] == pytest.approx(3.0)
    assert cube.get_value_at("position", 4)[0] == pytest.approx(3.0)


def _equirect_png(path, w=512, h=256):
    """A smooth synthetic equirectangular image: R encodes the elevation (0 at the nadir, 255 at
    the zenith), G = 128 + 100·cos(2π·u) the image column u ∈ [0, 1); returns the analytic
    expectation ``(elevation, u) -> (R, G)`` in 8-bit values."""
    from PIL import Image
    rows = 1.0 - (np.arange(h) + 0.5) / h
    cols = (np.arange(w) + 0.5) / w
    img = np.zeros((h, w, 3), np.uint8)
    img[..., 0] = np.round(255 * rows)[:, None]
    img[..., 1] = np.round(128 + 100 * np.cos(2 * np.pi * cols))[None, :]
    Image.fromarray(img).save(path)
    return lambda elev, u: (255 * (elev / np.pi + 0.5), 128 + 100 * np.cos(2 * np.pi * u))


@pytest.mark.blender
def test_environment_ground_projection(tmp_path):
    """A floor whose environment texture has projection_height h shows, at floor point p, the
    texel in direction p − (origin + (0, 0, h)): the nadir texel right below the projection centre,
    rows towards the horizon far away; h = 0 gives the horizon row everywhere (radial streaks)."""
    from kubric.core import camera_geometry as geo
    expect = _equirect_png(tmp_path / "env.png")
    origin, height, top = np.array([1.0, -2.0, 0.0]), 5.0, 0.01
    w = 32
    renders = {}
    for h in (height, 0.0):
        scene = kb.Scene(resolution=(w, w), frame_start=1, frame_end=1)
        tex = kb.Texture(filename=str(tmp_path / "env.png"), mapping="environment",
                         projection_height=h)
        scene += kb.Cube(position=origin, scale=(40, 40, top),
                         material=kb.FlatMaterial(color=tex))
        scene += kb.OrthographicCamera(position=(1.0, -2.001, 10.0), look_at=(1.0, -2.0, 0.0),
                                       orthographic_scale=20.0)
        renders[h] = _blender(scene, samples_per_pixel=8).render(return_layers=("rgba",))
        renders[h] = renders[h]["rgba"][0][..., :3].astype(float)
    # floor point of each pixel centre (orthographic rays straight down onto z = top)
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(w) + 0.5)
    origins, dirs = geo.pixel_rays(scene.camera, np.stack([cols, rows], -1))
    points = origins + dirs * ((origins[..., 2] - top) / -dirs[..., 2])[..., None]
    d = points - (origin + (0.0, 0.0, height))
    elev = np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1]))
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * np.pi)  # Blender's equirect column
    red, green = expect(elev, u)
    got = renders[height]
    assert np.abs(got[..., 0] - red).max() < 6
    off_axis = np.hypot(d[..., 0], d[..., 1]) > 1.0  # the column is undefined at the nadir
    assert np.abs(got[..., 1] - green)[off_axis].max() < 12
    centre = np.unravel_index(np.argmin(np.hypot(d[..., 0], d[..., 1])), elev.shape)
    assert got[centre][0] < 15  # straight below the centre: the nadir texel (R = 0)
    assert 85 < got[0, 0, 0] < 110  # a corner 14 m away: 20° below the horizon row (R = 127)
    flat = renders[0.0][..., 0]  # no projection height: every floor point looks at the horizon
    assert np.abs(flat - 127.5).max() < 4


@pytest.mark.blender
def test_upstream_hdri_shortcuts_missing_textures_and_save_state_replace(tmp_path):
    import bpy
    scene = _scene(w=8, h=6)
    r = _blender(scene)
    hdri = HDRI_DIR / "forest.exr"
    r._set_ambient_light_hdri(str(hdri), hdri_rotation=(0, 0, 1.0), strength=0.5)
    r._set_background_hdri(str(hdri))
    assert scene.ambient_illumination.strength == 0.5
    assert scene.ambient_illumination.rotation.tolist() == [0, 0, 1]
    assert scene.background.filename == str(hdri)
    bright = r.render_still(1, return_layers=("rgba",))["rgba"]
    assert bright[..., :3].mean() > 5  # the world is lit by the HDRI
    # a texture whose file vanished is an error naming it, unless explicitly ignored
    gone = tmp_path / "gone.png"
    from PIL import Image
    Image.new("RGB", (4, 4), (255, 0, 0)).save(gone)
    scene += kb.Cube(material=kb.FlatMaterial(color=kb.Texture(filename=str(gone))))
    r._sync()
    gone.unlink()
    with pytest.raises(FileNotFoundError, match="missing texture file.*gone.png"):
        r.render_still(1, return_layers=("rgba",))
    assert r.render_still(1, return_layers=("segmentation",),
                          ignore_missing_textures=True)["segmentation"].max() > 0
    # saving twice replaces the file (no .blend1 backup) and packs images
    path = tmp_path / "s.blend"
    r.save_state(path)
    r.save_state(path)
    assert path.is_file() and not (tmp_path / "s.blend1").exists()
    assert any(img.packed_file is not None for img in bpy.data.images if img.filepath)


@pytest.mark.blender
def test_uv_layer_wraps_tiled_coordinates(tmp_path):
    # a 4 m quad whose UVs run from 0 to 2.5 along x (a texture tiled 2.5 times)
    obj = tmp_path / "tiled.obj"
    obj.write_text("v -2 -2 0\nv 2 -2 0\nv 2 2 0\nv -2 2 0\n"
                   "vt 0 0\nvt 2.5 0\nvt 2.5 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
    scene = kb.Scene(resolution=(40, 8), frame_start=1, frame_end=1)
    scene += kb.OrthographicCamera(position=(0, 0, 5), orthographic_scale=4,
                                   quaternion=(1, 0, 0, 0))  # looks down −z, x right, y up
    scene += kb.FileBasedObject(render_filename=str(obj), bounds=((-2, -2, 0), (2, 2, 0)))
    uv = _blender(scene).render_still(1, return_layers=("uv",))["uv"]
    x = (np.arange(40) + 0.5) / 40 * 4 - 2  # world x of each pixel centre
    expected_u = np.mod((x + 2) / 4 * 2.5, 1.0)
    row = uv[4, :, 0]
    assert np.all((uv[..., :2] >= 0) & (uv[..., :2] < 1))
    interior = np.abs(expected_u - np.round(expected_u)) > 0.05  # away from the wrap seams
    np.testing.assert_allclose(row[interior], expected_u[interior], atol=1e-3)
