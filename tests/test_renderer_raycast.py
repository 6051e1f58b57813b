"""The raycast backend (kubric.renderer.raycast) and the renderer protocol (kubric.renderer.base).

* Without Blender: layers of a box scene against geometry derived here (ray–slab intersection,
  orthographic projection); a ``renderer=raycast`` MOVi-A scene written with bpy blocked.
* With Blender (the oracle): Cycles' exact layers of real MOVi-A (static camera, KuBasic OBJ
  shapes), MOVi-E (moving camera, GLB objects) and MOVi-C (HDRI dome, articulated URDF links)
  scenes against the raycast backend's, pixel by pixel.
"""

import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest
from scipy.ndimage import maximum_filter, minimum_filter

import kubric as kb
from kubric import docgen, file_io
from kubric.core import camera_geometry as geo
from kubric.pipeline import OptionError, get_recipe
from kubric.renderer import base

ROOT = pathlib.Path(__file__).resolve().parents[1]
NO_BPY = pathlib.Path(__file__).resolve().parent / "no_bpy"
EXACT = ("depth", "z", "segmentation", "forward_flow", "backward_flow", "normal",
         "object_coordinates", "uv")


# ---------------------------------------------------------------------------------- protocol
def test_create_unknown_backend_names_the_allowed_ones():
    with pytest.raises(ValueError, match=r"unknown renderer 'povray'; allowed: \['blender', "
                                         r"'raycast'\]"):
        base.create("povray", kb.Scene())


def test_raycast_is_a_renderer_and_checks_its_requests():
    scene = kb.Scene(resolution=(8, 6), frame_start=1, frame_end=2)
    scene += kb.PerspectiveCamera(position=(0, -5, 0), look_at=(0, 0, 0))
    r = base.create("raycast", scene)
    assert isinstance(r, base.Renderer) and set(r.layers) == set(base.ALL_LAYERS)
    assert r.settings()["engine"] == "RAYCAST"
    with pytest.raises(ValueError, match=r"unknown layers \['colour'\]"):
        r.render(return_layers=("depth", "colour"))
    with pytest.raises(ValueError, match="frames is empty"):
        r.render(frames=[])
    with pytest.raises(base.CapabilityError, match="cannot render motion blur"):
        base.create("raycast", scene, motion_blur=0.5)
    empty = r.render(return_layers=("depth", "segmentation", "forward_flow"))
    assert np.all(empty["depth"] == geo.BACKGROUND_DEPTH) and not empty["segmentation"].any()
    assert empty["forward_flow"].shape == (2, 6, 8, 2) and not empty["forward_flow"].any()


@pytest.mark.blender
def test_blender_implements_the_protocol_and_records_given_options(tmp_path):
    scene = kb.Scene(resolution=(8, 6))
    r = base.create("blender", scene, tmp_path, samples_per_pixel=3, max_bounces=2,
                    motion_blur=0.0)
    assert isinstance(r, base.Renderer) and r.layers == base.ALL_LAYERS
    assert r.settings() == {"engine": "CYCLES", "view_transform": "Standard",
                            "samples_per_pixel": 3, "denoising": True, "denoising_quality": "HIGH",
                            "denoising_prefilter": "ACCURATE", "max_bounces": 2,
                            "motion_blur": 0.0}
    with pytest.raises(ValueError, match=r"Blender.render: unknown layers \['colour'\]"):
        r.render(return_layers=("colour",))


def test_import_needs_no_bpy():
    code = ("import sys, kubric.renderer as r, kubric.renderer.raycast; "
            "assert 'bpy' not in sys.modules; print(sorted(r.BACKENDS))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "['blender', 'raycast']"


# ---------------------------------------------------------------------------------- geometry
def _box_scene(ortho):
    """A box (half sizes 0.5, 0.4, 0.3 around (0.2, 0.1, 0.3)) moving +x by 0.1 m per frame
    on nothing, looked at from +z (straight down) by a camera keyed at frames 0..3."""
    scene = kb.Scene(resolution=(40, 30), frame_start=1, frame_end=2)
    if ortho:
        scene += kb.OrthographicCamera(position=(0, 0, 6), orthographic_scale=3.0)
    else:
        scene += kb.PerspectiveCamera(position=(0.1, -0.2, 6), look_at=(0, 0, 0))
    box = kb.Cube(scale=(0.5, 0.4, 0.3), segmentation_id=5)
    scene += box
    for f in range(4):
        box.position = (0.2 + 0.1 * f, 0.1, 0.3)
        box.keyframe_insert("position", f)
    return scene, box


@pytest.mark.parametrize("ortho", [True, False])
def test_box_layers_against_slab_intersection(ortho):
    scene, box = _box_scene(ortho)
    out = base.create("raycast", scene).render(return_layers=EXACT)
    w, h = scene.resolution
    cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    o, d = geo.pixel_rays(scene.camera, np.stack([cols, rows], -1))
    for t, frame in enumerate((1, 2)):
        centre = np.array([0.2 + 0.1 * frame, 0.1, 0.3])
        half = np.array([0.5, 0.4, 0.3])
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (centre - half - o) / d, (centre + half - o) / d
        enter = np.nanmax(np.minimum(t1, t2), -1)
        leave = np.nanmin(np.maximum(t1, t2), -1)
        hit = enter < leave
        seg = out["segmentation"][t, ..., 0]
        assert np.array_equal(seg > 0, hit) and set(np.unique(seg)) == {0, 5}
        depth = out["depth"][t, ..., 0]
        np.testing.assert_allclose(depth[hit], enter[hit], rtol=1e-6)
        assert np.all(depth[~hit] == geo.BACKGROUND_DEPTH)
        p = o[hit] + d[hit] * enter[hit, None]
        np.testing.assert_allclose(out["object_coordinates"][t][hit],
                                   np.clip((p - centre) / half / 2 + 0.5, 0, 1), atol=1e-5)
        normal = out["normal"][t][hit]
        seen_top = np.isclose(p[:, 2], 0.6, atol=1e-6)
        assert np.allclose(normal[seen_top], (0, 0, 1), atol=1e-6) and seen_top.sum() > 50
        # the box moves +0.1 m in x per frame: its points land where the camera of t ± 1 sees
        # them (closed-form: project p + (±0.1, 0, 0))
        for name, step in (("forward_flow", 1), ("backward_flow", -1)):
            xy, _ = geo.project_to_pixels(scene.camera, p + [0.1 * step, 0, 0])
            expected = np.stack([xy[:, 1] - rows[hit], xy[:, 0] - cols[hit]], -1)
            np.testing.assert_allclose(out[name][t][hit], expected, atol=1e-4)
            if ortho:  # 0.1 m = 0.1 / 3 · 40 px to the right, nothing down
                np.testing.assert_allclose(out[name][t][hit] - [0, step * 4 / 3], 0, atol=1e-4)


def test_sphere_primitive_is_blenders_uv_sphere():
    """Radius 1 within the tessellation (a facet's centre is cos²(π/128) from the centre: half a
    step of 2π/128 in azimuth and of π/64 in polar angle); smooth normals close to radial."""
    scene = kb.Scene(resolution=(32, 32), frame_start=1, frame_end=1)
    scene += kb.PerspectiveCamera(position=(0, -4, 0), look_at=(0, 0, 0))
    scene += kb.Sphere(scale=1.0)
    out = base.create("raycast", scene).render(return_layers=("depth", "normal", "uv"))
    cols, rows = np.meshgrid(np.arange(32) + 0.5, np.arange(32) + 0.5)
    o, d = geo.pixel_rays(scene.camera, np.stack([cols, rows], -1))
    hit = out["depth"][0, ..., 0] < geo.BACKGROUND_DEPTH
    p = o[hit] + d[hit] * out["depth"][0][hit]
    r = np.linalg.norm(p, axis=-1)
    assert np.all(r <= 1 + 1e-6) and np.all(r >= np.cos(np.pi / 128) ** 2 - 1e-6)
    assert np.all(np.einsum("ij,ij->i", out["normal"][0][hit], p / r[:, None]) > 0.9995)
    # Blender's UVs: u = 0.5 + azimuth / 2π, v = 1 − polar angle / π
    u = 0.5 + np.arctan2(p[:, 1], p[:, 0]) / (2 * np.pi)
    v = 1 - np.arccos(np.clip(p[:, 2] / r, -1, 1)) / np.pi
    np.testing.assert_allclose(out["uv"][0][hit][:, 1], v, atol=0.01)
    np.testing.assert_allclose(out["uv"][0][hit][:, 0], u, atol=0.01)


# ---------------------------------------------------------------------------------- recipes
def test_raycast_recipe_options_are_checked():
    movi_a = get_recipe("movi_a")
    with pytest.raises(OptionError, match=r"renderer=raycast cannot take the RGB quality "
                       r"settings \(samples, denoising\) \(samples=4\)"):
        movi_a.from_assignments(["renderer=raycast", "samples=4"])
    with pytest.raises(OptionError, match="renderer"):
        movi_a.from_assignments(["renderer=povray"])
    with pytest.raises(OptionError, match="max_motion_blur=2.0"):
        get_recipe("movi_f").from_assignments(["renderer=raycast"])


def test_movi_a_scene_with_raycast_needs_no_bpy_and_packs(tmp_path):
    """A complete scene (written through write_scene, so checked against MOVi-A's schema) with
    bpy blocked in the worker, and packed with ``kubric pack --verify``."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(NO_BPY), str(ROOT)]))
    cmd = [sys.executable, "-m", "kubric", "worker", "movi_a", "--seed", "5", "--out",
           str(tmp_path), "--set", "resolution=48", "--set", "frame_end=3", "--set",
           "renderer=raycast", "--set", "max_num_objects=4"]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    scene_dir = tmp_path / "scene_00000005"
    assert (scene_dir / "_SUCCESS").is_file()
    meta = json.loads((scene_dir / "metadata.json").read_text())
    assert meta["metadata"]["renderer"]["engine"] == "RAYCAST"
    assert meta["flags"]["renderer"] == "raycast"
    layers = file_io.read_image_dict(scene_dir)
    assert layers["rgba"].shape == (3, 48, 48, 4)
    seg = layers["segmentation"][..., 0]
    # every instance is seen, the lamps light them (not black), the dome is lit too
    assert set(np.unique(seg)) - {0} == set(range(1, len(meta["instances"]) + 1))
    assert layers["rgba"][..., :3][seg > 0].mean() > 20
    assert docgen.undocumented_scene_fields(scene_dir) == []
    pack = subprocess.run([sys.executable, "-m", "kubric", "pack", str(tmp_path), "--out",
                           str(tmp_path / "dataset"), "--splits", "train=1", "--verify",
                           "--no-progress"], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert pack.returncode == 0, pack.stdout[-2000:] + pack.stderr[-2000:]
    assert "verified: every example equals its scene directory (1 examples)" in pack.stdout


# ---------------------------------------------------------------------------------- the oracle
def _interior(seg):
    """True where the 3×3 neighbourhood of a pixel carries one label."""
    return maximum_filter(seg, size=(1, 3, 3)) == minimum_filter(seg, size=(1, 3, 3))


def _simulated_scene(name, options, seed, scratch):
    """The scene model of recipe ``name`` just before it renders (steps 1–5 of movi_base)."""
    rec = get_recipe(name).from_assignments(options)
    rng = np.random.RandomState(seed)
    sources = rec.open_sources()
    scene = rec.make_scene()
    sim = kb.simulator.PyBullet(scene, scratch)
    rec.populate(scene, sim, rng, sources)
    sim.run(frame_start=0, frame_end=scene.frame_end + 1)
    sim.close()
    return scene


def compare_with_cycles(scene, scratch):
    """Render the exact layers with both backends (timed in the same run); return the
    per-layer (max, median) absolute differences over pixels away from silhouettes, the count
    of label mismatches there, and the timings."""
    t0 = time.perf_counter()
    ray = base.create("raycast", scene).render(return_layers=EXACT)
    t1 = time.perf_counter()
    cycles_renderer = base.create("blender", scene, scratch, samples_per_pixel=1,
                                  use_denoising=False)
    t2 = time.perf_counter()
    cycles = cycles_renderer.render(return_layers=EXACT)
    t3 = time.perf_counter()
    seg_r, seg_c = ray["segmentation"][..., 0], cycles["segmentation"][..., 0]
    inside = _interior(seg_r) & _interior(seg_c)
    stats = {"label_mismatches": int(((seg_r != seg_c) & inside).sum()),
             "interior_pixels": int(inside.sum()), "raycast_s": t1 - t0, "cycles_s": t3 - t2}
    same = inside & (seg_r == seg_c)
    for name in EXACT:
        if name == "segmentation":
            continue
        diff = np.abs(ray[name].astype(np.float64) - cycles[name])
        if name == "uv":  # wrapped into [0, 1): 0.9999 and 0.0001 are neighbours
            diff = np.minimum(diff, 1 - diff)
        if name in ("depth", "z"):
            diff = diff / cycles[name]  # relative
        diff = diff.max(-1)[same]
        stats[name] = (float(diff.max()), float(np.median(diff)))
    return stats


#: measured on MOVi-A / MOVi-E (64², 3 frames): depth, z relative ≤ 1.1e-5 (Cycles' one sample
#: lands within 0.005 px of the pixel centre: on grazing floors that moves the depth), flow
#: ≤ 8.4e-5 px, normals ≤ 1.1e-5, object coordinates ≤ 1.2e-5, uv ≤ 5e-6
TOLERANCES = {"depth": 5e-5, "z": 5e-5, "forward_flow": 5e-4, "backward_flow": 5e-4,
              "normal": 1e-4, "object_coordinates": 1e-4, "uv": 1e-4}


@pytest.mark.blender
@pytest.mark.parametrize("name,options", [
    ("movi_a", ["resolution=64", "frame_end=3"]),
    ("movi_e", ["resolution=64", "frame_end=3", "min_num_objects=4", "max_num_objects=5",
                "settle_frames=20", "collection_limit=8"]),
    ("movi_c", ["resolution=64", "frame_end=3", "collection_limit=8", "articulated_objects=2",
                "min_num_objects=3", "max_num_objects=3"]),
])
def test_cycles_exact_layers_agree_with_raycast(name, options):
    """Cycles' exact layers of a real MOVi scene checked against the raycast backend: labels
    identical away from silhouettes, depth and flow to float precision."""
    with tempfile.TemporaryDirectory() as scratch:
        scene = _simulated_scene(name, options, 3, scratch)
        if name == "movi_e":  # the camera moves, so flow covers camera motion
            assert len(scene.camera.keyframes["position"]) >= 3
        stats = compare_with_cycles(scene, scratch)
    print(name, json.dumps(stats))
    assert stats["interior_pixels"] > 0.6 * 3 * 64 * 64
    assert stats["label_mismatches"] == 0
    for layer, tol in TOLERANCES.items():
        assert stats[layer][0] <= tol, (layer, stats[layer])
