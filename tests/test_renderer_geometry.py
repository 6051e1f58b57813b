"""Blender renderer: annotation layers against geometry computed by the tests themselves."""

import numpy as np
import pytest

import kubric as kb
from kubric.core import camera_geometry as geo

pytestmark = pytest.mark.blender

W, H = 48, 32


def _blender(scene, **kw):
    from kubric.renderer.blender import Blender
    kw.setdefault("samples_per_pixel", 1)
    kw.setdefault("use_denoising", False)
    return Blender(scene, **kw)


def _pixel_centres(w, h):
    c, r = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    return np.stack([c, r], -1)


def test_depth_inside_sphere_is_radius():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0.3, -0.2, 0.1), look_at=(1, 2, 0.5))
    scene += kb.Sphere(scale=10.0)
    out = _blender(scene).render(return_layers=("depth", "z", "segmentation"))
    depth = out["depth"][0, ..., 0]
    # the camera is off-centre: the distance along each pixel ray to the sphere of radius 10
    o, d = geo.pixel_rays(scene.camera, _pixel_centres(W, H))
    b = np.sum(o * d, -1)
    expected = -b + np.sqrt(b**2 - (np.sum(o * o, -1) - 100.0))
    assert np.abs(depth - expected).max() < 0.01
    assert np.all(out["segmentation"] == 2)
    np.testing.assert_allclose(out["z"][0], geo.depth_to_z(scene.camera, out["depth"][0]),
                               rtol=1e-5)


def test_depth_centred_camera_in_sphere_is_ten():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0, 0, 0), look_at=(1, 0.3, 0.2))
    scene += kb.Sphere(scale=10.0)
    depth = _blender(scene).render(return_layers=("depth",))["depth"]
    assert depth.shape == (1, H, W, 1) and depth.dtype == np.float32
    assert np.abs(depth - 10.0).max() < 0.01


@pytest.mark.parametrize("ortho,dof", [(False, False), (True, False), (False, True)])
def test_plane_depth_and_z(ortho, dof):
    """Depth of field (RGB only) must not disturb the pinhole annotation rays."""
    d = 5.0
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=1)
    if ortho:
        cam = kb.OrthographicCamera(position=(0, 0, d), orthographic_scale=3.0, shift_x=0.1,
                                    shift_y=-0.05)
    else:
        cam = kb.PerspectiveCamera(position=(0, 0, d), focal_length=20, shift_x=0.1,
                                   shift_y=-0.05, use_dof=dof, focus_distance=1.0,
                                   aperture_fstop=0.1)
    scene += cam
    plane = kb.Cube(position=(0, 0, -1.0), scale=(50, 50, 1.0))  # top face at z = 0
    scene += plane
    out = _blender(scene).render(return_layers=("depth", "z", "segmentation", "normal"))
    z, depth = out["z"][0, ..., 0], out["depth"][0, ..., 0]
    np.testing.assert_allclose(z, d, atol=1e-4)
    if ortho:
        np.testing.assert_allclose(depth, d, atol=1e-4)
    else:
        _, dirs = geo.pixel_rays(cam, _pixel_centres(W, H))
        cos = -dirs[..., 2]  # camera looks down −z
        np.testing.assert_allclose(depth, d / cos, rtol=1e-5)
        assert depth.max() > d * 1.05  # the test really spans oblique rays
    assert np.all(out["segmentation"][0, ..., 0] == 2)
    np.testing.assert_allclose(out["normal"][0], np.broadcast_to([0, 0, 1], (H, W, 3)),
                               atol=1e-5)


def _moving_cube_scene(camera_motion=False):
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=3)
    cam = kb.PerspectiveCamera(position=(1.0, -6.0, 5.0), look_at=(0, 0, 0), focal_length=30)
    scene += cam
    cube = kb.Cube(position=(0, 0, 0.5), scale=0.7, euler=(0.1, 0.2, 0.5))
    scene += cube
    floor = kb.Cube(position=(0, 0, -1.0), scale=(20, 20, 0.5), static=True)
    scene += floor
    velocity = np.array([0.3, 0.2, 0.1]) if not camera_motion else np.zeros(3)
    for f in scene.frames:
        cube.position = np.array([0, 0, 0.5]) + velocity * (f - 1)
        cube.keyframe_insert("position", f)
        if camera_motion:
            cam.position = (1.0 + 0.2 * (f - 1), -6.0 + 0.1 * (f - 1), 5.0)
            cam.look_at((0.1 * (f - 1), 0, 0))
            cam.keyframe_insert("position", f)
            cam.keyframe_insert("quaternion", f)
    return scene, cam, cube, floor


def _expected_flow(scene, cam, depth, seg, t, dt, moving):
    """Flow of the surface point seen at each pixel from frame t to t+dt, from the model."""
    frames = list(scene.frames)
    f0, f1 = frames[t], frames[t] + dt
    f1c = min(max(f1, frames[0]), frames[-1])
    pix = _pixel_centres(W, H)
    p = geo.unproject_pixels(cam, pix, depth, frame=f0)
    p_new = p.copy()
    for label, asset in moving.items():
        m = seg == label
        with asset.at_frame(f0):
            r0, t0 = asset.rotation_matrix, np.asarray(asset.position, float)
        with asset.at_frame(f1c):
            r1, t1 = asset.rotation_matrix, np.asarray(asset.position, float)
        local = (p[m] - t0) @ r0
        p_new[m] = local @ r1.T + t1
    xy, _ = geo.project_to_pixels(cam, p_new, frame=f1c)
    return np.stack([xy[..., 1] - pix[..., 1], xy[..., 0] - pix[..., 0]], -1)


def _interior(seg, label):
    """Pixels of ``label`` whose 4-neighbours carry the same label (away from silhouettes)."""
    m = seg == label
    inner = m.copy()
    inner[1:] &= m[:-1]
    inner[:-1] &= m[1:]
    inner[:, 1:] &= m[:, :-1]
    inner[:, :-1] &= m[:, 1:]
    return inner


@pytest.mark.parametrize("camera_motion,blur", [(False, False), (True, False), (False, True)])
def test_flow_matches_model_motion(camera_motion, blur):
    """Motion blur (RGB only) must not disturb the exact flow."""
    scene, cam, cube, floor = _moving_cube_scene(camera_motion)
    out = _blender(scene, motion_blur=blur).render(return_layers=("depth", "segmentation", "forward_flow",
                                                "backward_flow"))
    cube_label, floor_label = 2, 3
    checked = 0
    for t in range(3):
        seg, depth = out["segmentation"][t, ..., 0], out["depth"][t, ..., 0]
        for name, dt in (("forward_flow", 1), ("backward_flow", -1)):
            flow = out[name][t]
            exp = _expected_flow(scene, cam, depth, seg, t, dt, {cube_label: cube})
            for label in (cube_label, floor_label):
                m = _interior(seg, label)
                if not m.any():
                    continue
                err = np.linalg.norm(flow[m] - exp[m], axis=-1)
                assert np.median(err) < 0.05, (name, t, label, np.median(err))
                assert err.max() < 0.5, (name, t, label, err.max())
                checked += m.sum()
            if not camera_motion:
                assert np.abs(flow[seg == floor_label]).max() < 1e-4  # static background
                # the cube really moves (unless held beyond the keyed range)
                if 0 <= t + dt < 3:
                    assert np.abs(flow[_interior(seg, cube_label)]).max() > 0.5
            else:
                if 0 <= t + dt < 3:
                    assert np.abs(flow[_interior(seg, floor_label)]).max() > 0.5
    assert checked > 1000


def _ray_cast(boxes, cam, pix):
    """Independent slab-method ray cast against the model's boxes (no renderer involved).

    Returns, per pixel centre: label of the first box hit (0 = none), world hit point, world face
    normal.
    """
    o, d = geo.pixel_rays(cam, pix)
    best = np.full(o.shape[:-1], np.inf)
    label = np.zeros(o.shape[:-1], int)
    point = np.zeros(o.shape)
    normal = np.zeros(o.shape)
    for lab, asset in boxes.items():
        rot, scale = asset.rotation_matrix, np.asarray(asset.scale, float)
        lo, hi = np.asarray(asset.bounds, float)
        ol = ((o - asset.position) @ rot) / scale
        dl = (d @ rot) / scale
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (lo - ol) / dl, (hi - ol) / dl
        tnear = np.minimum(t0, t1)
        tfar = np.maximum(t0, t1)
        entry = tnear.max(-1)
        axis = tnear.argmax(-1)
        hit = (entry <= tfar.min(-1)) & (entry > 0) & (entry < best)
        best[hit] = entry[hit]
        label[hit] = lab
        point[hit] = o[hit] + entry[hit, None] * d[hit]
        sign = -np.sign(np.take_along_axis(dl, axis[..., None], -1))[..., 0]
        n_local = np.zeros(o.shape)
        np.put_along_axis(n_local, axis[..., None], sign[..., None], -1)
        normal[hit] = n_local[hit] @ rot.T
    return label, point, normal


def test_segmentation_normals_object_coordinates_by_ray_cast():
    scene = kb.Scene(resolution=(W, H), frame_start=1, frame_end=1)
    cam = kb.PerspectiveCamera(position=(3.0, -5.0, 4.0), look_at=(0, 0, 0.3), focal_length=35)
    scene += cam
    a = kb.Cube(position=(-0.6, 0.2, 0.4), scale=(0.5, 0.7, 0.4), euler=(0, 0, 0.6))
    b = kb.Cube(position=(0.9, -0.3, 0.3), scale=0.45, euler=(0.3, 0.2, 1.0),
                segmentation_id=7)
    floor = kb.Cube(position=(0, 0, -0.5), scale=(3, 3, 0.5))
    scene += [a, b, floor]
    out = _blender(scene).render(return_layers=("segmentation", "normal",
                                                "object_coordinates", "uv"))
    seg = out["segmentation"][0, ..., 0]
    meshes = {2: a, 7: b, 4: floor}
    pix = _pixel_centres(W, H)
    label, point, normal = _ray_cast(meshes, cam, pix)
    # unambiguous pixels: rays shifted by ±0.02 px hit the same object
    stable = np.ones((H, W), bool)
    for off in ((0.02, 0), (-0.02, 0), (0, 0.02), (0, -0.02)):
        stable &= _ray_cast(meshes, cam, pix + np.array(off))[0] == label
    assert stable.mean() > 0.9
    np.testing.assert_array_equal(seg[stable], label[stable])
    assert {0, 2, 7, 4} <= set(np.unique(seg))
    # normals: the hit face's normal, on every unambiguous object pixel
    hit = stable & (label > 0)
    np.testing.assert_allclose(out["normal"][0][hit], normal[hit], atol=1e-4)
    assert np.all(out["normal"][0][label == 0] == 0)
    # object coordinates: the hit point in the object's frame over its unscaled bounds
    oc = out["object_coordinates"][0]
    for lab, asset in ((2, a), (7, b), (4, floor)):
        m = hit & (label == lab)
        local = (point[m] - asset.position) @ asset.rotation_matrix / asset.scale
        np.testing.assert_allclose(oc[m], (local + 1.0) / 2.0, atol=2e-3)
        # on a cube face one coordinate is exactly 0 or 1
        extreme = np.min(np.minimum(np.abs(oc[m]), np.abs(oc[m] - 1)), axis=-1)
        assert extreme.max() < 1e-3
    uv = out["uv"][0]
    assert np.all(uv[label == 0] == 0) and np.all(uv[..., 2] == 0)
    assert uv[hit][:, :2].min() >= 0 and uv[hit][:, :2].max() <= 1 and uv[hit].std() > 0.05


def test_annotations_identical_at_1_and_64_spp():
    def render(spp):
        scene = kb.Scene(resolution=(24, 20), frame_start=1, frame_end=2)
        scene += kb.PerspectiveCamera(position=(2, -4, 3), look_at=(0, 0, 0))
        s = kb.Sphere(scale=0.8, material=kb.PrincipledBSDFMaterial(color=(0.2, 0.5, 0.9)))
        scene += [s, kb.Cube(position=(0, 0, -1.3), scale=(3, 3, 0.5)),
                  kb.PointLight(position=(2, 0, 3), intensity=200)]
        for f in (1, 2):
            s.position = (0.2 * f, 0, 0)
            s.keyframe_insert("position", f)
        return _blender(scene, samples_per_pixel=spp).render()

    low, high = render(1), render(64)
    np.testing.assert_array_equal(low["segmentation"], high["segmentation"])
    for key in low:
        if key in ("rgba", "segmentation"):
            continue
        # identical up to float32 rounding (Cycles' multi-threaded float evaluation: ≤ 1 ulp)
        np.testing.assert_allclose(low[key], high[key], rtol=1e-6, atol=1e-6, err_msg=key)
    # the RGB really differs (more samples, less noise)
    assert np.abs(low["rgba"].astype(int) - high["rgba"].astype(int)).max() > 0


def test_smooth_sphere_normals_and_object_coordinates():
    scene = kb.Scene(resolution=(40, 30), frame_start=1, frame_end=1)
    cam = kb.PerspectiveCamera(position=(0.5, -4.0, 1.0), look_at=(0, 0, 0), focal_length=40)
    scene += cam
    ball = kb.Sphere(position=(0.1, 0.0, -0.1), scale=0.9, euler=(0.4, 0.0, 0.7))
    scene += ball
    out = _blender(scene).render(return_layers=("depth", "segmentation", "normal",
                                                "object_coordinates"))
    seg = out["segmentation"][0, ..., 0]
    o, d = geo.pixel_rays(cam, _pixel_centres(40, 30))
    c, r = np.asarray(ball.position, float), 0.9
    oc_ = o - c
    b = np.sum(oc_ * d, -1)
    disc = b**2 - (np.sum(oc_ * oc_, -1) - r * r)
    t = -b - np.sqrt(np.maximum(disc, 0))
    m = _interior(seg, 2) & (disc > 0.02)
    assert m.sum() > 200
    p = o + t[..., None] * d
    n = (p - c) / r
    np.testing.assert_allclose(out["depth"][0, ..., 0][m], t[m], atol=3e-3)
    # interpolated vertex normals of the 128 × 64 UV sphere: within ~0.3° of the true normal
    assert np.degrees(np.arccos(np.clip(np.sum(out["normal"][0][m] * n[m], -1), -1, 1))).max() \
        < 0.5
    local = (p[m] - c) @ ball.rotation_matrix / r
    np.testing.assert_allclose(out["object_coordinates"][0][m], (local + 1) / 2, atol=2e-3)
