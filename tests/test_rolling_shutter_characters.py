"""Rolling shutter with a skinned character: the raycast backend casts each row against the mesh
skinned at that row's time. On real output, against independent derivations:

* each row of a rolling render equals a global-shutter render of the scene at that row's time
  t_r = f + d·((r + 0.5)/H − 1/2) (one render per row);
* per row, each pixel's label, depth and object coordinates are those of its pinhole ray
  (written here) against the mesh the model skins at t_r (Möller–Trumbore in numpy): depth
  < 1e-4 relative, object coordinates the rest-pose material point over the rest bounds;
* each track on the character lies where the cv2 projection puts the query's material point
  at the time of the row the pixel lies on, < 1e-3 px;
* the global-shutter frames themselves: the raycast backend's character layers (smooth normals
  of the skinned mesh, rest-pose object coordinates, the material point's flow) equal Cycles'
  exact layers to float precision away from silhouettes (blender);
* ``pose_estimation`` with ``rolling_shutter`` runs through the worker on the raycast and the
  Blender backend and records the readout; each keypoint's pixel is the cv2 projection of its
  recorded 3D keypoint (the static camera's recorded extrinsics), < 1e-3 px.
"""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import kubric as kb
from kubric.annotations import tracks as tr
from kubric.annotations.surfaces import ray_triangles
from kubric.assets.procedural_character import tube_person, walk_clip
from kubric.renderer import base
from tests.test_rolling_shutter import D, H, W, _cv2_project, rows_equal_row_time_renders
from tests.test_rolling_shutter_deforming import _material_point, _row_time

pytest.importorskip("embreex")
FRAMES = [1, 2, 3]
LABEL = 7  # (not a 1-based position in scene.assets)
LAYERS = ("rgba", "depth", "segmentation", "normal", "object_coordinates", "uv")


def _scene(floor=True, pan=0.35):
    """A walking person, the camera panning (look-at point moving ``pan`` m/frame) and rising;
    a lit floor behind (``floor``)."""
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3, frame_rate=12)
    person = tube_person(position=(0.2, 0.3, 0.0), euler=(0, 0, 0.5), segmentation_id=LABEL)
    scene += person
    if floor:
        scene += kb.Cube(name="floor", position=(0, 0, -0.05), scale=(4, 4, 0.05), static=True,
                         background=True, segmentation_id=9)
    scene += kb.DirectionalLight(position=(1, -3, 4), look_at=(0, 0, 0), intensity=2.0)
    cam = kb.PerspectiveCamera(focal_length=50, rolling_shutter_duration=D)
    scene += cam
    for f in range(0, 5):
        cam.position = (1.0 - 0.1 * f, -3.4, 1.2 + 0.1 * f)
        cam.look_at((0.1 + pan * (f - 2), 0.0, 0.7 + 0.05 * f))
        cam.keyframe_insert("position", f)
        cam.keyframe_insert("quaternion", f)
    person.play(walk_clip())
    return scene, person


@pytest.fixture(scope="module")
def rolling():
    scene, person = _scene()
    layers = base.create("raycast", scene).render(return_layers=LAYERS)
    return scene, person, layers


def test_rows_equal_global_renders_at_each_row_time():
    scene, _ = _scene()
    out = rows_equal_row_time_renders(scene, LAYERS)
    assert (out["segmentation"] == LABEL).sum() > 60


def _pixel_rays(scene, rows, cols, t):
    """Pinhole rays (origin (3,), unit directions (n, 3)) through pixel centres at time t."""
    cam = scene.camera
    with cam.at_frame(float(t)):
        m = np.array(cam.matrix_world)
    fpx = cam.focal_length / cam.sensor_width * W
    local = np.stack([(cols + 0.5 - W / 2) / fpx, -(rows + 0.5 - H / 2) / fpx,
                      -np.ones(len(cols))], -1)
    dirs = local @ m[:3, :3].T
    return m[:3, 3], dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def test_each_row_shows_the_mesh_skinned_at_its_row_time(rolling):
    scene, person, layers = rolling
    i = FRAMES.index(2)
    seg, depth = layers["segmentation"][i, ..., 0], layers["depth"][i, ..., 0]
    coords = layers["object_coordinates"][i]
    lo, hi = person.rest_bounds
    checked = 0
    for r in range(H):
        t = _row_time(2, r + 0.5)
        cols = np.arange(W)
        origin, dirs = _pixel_rays(scene, np.full(W, r), cols, t)
        tris = person.deformed_vertices(t)[person.faces]
        tri, bary, dist = ray_triangles(np.broadcast_to(origin, dirs.shape), dirs, tris)
        on = seg[r] == LABEL
        assert (tri[on] >= 0).all(), r  # every character pixel's ray hits the skinned mesh
        np.testing.assert_allclose(depth[r, on], dist[on], rtol=1e-4)
        rest = np.einsum("nk,nkj->nj", bary[on], person.vertices[person.faces[tri[on]]])
        np.testing.assert_allclose(coords[r, on], (rest - lo) / (hi - lo), atol=1e-5)
        # elsewhere the mesh is missed or hidden behind what the pixel shows
        assert (dist[~on] >= depth[r, ~on] * (1 - 1e-4)).all(), r
        checked += on.sum()
    assert checked > 60
    # the effect is there: the global-shutter frame differs
    glob_scene, _ = _scene()
    glob_scene.camera.rolling_shutter_duration = 0.0
    glob = base.create("raycast", glob_scene).render(frames=[2], return_layers=("segmentation",))
    assert (glob["segmentation"][0, ..., 0] != seg).sum() > 5


def test_character_track_pixels_are_material_points_at_their_row_time(rolling):
    scene, person, layers = rolling
    t, r, c = np.nonzero(layers["segmentation"][..., 0] == LABEL)
    queries = np.stack([t, r + 0.5, c + 0.5], -1)[::7].astype(np.float32)  # on the person
    got = tr.scene_tracks(scene, layers, [person], None, queries=queries)
    xy, q = got["target_points"].astype(float), got["query_points"].astype(float)
    checked, moved = 0, 0.0
    for n in np.flatnonzero(got["instance_id"] == 1):
        qt, qy, qx = q[n]
        tri, bary = _material_point(scene, person, qx, qy, _row_time(1 + qt, qy))
        assert tri >= 0
        for t, f in enumerate(FRAMES):
            x, y = xy[n, t]
            if not (0 <= y < H and 0 <= x < W):
                continue
            time = _row_time(f, y)
            want = _cv2_project(scene.camera, person.surface_points([tri], [bary], time)[0],
                                time)
            assert np.abs(want - (x, y)).max() < 1e-3, (n, f)
            glob = _cv2_project(scene.camera, person.surface_points([tri], [bary], f)[0], f)
            moved = max(moved, np.abs(glob - (x, y)).max())
            checked += 1
    assert checked > 20 and moved > 0.5


@pytest.mark.parametrize("renderer", ["raycast", pytest.param("blender",
                                                            marks=pytest.mark.blender)])
def test_pose_estimation_with_rolling_shutter(tmp_path, renderer):
    import cv2

    from tests.test_rolling_shutter_movi import ROOT, _kubric
    options = ["resolution=24", "frame_end=2", "max_num_people=1", "min_num_clutter=0",
               "max_num_clutter=1", "character_source=procedural", "motion_source=procedural",
               "rolling_shutter=0.8", f"renderer={renderer}"]
    if renderer == "blender":
        options += ["samples=2", "denoise=false"]
    args = ["worker", "pose_estimation", "--seed", 2, "--out", tmp_path]
    for o in options:
        args += ["--set", o]
    if renderer == "raycast":
        _kubric(*args)  # bpy blocked
    else:
        proc = subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
    meta = json.loads((pathlib.Path(tmp_path) / "scene_00000002" / "metadata.json").read_text())
    assert meta["metadata"]["rolling_shutter"]["duration"] == 0.8
    (person,) = meta["instances"]
    cam = meta["camera"]
    assert np.ptp(np.asarray(cam["positions"]), axis=0).max() == 0  # static: any row time
    k = np.asarray(cam["intrinsics_pixels"])
    checked = 0
    for i, ext in enumerate(np.asarray(cam["extrinsics_opencv"])):
        rvec, _ = cv2.Rodrigues(ext[:3, :3])
        for xy, p3 in zip(np.asarray(person["keypoints_2d"][i], float),
                          np.asarray(person["keypoints_3d"][i], float), strict=True):
            got, _ = cv2.projectPoints(p3[None], rvec, ext[:3, 3], k, None)
            assert np.abs(got.reshape(2) - xy).max() < 1e-3, (i, xy)
            checked += 1
    assert checked == 2 * 17


@pytest.mark.blender
def test_raycast_character_layers_agree_with_cycles(tmp_path):
    """The global-shutter frames the rows are compared with: the raycast backend's skinned
    character (smooth normals of the skinned mesh, rest-pose object coordinates, flow of the
    material point) against Cycles' exact layers, to float precision away from silhouettes."""
    from tests.test_renderer_raycast import TOLERANCES, _interior, compare_with_cycles
    scene, _ = _scene()
    scene.camera.rolling_shutter_duration = 0.0
    seg = base.create("raycast", scene).render(return_layers=("segmentation",))
    seg = seg["segmentation"][..., 0]
    assert (_interior(seg) & (seg == LABEL)).sum() > 40  # the person is compared
    stats = compare_with_cycles(scene, tmp_path)
    assert stats["label_mismatches"] == 0
    for layer, tol in TOLERANCES.items():
        assert stats[layer][0] <= tol, (layer, stats[layer])
