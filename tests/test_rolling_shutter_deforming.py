"""Rolling shutter on deforming surfaces, on real output against independent derivations:

* the raycast backend's rolling render of a simulated cloth (a Deformable) equals, row by row,
  global-shutter renders of the scene at each row's time t_r = f + d·((r + 0.5)/H − 1/2);
* its forward flow lands where the pixel's material point (found here by casting the pixel ray
  against the cloth mesh at t_r, Möller–Trumbore) is seen in the next frame at the time of the
  row it lands on (a plain fixed-point iteration here, cv2 projection), < 1e-3 px;
* tracks on the cloth: each pixel is the cv2 projection of the query's material point on the
  mesh at the time of the row the pixel lies on, < 1e-3 px;
* keypoints of a walking character: each keypoint's pixel is the cv2 projection of the
  character's keypoint at the time of its row (camera at that time), < 1e-3 px.
"""

import numpy as np

import kubric as kb
from kubric.annotations import tracks as tr
from kubric.annotations.keypoints import character_keypoints
from kubric.annotations.surfaces import ray_triangles
from kubric.renderer import base
from tests.character_fixtures import walking_scene
from tests.test_rolling_shutter import D, H, W, _cv2_project, rows_equal_row_time_renders


def _row_time(f, y):
    return f + D * (np.clip(y, 0, H) / H - 0.5)


def _cloth_scene():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3)
    cam = kb.PerspectiveCamera(focal_length=30, rolling_shutter_duration=D)
    scene += cam
    scene += kb.DirectionalLight(position=(1, -1, 5), look_at=(0, 0, 0), intensity=2.0)
    scene += kb.Cube(name="floor", scale=(6, 6, 0.1), position=(0, 0, -0.1), background=True,
                     segmentation_id=9)
    cloth = kb.Deformable.cloth(size=(2.6, 2.6), resolution=(7, 7), name="cloth",
                                position=(0, 0, 0.5), segmentation_id=5)
    scene += cloth
    rest = cloth.rest_world_vertices()
    for f in range(0, 6):
        cam.position = (0.2 * f, -6 + 0.1 * f, 5)
        cam.look_at((0.1 * f, 0.3 * f, 0))  # tilting: vertical image motion
        cam.keyframe_insert("position", f)
        cam.keyframe_insert("quaternion", f)
        wave = rest + [-1.0 + 0.5 * f, -2.6 + 0.8 * f, 0.0]
        wave[:, 2] += 0.25 * np.sin(2.5 * rest[:, 0] + 0.9 * f)
        cloth.record(f, wave)
    return scene, cloth


def _material_point(scene, cloth, x, y, t):
    """(triangle, barycentric) of the cloth point seen through pixel (x, y) at time t (the
    camera's pinhole ray and the mesh simulated at t, Möller–Trumbore)."""
    cam = scene.camera
    with cam.at_frame(float(t)):
        m = np.array(cam.matrix_world)
    fpx = cam.focal_length / cam.sensor_width * W
    d = m[:3, :3] @ np.array([(x - W / 2) / fpx, -(y - H / 2) / fpx, -1.0])
    verts = cloth.deformed_vertices(float(t))
    tri, bary, _ = ray_triangles(m[None, :3, 3], d[None], verts[cloth.faces])
    return int(tri[0]), bary[0]


def _seen_at(scene, cloth, tri, bary, f):
    """Pixel (x, y) of a material point in frame f under the rolling shutter: y = proj_y(P(t(y)),
    t(y)) by plain fixed-point iteration (a contraction at these speeds)."""
    xy = _cv2_project(scene.camera, cloth.surface_points([tri], [bary], f)[0], f)
    for _ in range(200):
        t = _row_time(f, xy[1])
        new = _cv2_project(scene.camera, cloth.surface_points([tri], [bary], t)[0], t)
        if np.abs(new - xy).max() < 1e-7:
            break
        xy = new
    return new


def test_cloth_rows_equal_global_renders_at_each_row_time():
    scene, _ = _cloth_scene()
    out = rows_equal_row_time_renders(scene, ("depth", "segmentation", "object_coordinates",
                                              "uv"))
    assert (out["segmentation"] == 5).sum() > 40


def test_cloth_flow_lands_on_the_material_point_at_its_row_time():
    scene, cloth = _cloth_scene()
    out = base.create("raycast", scene).render(frames=[2], return_layers=(
        "segmentation", "forward_flow"))
    seg, flow = out["segmentation"][0, ..., 0], out["forward_flow"][0]
    rows, cols = np.nonzero(seg == 5)
    worst, moved = 0.0, 0.0
    for r, c in zip(rows[::3], cols[::3], strict=True):
        tri, bary = _material_point(scene, cloth, c + 0.5, r + 0.5, _row_time(2, r + 0.5))
        assert tri >= 0
        end = _seen_at(scene, cloth, tri, bary, 3)
        got = np.array([c + 0.5 + flow[r, c, 1], r + 0.5 + flow[r, c, 0]])
        worst = max(worst, np.abs(got - end).max())
        # the global-shutter end (the same material point at frame 3's time): elsewhere
        glob = _cv2_project(scene.camera, cloth.surface_points([tri], [bary], 3)[0], 3)
        moved = max(moved, np.abs(glob - end).max())
    assert worst < 1e-3 and moved > 0.3


def test_cloth_track_pixels_are_material_points_at_their_row_time():
    scene, cloth = _cloth_scene()
    layers = base.create("raycast", scene).render(return_layers=("depth", "segmentation"))
    got = tr.scene_tracks(scene, layers, [cloth], np.random.RandomState(2), num_tracks=40,
                          stride=2, max_fraction=0.9)
    xy, q = got["target_points"].astype(float), got["query_points"].astype(float)
    checked, moved = 0, 0.0
    for n in np.flatnonzero(got["instance_id"] == 1):
        qt, qy, qx = q[n]
        tri, bary = _material_point(scene, cloth, qx, qy, _row_time(1 + qt, qy))
        for t, f in enumerate((1, 2, 3)):
            x, y = xy[n, t]
            if not (0 <= y < H and 0 <= x < W):
                continue
            time = _row_time(f, y)
            want = _cv2_project(scene.camera, cloth.surface_points([tri], [bary], time)[0], time)
            assert np.abs(want - (x, y)).max() < 1e-3, (n, f)
            glob = _cv2_project(scene.camera, cloth.surface_points([tri], [bary], f)[0], f)
            moved = max(moved, np.abs(glob - (x, y)).max())
            checked += 1
    assert checked > 30 and moved > 0.3


def test_keypoints_are_seen_at_their_row_time():
    scene, person = walking_scene(frames=3)
    scene.camera.rolling_shutter_duration = D
    frames = [1, 2, 3]
    # background layers: the positions under test do not depend on them, only the occlusion
    # flags do
    depth = np.full((3, H, W), 1e4, np.float32)
    seg = np.zeros((3, H, W), np.uint32)
    got = character_keypoints(scene.camera, frames, depth, seg, scene.assets, person)
    pick = [person.keypoint_names.index(n) for n in got["keypoint_names"]]
    checked, moved = 0, 0.0
    for t, f in enumerate(frames):
        for k, (x, y) in enumerate(got["keypoints_2d"][t].astype(float)):
            time = _row_time(f, y)
            point = person.keypoints(time)[pick[k]]
            assert np.abs(_cv2_project(scene.camera, point, time) - (x, y)).max() < 1e-3
            assert np.abs(got["keypoints_3d"][t, k] - point).max() < 1e-5
            glob = _cv2_project(scene.camera, person.keypoints(f)[pick[k]], f)
            moved = max(moved, np.abs(glob - (x, y)).max())
            checked += 1
    assert checked == 3 * 17 and moved > 0.3
