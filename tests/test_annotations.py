"""Annotations on synthetic segmentation arrays and a hand-keyframed scene (no renderer)."""

import numpy as np
import pytest

import kubric as kb
from kubric.core import camera_geometry as geo


def _scene_with_objects():
    scene = kb.Scene(resolution=(8, 6), frame_start=1, frame_end=3)
    cam = kb.PerspectiveCamera(position=(0, -10, 0), look_at=(0, 0, 0))
    scene.add(cam)
    a, b, c = kb.Cube(name="a"), kb.Sphere(name="b"), kb.Cube(name="c")
    scene.add([a, b, c])
    return scene, cam, a, b, c


def test_visibility_counts_and_sorting_and_relabel():
    scene, cam, a, b, c = _scene_with_objects()
    assets = list(scene.assets)  # cam, a, (a's material), b, ... -> labels by position
    la, lb, lc = (assets.index(x) + 1 for x in (a, b, c))
    seg = np.zeros((2, 6, 8, 1), dtype=np.uint32)
    seg[0, :2, :2] = la            # 4 px of a
    seg[0, 3:, 3:] = lb            # 15 px of b
    seg[1, 0, 0] = la              # 1 px of a
    vis = kb.compute_visibility(seg, assets)
    assert vis.shape == (len(assets), 2)
    np.testing.assert_array_equal(vis[la - 1], [4, 1])
    np.testing.assert_array_equal(vis[lb - 1], [15, 0])
    np.testing.assert_array_equal(b.metadata["visibility"], [15, 0])
    assert int(np.sum(c.metadata["visibility"])) == 0
    ordered = kb.post_processing.visible_sorted(list(scene.foreground_assets))
    assert ordered == [b, a]  # c never visible: dropped
    new = kb.adjust_segmentation_idxs(seg, assets, ordered)
    assert new.dtype == seg.dtype and new.shape == seg.shape
    assert set(np.unique(new)) == {0, 1, 2}
    np.testing.assert_array_equal(new[0, 3:, 3:, 0], 1)   # b is instance 0 -> label 1
    np.testing.assert_array_equal(new[0, :2, :2, 0], 2)   # a is instance 1 -> label 2
    assert new[0, 2, 0, 0] == 0


def test_segmentation_id_override_and_bad_input():
    scene, cam, a, b, c = _scene_with_objects()
    a.segmentation_id = 7
    seg = np.full((1, 6, 8), 7, dtype=np.uint16)
    vis = kb.compute_visibility(seg, [a, b])
    np.testing.assert_array_equal(vis, [[48], [0]])
    with pytest.raises(ValueError, match="shape"):
        kb.compute_visibility(np.zeros((6, 8)), [a])
    with pytest.raises(TypeError, match="integer"):
        kb.compute_visibility(np.zeros((1, 6, 8), np.float32), [a])
    with pytest.raises(ValueError, match="compute_visibility"):
        kb.post_processing.visible_sorted([c])


def test_bboxes_contain_every_labelled_pixel():
    rng = np.random.default_rng(3)
    seg = np.zeros((4, 20, 30, 1), dtype=np.uint8)
    seg[0, 2:5, 7:9] = 1
    seg[1, 19, 29] = 1
    seg[3] = (rng.random((20, 30, 1)) < 0.1) * 2
    objs = [kb.Cube(), kb.Cube()]
    boxes = kb.compute_bboxes(seg, objs)
    b1, f1 = boxes[0]
    np.testing.assert_array_equal(f1, [0, 1])
    np.testing.assert_allclose(b1[0], [2 / 20, 7 / 30, 5 / 20, 9 / 30], rtol=1e-6)
    np.testing.assert_allclose(b1[1], [19 / 20, 29 / 30, 1.0, 1.0], rtol=1e-6)
    assert b1.dtype == np.float32 and b1.shape == (2, 4)
    b2, f2 = boxes[1]
    np.testing.assert_array_equal(f2, [3])
    ys, xs = np.nonzero(seg[3, :, :, 0] == 2)
    ymin, xmin, ymax, xmax = b2[0]
    # every labelled pixel lies fully inside the box, and the box is tight
    assert np.all(ys / 20 >= ymin - 1e-6) and np.all((ys + 1) / 20 <= ymax + 1e-6)
    assert np.all(xs / 30 >= xmin - 1e-6) and np.all((xs + 1) / 30 <= xmax + 1e-6)
    assert ys.min() / 20 == pytest.approx(ymin) and (xs.max() + 1) / 30 == pytest.approx(xmax)
    assert objs[0].metadata["bbox_frames"].tolist() == [0, 1]


def _moving_scene():
    scene = kb.Scene(resolution=(64, 48), frame_start=1, frame_end=3)
    cam = kb.PerspectiveCamera(focal_length=35, sensor_width=32, position=(0, -10, 2))
    scene.add(cam)
    for f, x in ((1, 0.0), (3, 2.0)):
        cam.position = (x, -10, 2)
        cam.look_at((0, 0, 0))
        cam.keyframe_insert("position", f)
        cam.keyframe_insert("quaternion", f)
    obj = kb.Cube(name="box", scale=(0.5, 1.0, 2.0), mass=2.0, friction=0.3, restitution=0.7,
                  metadata={"shape": "cube", "color_label": "red"})
    scene.add(obj)
    obj.position = (0, 0, 1)
    obj.keyframe_insert("position", 1)
    obj.position = (2, 0, 1)
    obj.quaternion = kb.Quaternion(axis="Z", angle=np.pi / 2)
    obj.keyframe_insert("position", 3)
    obj.keyframe_insert("quaternion", 3)
    obj.quaternion = (1, 0, 0, 0)
    obj.keyframe_insert("quaternion", 1)
    obj.velocity = (1, 0, 0)
    obj.keyframe_insert("velocity", 1)
    floor = kb.Cube(name="floor", static=True, background=True)
    scene.add(floor)
    return scene, cam, obj, floor


def test_camera_info_fields_and_conventions():
    scene, cam, _, _ = _moving_scene()
    info = kb.get_camera_info(cam)
    assert info["positions"].shape == (3, 3) and info["quaternions"].shape == (3, 4)
    np.testing.assert_allclose(info["positions"][1], [1, -10, 2], atol=1e-6)
    f, sw, sh = 35.0, 32.0, 32.0 * 48 / 64
    np.testing.assert_allclose(info["K"], [[f / sw, 0, -0.5], [0, -f / sh, -0.5], [0, 0, -1]])
    assert info["field_of_view"] == pytest.approx(2 * np.arctan(16 / 35))
    assert info["matrices_world"].shape == (3, 4, 4)
    np.testing.assert_allclose(info["R"], info["matrices_world"][0])
    np.testing.assert_allclose(info["matrices_world"][2][:3, 3], [2, -10, 2], atol=1e-6)
    # OpenCV intrinsics + per-frame matrices reproduce camera_geometry's projection.
    point = np.array([0.3, 0.4, 0.5])
    for t, frame in enumerate(scene.frames):
        m = np.linalg.inv(info["matrices_world"][t])
        p_cv = geo.CAMERA_TO_OPENCV @ (m[:3, :3] @ point + m[:3, 3])
        xy = (info["intrinsics_pixels"] @ p_cv)[:2] / p_cv[2]
        uv = geo.project_points(cam, point, frame)[:2]
        np.testing.assert_allclose(xy, uv * [64, 48], atol=1e-9)
        # and with the normalised K (upstream form)
        p_cam = m[:3, :3] @ point + m[:3, 3]
        h = info["K"] @ p_cam
        np.testing.assert_allclose(h[:2] / h[2], uv, atol=1e-12)
    assert "down -z" in info["conventions"]


def test_instance_info_per_frame_values():
    scene, cam, obj, floor = _moving_scene()
    [info] = kb.get_instance_info(scene)  # floor is background: excluded
    assert info["asset_id"] == "box" and info["shape"] == "cube" and info["color_label"] == "red"
    assert (info["mass"], info["friction"], info["restitution"]) == (2.0, 0.3, 0.7)
    np.testing.assert_allclose(info["positions"], [[0, 0, 1], [1, 0, 1], [2, 0, 1]], atol=1e-6)
    np.testing.assert_allclose(info["quaternions"][1], kb.Quaternion(axis="Z", angle=np.pi / 4),
                               atol=1e-6)
    assert info["velocities"].shape == (3, 3) and info["angular_velocities"].shape == (3, 3)
    # image positions use the camera pose of each frame
    for t, frame in enumerate(scene.frames):
        expected = geo.project_points(cam, info["positions"][t], frame)[:2]
        np.testing.assert_allclose(info["image_positions"][t], expected, atol=1e-6)
    assert info["image_positions"][0][0] == pytest.approx(0.5, abs=1e-6)
    # bboxes_3d: corner order product(x, y, z) of scaled bounds, rotated then translated
    box = info["bboxes_3d"]
    assert box.shape == (3, 8, 3)
    np.testing.assert_allclose(box[0][0], [-0.5, -1, -1], atol=1e-6)
    np.testing.assert_allclose(box[0][7], [0.5, 1, 3], atol=1e-6)
    # at frame 3 rotated 90° about z: local x -> world y
    np.testing.assert_allclose(box[2][7], [2 - 1, 0.5, 3], atol=1e-5)
    # explicit subset and frame list
    [info_f] = kb.get_instance_info(scene, [floor], frames=[2])
    assert info_f["positions"].shape == (1, 3)


def test_process_collisions_indices_and_frame_pose():
    scene, cam, obj, floor = _moving_scene()
    events = kb.process_collisions(
        [{"instances": (obj, floor), "frame": 1.5, "force": 3.0, "position": (1, 1, 0),
          "contact_normal": (0, 0, 1)},
         {"instances": (floor, obj), "frame": 3.0, "force": 1.0, "position": (1, 0, 0),
          "contact_normal": (0, 0, -1)}], scene, assets_subset=[obj])
    assert events[0]["instances"] == [0, -1] and events[1]["instances"] == [-1, 0]
    assert events[0]["frame"] == 1.5 and events[0]["force"] == 3.0
    np.testing.assert_allclose(events[0]["image_position"],
                               geo.project_points(cam, (1, 1, 0), 1.5)[:2], atol=1e-6)
    # the pose at frame 1.5 differs from the last pose: using the last one would be wrong
    last = geo.project_points(cam, (1, 1, 0), 3)[:2]
    assert abs(events[0]["image_position"][0] - last[0]) > 0.01
    with pytest.raises(KeyError, match="contact_normal"):
        kb.process_collisions([{"instances": (obj, floor), "frame": 1, "force": 0,
                                "position": (0, 0, 0)}], scene)


def test_scene_metadata():
    scene, _, _, _ = _moving_scene()
    scene.background = kb.get_color("red")
    meta = kb.get_scene_metadata(scene, seed=5, num_instances=1)
    assert meta["resolution"] == [64, 48] and meta["num_frames"] == 3
    assert meta["frame_rate"] == 24 and meta["step_rate"] == 240
    assert meta["seed"] == 5 and meta["num_instances"] == 1
    assert meta["background"] == "#ff0000ff"
    np.testing.assert_allclose(meta["gravity"], [0, 0, -10])
    assert "bpy" in meta["versions"] and "pybullet" in meta["versions"]


def test_get_camera_info_merges_extra_keys_like_upstream():
    scene = kb.Scene(resolution=(16, 8), frame_start=1, frame_end=2)
    scene += kb.PerspectiveCamera(position=(0, -5, 1), look_at=(0, 0, 0))
    info = kb.get_camera_info(scene.camera, rig="left")
    assert info["rig"] == "left" and info["positions"].shape == (2, 3)


def test_get_instance_info_skips_lights_by_default_and_rejects_them_explicitly():
    scene = kb.Scene(resolution=(16, 16), frame_start=1, frame_end=2)
    scene += kb.PerspectiveCamera(position=(0, -5, 1), look_at=(0, 0, 0))
    light = kb.PointLight(position=(-2.5, -1, 5), intensity=300)
    cube = kb.Cube(position=(0, 0, 1))
    scene.add([light, cube])
    infos = kb.get_instance_info(scene)
    assert [i["asset_id"] for i in infos] == [cube.uid]
    with pytest.raises(TypeError, match=r"\['PointLight'\] are not PhysicalObjects"):
        kb.get_instance_info(scene, [light, cube])
