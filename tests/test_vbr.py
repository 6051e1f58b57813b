"""vbr: `kubric generate vbr` writes a scene directory and its LASR sequence; the LASR files agree
with the scene's layers and with geometry derived independently here (rays walked by the depth
layer, the instances' per-frame poses, the URDF / mesh vertices)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from kubric.io.layers import read_image_dict
from kubric.io.pfm_io import read_pfm

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SMALL = ("resolution=56", "num_frames=4", "samples=4", "denoise=false", "camera_distance=3,3.5")


def _kubric(*args):
    proc = subprocess.run([sys.executable, "-m", "kubric", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("vbr")
    sets = []
    for s in (*SMALL, "object_type=articulated", "articulated_model=r2d2", "camera=follow"):
        sets += ["--set", s]
    _kubric("generate", "vbr", "--out", str(root / "articulated"), "--scenes", "1",
            "--first-seed", "3", "--workers", "1", "--no-progress", *sets)
    sets = []
    for s in (*SMALL, "object_type=rigid", "shape=torus"):
        sets += ["--set", s]
    _kubric("worker", "vbr", "--seed", "5", "--out", str(root / "rigid"), *sets)
    sets = []
    for s in (*SMALL, "object_type=articulated", "articulated_model=r2d2", "camera=follow"):
        sets += ["--set", s]
    _kubric("worker", "vbr", "--seed", "3", "--out", str(root / "again"), *sets)
    return {"articulated": root / "articulated" / "scene_00000003",
            "rigid": root / "rigid" / "scene_00000005"}


def _load(scene_dir):
    meta = json.loads((scene_dir / "metadata.json").read_text())
    layers = read_image_dict(scene_dir, ["rgba", "depth", "segmentation", "forward_flow",
                                         "backward_flow"])
    seq = meta["metadata"]["lasr_sequence"]
    davis = scene_dir / "lasr" / "DAVIS"
    return meta, layers, seq, (lambda kind: davis / kind / "Full-Resolution" / seq)


def _rays(meta, frame, shape):
    """World origin and unit directions of every pixel-centre ray (Blender camera axes)."""
    h, w = shape
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    m = np.asarray(meta["camera"]["matrices_world"][frame])
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    d = np.stack([(cols + 0.5 - k[0, 2]) / k[0, 0], -(rows + 0.5 - k[1, 2]) / k[1, 1],
                  -np.ones((h, w))], -1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return m[:3, 3], d @ m[:3, :3].T


def _rot(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _to_pixels(meta, frame, world):
    """Pixel position (x, y), pixel centres at +0.5, and distance of world points."""
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    m = np.asarray(meta["camera"]["matrices_world"][frame])
    cam = (world - m[:3, 3]) @ m[:3, :3]
    z = -cam[..., 2]
    return np.stack([k[0, 0] * cam[..., 0] / z + k[0, 2], -k[1, 1] * cam[..., 1] / z + k[1, 2]],
                    -1), np.linalg.norm(cam, axis=-1)


def _reprojected_visibility(meta, layers, t, u):
    """Per object pixel of frame t: does its surface point, carried by its instance's pose from
    frame t to frame u, land in the image on a pixel whose depth is its distance?"""
    seg = layers["segmentation"][..., 0]
    depth = layers["depth"][..., 0]
    h, w = seg.shape[1:]
    origin, dirs = _rays(meta, t, (h, w))
    world = origin + dirs * depth[t][..., None]
    moved = np.zeros_like(world)
    for label in np.unique(seg[t][seg[t] > 0]):
        inst = meta["instances"][label - 1]
        r0, r1 = _rot(inst["quaternions"][t]), _rot(inst["quaternions"][u])
        p0, p1 = np.asarray(inst["positions"][t]), np.asarray(inst["positions"][u])
        sel = seg[t] == label
        moved[sel] = ((world[sel] - p0) @ r0) @ r1.T + p1
    xy, dist = _to_pixels(meta, u, moved)
    inside = (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
    col = np.clip(np.floor(xy[..., 0]).astype(int), 0, w - 1)
    row = np.clip(np.floor(xy[..., 1]).astype(int), 0, h - 1)
    visible = inside & (np.abs(depth[u][row, col] - dist) < 0.03 * dist)
    flow = np.stack([xy[..., 1] - (np.arange(h)[:, None] + 0.5),
                     xy[..., 0] - (np.arange(w)[None, :] + 0.5)], -1)
    return seg[t] > 0, visible, flow


def _label_edges(seg):
    """Pixels with a 4-neighbour of another label (the image border does not count)."""
    pad = np.pad(seg, 1, mode="edge")
    h, w = seg.shape
    return np.any([pad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] != seg
                   for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0))], axis=0)


@pytest.mark.blender
@pytest.mark.parametrize("kind", ["articulated", "rigid"])
def test_lasr_flow_is_the_scene_flow_and_occlusion_matches_depth_reprojection(scenes, kind):
    meta, layers, seq, folder = _load(scenes[kind])
    count = layers["rgba"].shape[0]
    assert meta["metadata"]["object_type"] == kind
    agree, total, occluded_seen = np.zeros(2), np.zeros(2), 0
    for name, flows, step in (("FlowFW", layers["forward_flow"], 1),
                              ("FlowBW", layers["backward_flow"], -1)):
        frames = range(count - 1) if step == 1 else range(1, count)
        assert sorted(p.name for p in folder(name).iterdir()) == sorted(
            [f"flo-{i:05d}.pfm" for i in frames] + [f"occ-{i:05d}.pfm" for i in frames])
        for t in frames:
            flo = read_pfm(folder(name) / f"flo-{t:05d}.pfm")
            occ = read_pfm(folder(name) / f"occ-{t:05d}.pfm")
            assert flo.shape == layers["rgba"].shape[1:3] + (3,) and occ.shape == flo.shape[:2]
            # LASR's (dx, dy) is our (drow, dcol) swapped: the layer's values, unchanged
            np.testing.assert_array_equal(flo[..., 0], flows[t][..., 1])
            np.testing.assert_array_equal(flo[..., 1], flows[t][..., 0])
            obj, visible, flow_3d = _reprojected_visibility(meta, layers, t, t + step)
            assert set(np.unique(occ)) <= {0.0, 1.0}
            np.testing.assert_array_equal(flo[..., 2], (obj & (occ == 0)).astype(np.float32))
            # the flow layer is the motion of the surface point (from poses, independently)
            err = np.linalg.norm(flow_3d[obj] - flows[t][obj], axis=-1)
            assert np.median(err) < 0.05 and np.mean(err < 0.5) > 0.95, (t, err.max())
            same = (occ == 1) == ~visible
            inner = obj & ~_label_edges(layers["segmentation"][t, ..., 0])
            agree += np.array([np.sum(same[obj]), np.sum(same[inner])])
            total += np.array([np.sum(obj), np.sum(inner)])
            occluded_seen += int(np.sum(occ[obj] == 1))
    assert total[1] > 500 and occluded_seen > 0
    # all pixels / pixels away from a boundary between two labels (where a point of one part
    # lands next to the part it touches, which the export conservatively calls occluded)
    ratio = agree / total
    assert ratio[0] > 0.94 and ratio[1] > 0.98, ratio


@pytest.mark.blender
def test_silhouettes_images_and_config(scenes):
    for scene_dir in scenes.values():
        meta, layers, seq, folder = _load(scene_dir)
        for i in range(layers["rgba"].shape[0]):
            mask = np.asarray(Image.open(folder("Annotations") / f"{i:05d}.png"))
            assert mask.dtype == np.uint8 and mask.ndim == 2
            # every instance is a part of the object: the silhouette is the segmentation > 0
            np.testing.assert_array_equal(mask, np.where(layers["segmentation"][i, ..., 0] > 0,
                                                         128, 0))
            jpg = np.asarray(Image.open(folder("JPEGImages") / f"{i:05d}.jpg"), float)
            assert np.mean(np.abs(jpg - layers["rgba"][i, ..., :3])) < 4.0
        config = (scene_dir / "lasr" / "configs" / f"{seq}.config").read_text()
        assert f"datapath = database/DAVIS/JPEGImages/Full-Resolution/{seq}/" in config
        assert "[meta]\nnumvid = 1" in config


def _rtk(path):
    rtk = np.loadtxt(path)
    assert rtk.shape == (4, 4)
    return rtk


def _project(rtk, points):
    cam = points @ rtk[:3, :3].T + rtk[:3, 3]
    return np.stack([rtk[3, 0] * cam[..., 0] / cam[..., 2] + rtk[3, 2],
                     rtk[3, 1] * cam[..., 1] / cam[..., 2] + rtk[3, 3]], -1)


@pytest.mark.blender
@pytest.mark.parametrize("kind", ["articulated", "rigid"])
def test_camera_files_reproduce_the_pixels_of_the_objects_surface(scenes, kind):
    """A pixel's surface point (its ray walked by the depth layer), expressed in the root
    object's frame, projects back onto that pixel's centre (integer coordinates) through
    Cameras/, and the world point through CamerasWorld/."""
    meta, layers, seq, folder = _load(scenes[kind])
    root = json.loads((scenes[kind] / "lasr" / "export.json").read_text())["root_instance"]
    inst = meta["instances"][root]
    assert "articulated_link" not in inst
    h, w = layers["rgba"].shape[1:3]
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    for i in range(layers["rgba"].shape[0]):
        sel = layers["segmentation"][i, ..., 0] > 0
        origin, dirs = _rays(meta, i, (h, w))
        world = (origin + dirs * layers["depth"][i][..., :1])[sel]
        local = (world - np.asarray(inst["positions"][i])) @ _rot(inst["quaternions"][i])
        want = np.stack([cols[sel], rows[sel]], -1)
        np.testing.assert_allclose(_project(_rtk(folder("Cameras") / f"{i:05d}.txt"), local),
                                   want, atol=2e-3)
        np.testing.assert_allclose(_project(_rtk(folder("CamerasWorld") / f"{i:05d}.txt"),
                                            world), want, atol=2e-3)


@pytest.mark.blender
def test_articulated_links_lie_inside_their_projected_urdf_boxes(scenes):
    """The r2d2 links' silhouettes lie inside the projection (through the exported base camera
    composed with the link's pose relative to the base) of their URDF meshes' boxes."""
    from kubric.assets.articulated import link_visuals
    from kubric.recipes.articulated_models import model_path

    meta, layers, seq, folder = _load(scenes["articulated"])
    meshes = link_visuals(model_path("r2d2"))
    root = json.loads((scenes["articulated"] / "lasr" / "export.json").read_text())["root_instance"]
    base = meta["instances"][root]
    box = np.asarray(base["bboxes_3d"][0])  # corners (x, y, z) in {min, max}^3, z fastest
    extent = meshes["base_link"].bounds[1, 2] - meshes["base_link"].bounds[0, 2]
    scale = np.linalg.norm(box[1] - box[0]) / extent
    checked = 0
    for i in range(layers["rgba"].shape[0]):
        rtk = _rtk(folder("Cameras") / f"{i:05d}.txt")
        rb, pb = _rot(base["quaternions"][i]), np.asarray(base["positions"][i])
        for k, inst in enumerate(meta["instances"]):
            rows, cols = np.nonzero(layers["segmentation"][i, ..., 0] == k + 1)
            if len(rows) < 3:
                continue
            mesh = meshes[inst.get("articulated_link", "base_link")]
            corners = np.array([[x, y, z] for x in mesh.bounds[:, 0] for y in mesh.bounds[:, 1]
                                for z in mesh.bounds[:, 2]]) * scale
            world = corners @ _rot(inst["quaternions"][i]).T + np.asarray(inst["positions"][i])
            xy = _project(rtk, (world - pb) @ rb)
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            assert cols.min() >= lo[0] - 1 and cols.max() <= hi[0] + 1, (i, k)
            assert rows.min() >= lo[1] - 1 and rows.max() <= hi[1] + 1, (i, k)
            checked += 1
    assert checked >= 12


@pytest.mark.blender
def test_same_seed_same_scene_and_same_lasr_files(scenes):
    a = scenes["articulated"]
    b = a.parent.parent / "again" / a.name
    for name in ("metadata.json", "events.json"):
        assert (a / name).read_text() == (b / name).read_text(), name
    exact = [p.relative_to(a) for p in (a / "lasr").rglob("*") if p.is_file()
             and p.suffix != ".jpg"]
    assert len(exact) > 20
    for rel in exact:  # flows, occlusion, silhouettes, cameras, config: byte for byte
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    rgb_a = read_image_dict(a, ["rgba"])["rgba"].astype(np.int32)
    rgb_b = read_image_dict(b, ["rgba"])["rgba"].astype(np.int32)
    assert np.abs(rgb_a - rgb_b).mean() < 1.0


@pytest.mark.blender
def test_every_written_field_is_documented(scenes):
    from kubric.docgen import undocumented_scene_fields

    for scene_dir in scenes.values():
        assert undocumented_scene_fields(scene_dir) == []


def test_bad_urdf_files_are_refused_before_anything_runs(tmp_path):
    from kubric.pipeline import OptionError, get_recipe

    vbr = get_recipe("vbr")
    (tmp_path / "novis.urdf").write_text('<robot name="x"><link name="a"/></robot>')
    (tmp_path / "broken.urdf").write_text("<robot")
    (tmp_path / "mesh.obj").write_text("v 0 0 0\n")
    for name, needle in (("novis.urdf", "no link has a <visual>"),
                         ("broken.urdf", "not readable XML"), ("mesh.obj", "not a .urdf file")):
        with pytest.raises(OptionError, match=needle) as err:
            vbr(urdf_file=tmp_path / name)
        assert "\n" not in str(err.value) and "urdf_file" in str(err.value)
    with pytest.raises(OptionError, match="step_rate"):
        vbr(frame_rate=7)
