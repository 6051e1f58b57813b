"""The blender backend through a lens (a Cycles custom OSL camera, kubric.renderer.blender_lens)
against the raycast backend as the oracle (whose lens rays are checked against OpenCV in
tests/test_lens_movi.py): the same exact layers on a small scene with a moving object, a shifted
principal point and each lens model; a walking person's flow through the custom-camera path
against Cycles' motion vectors; a real pose_estimation scene's keypoints against OpenCV; and what
it refuses."""

import numpy as np
import pytest
from scipy.ndimage import maximum_filter, minimum_filter

import kubric as kb
from kubric.core import camera_geometry as geo
from kubric.core import lenses
from kubric.renderer import base

pytestmark = pytest.mark.blender

W, H = 64, 48
LENSES = {"fisheye": lenses.Fisheye(0.2, -0.05, 0.01, -0.002),
          "opencv": lenses.BrownConrady(-0.3, 0.09, 0.002, -0.001, -0.01),
          # the radial map turns at r = 0.65 (ρ = 0.43): the image corners have no ray
          "barrel": lenses.BrownConrady(k1=-0.8)}
LAYERS = ("depth", "z", "segmentation", "forward_flow", "backward_flow", "normal",
          "object_coordinates", "uv")


def _scene(lens):
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=2)
    scene += kb.PerspectiveCamera(name="camera", position=(1, -8, 3), look_at=(0, 0, 0.5),
                                  lens=lens, shift_x=0.03, shift_y=-0.02)
    scene += kb.Cube(scale=(40, 40, 0.1), position=(0, 0, -0.1), background=True)
    cube = kb.Cube(scale=0.8, position=(0.5, 0, 0.8))
    scene += cube
    scene += kb.Sphere(scale=0.6, position=(-1.5, 1, 0.6))
    for f in range(4):
        cube.position = (0.5 + 0.2 * f, 0.1 * f, 0.8)
        cube.quaternion = kb.Quaternion(axis=(0, 0, 1), angle=0.1 * f)
        cube.keyframe_insert("position", f)
        cube.keyframe_insert("quaternion", f)
    return scene


@pytest.mark.parametrize("model", sorted(LENSES))
def test_blender_lens_layers_agree_with_raycast(model, tmp_path):
    scene = _scene(LENSES[model])
    ray = base.create("raycast", scene).render(return_layers=LAYERS)
    cycles = base.create("blender", scene, tmp_path, samples_per_pixel=4,
                         background_transparency=True).render(return_layers=LAYERS + ("rgba",))
    seg_r, seg_c = ray["segmentation"][..., 0], cycles["segmentation"][..., 0]
    assert (seg_r != seg_c).mean() < 0.002  # at most a few silhouette pixels
    single = maximum_filter(seg_r, size=(1, 3, 3)) == minimum_filter(seg_r, size=(1, 3, 3))
    interior = single & (seg_r == seg_c) & (seg_r > 0)
    assert interior.sum() > 3000
    for name in ("depth", "z"):
        rel = np.abs(ray[name] - cycles[name])[..., 0][interior] / ray[name][..., 0][interior]
        assert rel.max() < 5e-5, (name, rel.max())
    for name, tol in (("forward_flow", 5e-4), ("backward_flow", 5e-4), ("normal", 1e-4),
                      ("object_coordinates", 1e-4), ("uv", 1e-4)):
        err = np.abs(ray[name] - cycles[name])[interior].max()
        assert err < tol, (name, err)
    no_ray = ~np.isfinite(geo.pixel_rays(scene.camera, geo.pixel_centres(H, W))[1]).all(-1)
    assert (model == "barrel") == bool(no_ray.any())
    assert not cycles["segmentation"][:, no_ray].any()  # Cycles casts nothing there either
    moving = np.abs(ray["forward_flow"][interior]).max()
    assert moving > 1.0  # the flow is not trivially zero
    # RGB through the same lens: its coverage (alpha) is where the exact layers see a surface
    covered = cycles["rgba"][..., 3] > 127
    assert (covered == (seg_c > 0)).mean() > 0.98  # edges (and the image circle) blend


def test_blender_refuses_what_its_lens_camera_cannot_render(tmp_path):
    scene = _scene(LENSES["fisheye"])
    scene.camera.keyframe_insert("focal_length", 1)
    renderer = base.create("blender", scene, tmp_path)
    with pytest.raises(base.CapabilityError, match=r"camera 'camera' has a lens and keyframed "
                                                   r"\['focal_length'\]"):
        renderer.render(frames=[1], return_layers=("depth",))


def test_character_flow_through_a_custom_camera_equals_cycles_motion_vectors(tmp_path):
    """A walking (procedural) person: the flow a lens camera computes from the rest-pose AOV
    (kubric.renderer.blender_lens.rest_anchors + the skinned mesh at t ± 1) equals Cycles' own
    motion vectors of the pinhole camera, with the lens set to zero coefficients (the same rays
    through the custom-camera path)."""
    from character_fixtures import walking_scene

    out = {}
    for name, lens in (("pinhole", None), ("custom", lenses.BrownConrady())):
        scene, _ = walking_scene(frames=3)
        scene.camera.lens = lens
        out[name] = base.create("blender", scene, tmp_path / name, samples_per_pixel=1).render(
            return_layers=("depth", "segmentation", "forward_flow", "backward_flow"))
    a, b = out["pinhole"], out["custom"]
    seg = a["segmentation"][..., 0]
    assert np.array_equal(seg, b["segmentation"][..., 0])
    single = maximum_filter(seg, size=(1, 3, 3)) == minimum_filter(seg, size=(1, 3, 3))
    person = single & (seg == 1)  # the person is the first asset
    assert person.sum() > 100
    rel = np.abs(a["depth"] - b["depth"])[..., 0][single & (seg > 0)] / a["depth"][..., 0][
        single & (seg > 0)]
    assert rel.max() < 5e-6
    for name in ("forward_flow", "backward_flow"):
        assert np.abs(a[name][person]).max() > 0.5  # the person moves
        assert np.abs(a[name] - b[name])[person].max() < 1e-3


def test_pose_estimation_keypoints_through_a_lens_are_opencvs(tmp_path):
    """A real pose_estimation scene with lens=fisheye: every person's keypoints_2d is
    cv2.fisheye.projectPoints of its keypoints_3d with the recorded camera (< 1e-3 px)."""
    import json

    import cv2

    from tests.collection_fixtures import run_worker
    from tests.test_pose_estimation import PROCEDURAL

    run_worker("pose_estimation", 3, tmp_path, ["resolution=64", "frame_end=3", "quality=draft",
                                                "max_num_people=2", "lens=fisheye",
                                                "lens_coefficients=0.2,-0.05,0.01,-0.002",
                                                *PROCEDURAL])
    meta = json.loads((tmp_path / "scene_00000003" / "metadata.json").read_text())
    cam = meta["camera"]
    assert cam["distortion_model"] == "fisheye"
    k = np.asarray(cam["intrinsics_pixels"], np.float64)
    dist = np.asarray(cam["distortion_coefficients"][:4], np.float64)
    checked = 0
    for person in meta["instances"]:
        if "keypoints_3d" not in person:
            continue
        for t, ext in enumerate(cam["extrinsics_opencv"]):
            ext = np.asarray(ext, np.float64)
            kp3 = np.asarray(person["keypoints_3d"][t], np.float64)
            xy = cv2.fisheye.projectPoints(kp3[:, None], cv2.Rodrigues(ext[:3, :3])[0],
                                           ext[:3, 3], k, dist)[0][:, 0]
            assert np.abs(np.asarray(person["keypoints_2d"][t]) - xy).max() < 1e-3
            checked += 1
    assert checked >= 3


def _original_osl_source():
    from kubric.renderer import blender_lens as bl
    return bl.osl_source


_OSL_SOURCE = _original_osl_source()


def _wireframe_brightness(lens, tmp_path, monkeypatch, **source_options):
    """Mean brightness (H, W) of a grid seen through ``lens``, drawn with Cycles' Wireframe node
    in *pixel size* mode: its wire width comes from the camera rays' differentials."""
    import bpy

    from kubric.renderer import blender_lens as bl
    monkeypatch.setattr(bl, "osl_source", lambda *a: _OSL_SOURCE(*a, **source_options))
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(name="camera", position=(1, -8, 3), look_at=(0, 0, 0.5),
                                  lens=lens)
    renderer = base.create("blender", scene, tmp_path, samples_per_pixel=8,
                           use_denoising=False)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=24, y_subdivisions=24, size=12)
    material = bpy.data.materials.new("wire")
    nodes, links = material.node_tree.nodes, material.node_tree.links
    nodes.clear()
    wire, emission = nodes.new("ShaderNodeWireframe"), nodes.new("ShaderNodeEmission")
    wire.use_pixel_size = True
    wire.inputs[0].default_value = 2.0
    links.new(wire.outputs[0], emission.inputs["Strength"])
    links.new(emission.outputs[0], nodes.new("ShaderNodeOutputMaterial").inputs[0])
    bpy.context.active_object.data.materials.append(material)
    rgba = renderer.render(frames=[1], return_layers=("rgba",))["rgba"][0]
    return rgba[..., :3].astype(np.float64).mean(-1)


@pytest.mark.parametrize("model", ["fisheye", "opencv"])
def test_the_lens_shader_s_ray_derivatives_equal_osl_s_automatic_ones(model, tmp_path,
                                                                     monkeypatch):
    """The shader writes the ray's derivatives out (so OSL does not differentiate its Newton
    iterations: ~15 % of a frame); a wireframe drawn at a fixed width in pixels — a width Cycles
    takes from those derivatives — comes out as with OSL's own automatic derivatives, and
    visibly wider with derivatives 4× too large."""
    from kubric.renderer import blender_lens as bl
    lens = LENSES[model]
    auto = _wireframe_brightness(lens, tmp_path / "a", monkeypatch, derivatives=False)
    ours = _wireframe_brightness(lens, tmp_path / "b", monkeypatch)
    monkeypatch.setattr(bl, "PIXEL_STEP", (4.0, -4.0))
    wide = _wireframe_brightness(lens, tmp_path / "c", monkeypatch)
    assert 20 < auto.mean() < 200  # wires and gaps both on screen
    assert np.abs(ours - auto).mean() < 0.5, np.abs(ours - auto).mean()
    assert np.abs(wide - auto).mean() > 10 and wide.mean() > auto.mean() + 10
