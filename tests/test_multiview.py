"""The multi-view recipes end to end at tiny settings (must-show of the multi-view issue).

Each recipe runs once as a `kubric worker` process. Every geometric check reads only the written
files and re-derives the geometry itself (rays from ``transforms_*.json`` as a NeRF loader builds
them, object poses from ``metadata.json``), independent of kubric's camera code.
"""

import concurrent.futures
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric import file_io

pytestmark = pytest.mark.blender

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ["resolution=48x36", "samples=2", "denoise=false"]
RUNS = {
    "klevr": TINY + ["num_views=10", "min_num_objects=5", "max_num_objects=6"],
    "klevr:again": TINY + ["num_views=10", "min_num_objects=5", "max_num_objects=6"],
    "toybox": TINY + ["num_views=4", "split_ratio=2,1,1", "num_categories=2"],
    "texture_nerf": TINY + ["num_views=4", "split_ratio=2,1,1", "num_objects=12",
                            "texture_size=128", "band_range=-1,1.8"],
    "robust_nerf": TINY + ["num_views=5", "split_ratio=3,1,1", "num_impostors=2",
                           "max_num_objects=5"],
    "multiview_matting": TINY + ["num_views=4", "split_ratio=2,1,1", "difficulty=hard",
                                 "min_num_clutter=3", "max_num_clutter=3"],
    "nvs": TINY + ["num_views=4", "split_ratio=2,1,1"],
    "robust_nerf:jitter": TINY + ["num_views=5", "split_ratio=3,1,1", "impostor_motion=jitter",
                                  "jitter=0.4"],
}
HDRIS = {"city", "courtyard", "forest", "interior", "night", "sunrise", "sunset"}  # no studio
TOY_CATEGORIES = {"cube": "boxy", "sponge": "boxy", "sphere": "round", "cylinder": "round",
                  "torus": "round", "teapot": "kitchen"}


def run_worker(recipe, out, seed, options, timeout=300):
    cmd = [sys.executable, "-m", "kubric", "worker", recipe, "--seed", str(seed), "--out",
           str(out)]
    for o in options:
        cmd += ["--set", o]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def kubasic_with_categories(out, categories):
    from kubric import asset_tools
    from kubric.recipes.klevr import with_categories
    return with_categories(asset_tools.ensure_kubasic(), categories, out)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("multiview")
    from kubric.pipeline import get_recipe
    get_recipe("klevr").from_assignments(RUNS["klevr"]).prepare()  # build assets once
    toys = kubasic_with_categories(root / "toys", TOY_CATEGORIES)
    runs = dict(RUNS, toybox=RUNS["toybox"] + [f"objects={toys}"])
    get_recipe("toybox").from_assignments(runs["toybox"]).prepare()  # build the HDRIs once

    def run(item):
        key, options = item
        return key, run_worker(key.split(":")[0], root / key.replace(":", "_"), 1, options)

    out = {}
    with concurrent.futures.ThreadPoolExecutor(2) as pool:
        for key, proc in pool.map(run, runs.items()):
            assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
            out[key] = root / key.replace(":", "_") / "scene_00000001"
    return out


def read_labels(scene, name):
    """(T, H, W) labels of the ``{name}_{i:05d}.png`` files."""
    frames = [np.asarray(file_io.read_palette_png(p)) for p in sorted(scene.glob(f"{name}_*.png"))]
    return np.stack([f.reshape(f.shape[:2]) for f in frames])


# ---------------------------------------------------------------------- independent geometry
def quat_matrix(q):
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def load_transforms(scene):
    """{view: (transforms file dict, frame entry)} over the three split files."""
    views = {}
    for split in ("train", "val", "test"):
        data = json.loads((scene / f"transforms_{split}.json").read_text())
        for entry in data["frames"]:
            assert entry["split"] == split
            views[entry["view"]] = (data, entry)
    return views


def nerf_rays(data, entry, rows, cols):
    """Rays of pixels (rows, cols) as a NeRF loader builds them from the JSON alone."""
    m = np.asarray(entry["transform_matrix"], np.float64)
    d = np.stack([(cols + 0.5 - data["cx"]) / data["fl_x"],
                  -(rows + 0.5 - data["cy"]) / data["fl_y"], -np.ones(len(rows))], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    return np.broadcast_to(m[:3, 3], d.shape), d @ m[:3, :3].T


def surface_errors(scene):
    """Distances between (ray walked by depth) and (object coordinates placed by the instance
    pose of that view) for every pixel that sees an instance, over all views."""
    meta = file_io.read_json(scene / "metadata.json")
    layers = file_io.read_image_dict(scene)
    errors = []
    for view, (data, entry) in load_transforms(scene).items():
        assert entry["file_path"] == f"./rgba_{view:05d}"
        assert (scene / (entry["file_path"] + ".png")).is_file()
        seg = layers["segmentation"][view, ..., 0].astype(int)
        rows, cols = np.nonzero(seg)
        if not len(rows):
            continue
        origin, d = nerf_rays(data, entry, rows, cols)
        p_ray = origin + d * layers["depth"][view, rows, cols, 0][:, None]
        oc = layers["object_coordinates"][view, rows, cols].astype(np.float64)
        p_model = np.zeros_like(p_ray)
        for k in np.unique(seg[rows, cols]):
            inst = meta["instances"][k - 1]
            rot = quat_matrix(inst["quaternions"][view])
            pos = np.asarray(inst["positions"][view], np.float64)
            corners = (np.asarray(inst["bboxes_3d"][view], np.float64) - pos) @ rot
            lo, hi = corners[0], corners[7]
            sel = seg[rows, cols] == k
            p_model[sel] = (lo + oc[sel] * (hi - lo)) @ rot.T + pos
        errors.append(np.linalg.norm(p_ray - p_model, axis=-1))
    return np.concatenate(errors)


@pytest.mark.parametrize("recipe", sorted(k for k in RUNS if not k.endswith(":again")))
def test_transforms_rays_land_on_the_model_surface(scenes, recipe):
    scene = scenes[recipe]
    assert (scene / "_SUCCESS").is_file()
    meta = file_io.read_json(scene / "metadata.json")
    views = load_transforms(scene)
    n = meta["metadata"]["num_views"]
    assert sorted(views) == list(range(n))
    a, b, c = meta["metadata"]["split_ratio"]
    for view, (data, entry) in views.items():
        p = view % (a + b + c)
        assert entry["split"] == ("train" if p < a else "val" if p < a + b else "test")
        w, h = meta["metadata"]["resolution"]
        assert (data["w"], data["h"]) == (w, h)
        assert data["camera_angle_x"] == pytest.approx(2 * np.arctan(0.5 * w / data["fl_x"]))
        np.testing.assert_allclose(entry["transform_matrix"],
                                   meta["camera"]["matrices_world"][view], atol=1e-6)
    depth = file_io.read_image_dict(scene, ["depth"])["depth"]
    hits = depth[depth < meta["metadata"]["background_depth"]]
    for data, _ in views.values():
        assert (data["near"], data["far"]) == pytest.approx((hits.min(), hits.max()), rel=1e-6)
    errors = surface_errors(scene)
    assert len(errors) > 100
    assert np.median(errors) < 1e-3, (np.median(errors), np.percentile(errors, 95))


def test_iter_views_rays_match_the_camera_metadata(scenes):
    """The library's loader: its rays equal those from metadata.json's OpenCV intrinsics and
    camera matrices (an independent path), and walking them by depth reaches the point cloud."""
    from kubric.datasets.exports.nerf import iter_views
    scene = scenes["klevr"]
    meta = file_io.read_json(scene / "metadata.json")
    k = np.asarray(meta["camera"]["intrinsics_pixels"])
    pts = np.load(scene / "points.npz")
    seen = []
    for split in ("train", "val", "test"):
        for v in iter_views(scene, split):
            seen.append(v["view"])
            h, w = v["depth"].shape
            cols, rows = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
            cv = np.stack([(cols - k[0, 2]) / k[0, 0], (rows - k[1, 2]) / k[1, 1],
                           np.ones_like(cols)], -1)  # OpenCV axes: y down, looking down +z
            m = np.asarray(meta["camera"]["matrices_world"][v["view"]])
            d = (cv * [1, -1, -1]) @ m[:3, :3].T
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            np.testing.assert_allclose(v["directions"], d, atol=1e-9)
            np.testing.assert_allclose(v["origins"][0, 0], m[:3, 3])
            hit = v["depth"] < meta["metadata"]["background_depth"]
            xyz = (v["origins"] + v["directions"] * v["depth"][..., None])[hit]
            np.testing.assert_allclose(xyz, pts["xyz"][pts["view"] == v["view"]], atol=1e-4)
            assert v["rgb"].shape == (h, w, 3) and v["rgb"].dtype == np.uint8
            np.testing.assert_array_equal(v["rgb"][hit], pts["rgb"][pts["view"] == v["view"]])
    assert sorted(seen) == list(range(meta["metadata"]["num_views"]))
    with pytest.raises(ValueError, match="unknown split"):
        next(iter_views(scene, "training"))


def test_same_seed_same_scene(scenes):
    a, b = scenes["klevr"], scenes["klevr:again"]
    for name in ("transforms_train.json", "transforms_test.json", "events.json"):
        assert (a / name).read_text() == (b / name).read_text(), name
    meta_a, meta_b = (file_io.read_json(s / "metadata.json") for s in (a, b))
    assert meta_a["instances"] == meta_b["instances"]
    np.testing.assert_array_equal(read_labels(a, "semantic"), read_labels(b, "semantic"))
    pa, pb = np.load(a / "points.npz"), np.load(b / "points.npz")
    np.testing.assert_array_equal(pa["xyz"], pb["xyz"])


def test_undocumented_fields(scenes):
    from kubric.docgen import undocumented_scene_fields
    for recipe, scene in scenes.items():
        assert undocumented_scene_fields(scene) == [], recipe


# ---------------------------------------------------------------------- klevr
def test_klevr_semantics_match_the_instance_class_table(scenes):
    scene = scenes["klevr"]
    meta = file_io.read_json(scene / "metadata.json")
    classes = meta["metadata"]["semantic_classes"]
    assert classes[0] == "background"
    layers = file_io.read_image_dict(scene)
    seg = layers["segmentation"][..., 0]
    sem = read_labels(scene, "semantic")
    assert sem.shape == seg.shape
    table = np.array([0] + [inst["semantic_id"] for inst in meta["instances"]])
    np.testing.assert_array_equal(sem, table[seg])
    for inst in meta["instances"]:
        assert classes[inst["semantic_id"]] == inst["category"] == inst["asset_id"]
    assert len(set(table[1:])) >= 2


def test_toybox_uses_the_most_common_categories(scenes):
    scene = scenes["toybox"]
    meta = file_io.read_json(scene / "metadata.json")
    classes = meta["metadata"]["semantic_classes"]
    assert classes == ["background", "round", "boxy"]  # 3 round, 2 boxy, 1 kitchen
    sem, seg = read_labels(scene, "semantic"), read_labels(scene, "segmentation")
    table = np.array([0] + [inst["semantic_id"] for inst in meta["instances"]])
    np.testing.assert_array_equal(sem, table[seg])
    for inst in meta["instances"]:
        assert TOY_CATEGORIES[inst["asset_id"]] == inst["category"] == classes[inst["semantic_id"]]
    assert meta["metadata"]["background"] in HDRIS


def _interp_points(layers, data, entry, view, xy):
    """Surface points of ``view`` at sub-pixel positions ``xy`` (N,2), interpolating 1/z
    bilinearly (exact on planes), with the 4 neighbouring pixel indices."""
    x, y = xy[:, 0] - 0.5, xy[:, 1] - 0.5
    c0, r0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - c0, y - r0
    rows = np.stack([r0, r0, r0 + 1, r0 + 1], 1)
    cols = np.stack([c0, c0 + 1, c0, c0 + 1], 1)
    wts = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
    # depth -> z with each neighbour's own ray
    _, d = nerf_rays(data, entry, rows.ravel(), cols.ravel())
    axis = -np.asarray(entry["transform_matrix"])[:3, 2]
    z = layers["depth"][view, rows.ravel(), cols.ravel(), 0] * (d @ axis)
    inv_z = (wts.ravel() / z).reshape(-1, 4).sum(1)
    origin, d_xy = nerf_rays(data, entry, y, x)  # rays through xy
    depth = 1.0 / inv_z / (d_xy @ axis)
    return origin + d_xy * depth[:, None], rows, cols


def test_klevr_point_clouds_of_two_views_agree(scenes):
    scene = scenes["klevr"]
    pts = dict(np.load(scene / "points.npz"))
    assert set(pts) >= {"xyz", "rgb", "class", "instance", "view"}
    layers = file_io.read_image_dict(scene)
    views = load_transforms(scene)
    h, w = layers["depth"].shape[1:3]
    checked = 0
    for a, b in [(0, 1), (2, 5), (3, 7)]:
        sel = pts["view"] == a
        xyz, cls, inst = pts["xyz"][sel].astype(np.float64), pts["class"][sel], pts["instance"][sel]
        data_b, entry_b = views[b]
        m = np.asarray(entry_b["transform_matrix"])
        cam = (xyz - m[:3, 3]) @ m[:3, :3]
        front = cam[:, 2] < -0.1
        xy = np.stack([data_b["cx"] + data_b["fl_x"] * cam[:, 0] / -cam[:, 2],
                       data_b["cy"] - data_b["fl_y"] * cam[:, 1] / -cam[:, 2]], 1)
        inside = front & (xy[:, 0] > 1) & (xy[:, 0] < w - 1) & (xy[:, 1] > 1) & (xy[:, 1] < h - 1)
        idx = np.nonzero(inside)[0]
        p_b, rows, cols = _interp_points(layers, data_b, entry_b, b, xy[idx])
        seg_b = layers["segmentation"][b, rows, cols, 0]
        nrm_b = layers["normal"][b, rows, cols]
        row_a, col_a = pts["pixel"][sel][idx].T
        nrm_a = layers["normal"][a, row_a, col_a]
        # overlap: b sees the same instance with the same (planar) face normal at all 4 pixels
        same = np.all(seg_b == inst[idx][:, None], axis=1) & \
            np.all(np.linalg.norm(nrm_b - nrm_a[:, None], axis=-1) < 2e-3, axis=1)
        assert same.sum() > 20, (a, b, same.sum())
        err = np.linalg.norm(p_b[same] - xyz[idx][same], axis=-1)
        assert np.median(err) < 1e-3, (a, b, np.median(err))
        sem_b = read_labels(scene, "semantic")[b]
        np.testing.assert_array_equal(sem_b[rows[same, 0], cols[same, 0]], cls[idx][same])
        checked += int(same.sum())
    assert checked > 100


# ---------------------------------------------------------------------- bad input


def test_bad_input_fails_in_one_line_before_rendering(tmp_path):
    from kubric.pipeline import OptionError, get_recipe
    with pytest.raises(OptionError) as err:
        get_recipe("klevr").from_assignments(["num_views=9", "split_ratio=8,1,1"])
    assert "num_views=9" in str(err.value) and "10" in str(err.value)
    assert "\n" not in str(err.value)
    get_recipe("klevr").from_assignments(["num_views=9", "split_ratio=8,1,0"])  # fits
    nocat = kubasic_with_categories(tmp_path / "nocat", {})
    with pytest.raises(OptionError) as err:
        get_recipe("toybox").from_assignments([f"objects={nocat}"])
    assert "without categories" in str(err.value) and "\n" not in str(err.value)
    toys = kubasic_with_categories(tmp_path / "toys", TOY_CATEGORIES)
    with pytest.raises(OptionError, match="'chair'"):
        get_recipe("toybox").from_assignments([f"objects={toys}", "categories=round,chair"])
    with pytest.raises(OptionError, match="'banana'"):
        get_recipe("klevr").from_assignments(["shapes=cube,banana"])
    with pytest.raises(OptionError) as err:
        get_recipe("texture_nerf").from_assignments(["band_range=-1,2.5", "texture_size=256"])
    assert "band_range=-1.0,2.5" in str(err.value) and "128" in str(err.value)
    assert "\n" not in str(err.value)
    get_recipe("texture_nerf").from_assignments(["band_range=-1,2.5", "texture_size=1024"])
    proc = run_worker("klevr", tmp_path / "out", 0, ["num_views=3"], timeout=60)
    assert proc.returncode != 0
    assert "num_views=3" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


# ---------------------------------------------------------------------- texture_nerf
def test_texture_nerf_band_label_is_the_cube_cutoff(scenes):
    scene = scenes["texture_nerf"]
    meta = file_io.read_json(scene / "metadata.json")
    seg = read_labels(scene, "segmentation")
    band = read_labels(scene, "band")
    cutoff = np.stack([file_io.read_tiff(p)[..., 0]
                       for p in sorted(scene.glob("cutoff_*.tiff"))])
    table = np.array([0.0] + [inst["cutoff_frequency"] for inst in meta["instances"]])
    np.testing.assert_allclose(cutoff, table[seg], rtol=1e-6)
    low, width = -1.0, 0.5  # band_range low and band_width
    expect = np.zeros(len(table), int)
    expect[1:] = 1 + np.floor((np.log10(table[1:]) - low) / width).astype(int)
    np.testing.assert_array_equal(band, expect[seg])
    assert all(10 ** -1 <= c <= 10 ** 1.8 for c in table[1:])
    edges = np.asarray(meta["metadata"]["bands"])
    for inst in meta["instances"]:
        lo, hi = edges[inst["band"] - 1]
        assert lo <= inst["cutoff_frequency"] < hi
    assert len(set(band[seg > 0])) >= 3  # several bands seen


def _radial_power_f95(image, pixels_per_face):
    """Frequency (cycles per face) below which 95% of the non-DC power of ``image`` lies."""
    grey = image.mean(-1)
    grey = grey - grey.mean()
    n = grey.shape[0]
    window = np.hanning(n)[:, None] * np.hanning(n)[None, :]
    power = np.abs(np.fft.fft2(grey * window)) ** 2
    k = np.fft.fftfreq(n) * n
    radius = np.hypot(k[:, None], k[None, :]) * pixels_per_face / n  # cycles per face
    order = np.argsort(radius.ravel())
    cumulative = np.cumsum(power.ravel()[order])
    return float(radius.ravel()[order][np.searchsorted(cumulative, 0.95 * cumulative[-1])])


def test_texture_spectrum_falls_off_at_the_cutoff(tmp_path):
    """One flat, front-facing cube per cut-off, seen by an orthographic camera under uniform
    white light: the rendered texture's power spectrum ends at the stated cut-off."""
    import kubric as kb
    from kubric.recipes.texture_nerf import band_limited_texture, textured_cube

    size, visible = 128, 0.8  # image pixels; the camera sees 0.8 of the face width
    cutoffs = (10.0, 30.0)
    scene = kb.Scene(resolution=(size, size), frame_start=0, frame_end=len(cutoffs) - 1)
    scene.ambient_illumination = kb.Color(1.0, 1.0, 1.0)
    scene.background = kb.Color(1.0, 1.0, 1.0)
    rng = np.random.RandomState(0)
    camera = kb.OrthographicCamera(orthographic_scale=visible)
    scene.camera = camera
    for frame, cutoff in enumerate(cutoffs):
        texture = band_limited_texture(rng, 256, cutoff, (0.5, 0.5, 0.5))
        path = tmp_path / f"t{frame}.png"
        file_io.write_png(np.rint(texture * 255).astype(np.uint8), path)
        cube = textured_cube(tmp_path, 1.0, path)
        cube.position = (4.0 * frame, 0.0, 0.0)
        scene.add(cube)
        camera.position = (4.0 * frame, -5.0, 0.0)  # faces the cube's -y face (u = x, v = z)
        camera.look_at((4.0 * frame, 0.0, 0.0))
        camera.keyframe_insert("position", frame)
        camera.keyframe_insert("quaternion", frame)
    renderer = kb.renderer.Blender(scene, tmp_path / "render", samples_per_pixel=16,
                                   use_denoising=False)
    rgba = renderer.render(return_layers=("rgba",))["rgba"][..., :3].astype(np.float64) / 255
    f95 = [_radial_power_f95(img, size / visible) for img in rgba]
    for cutoff, f in zip(cutoffs, f95, strict=True):
        assert 0.8 * cutoff <= f <= 1.2 * cutoff, (cutoff, f95)


# ---------------------------------------------------------------------- robust_nerf
def _footprints(inst, view):
    """(centre xy, radius) of an instance's footprint circle from its written 3D box."""
    pos = np.asarray(inst["positions"][view], np.float64)
    corners = np.asarray(inst["bboxes_3d"][view], np.float64)
    return pos[:2], float(np.max(np.linalg.norm(corners[:, :2] - pos[:2], axis=1)))


@pytest.mark.parametrize("key", ["robust_nerf", "robust_nerf:jitter"])
def test_robust_nerf_impostors_only_in_train_views_never_overlapping(scenes, key):
    scene = scenes[key]
    meta = file_io.read_json(scene / "metadata.json")
    splits = [v["split"] for v in meta["metadata"]["views"]]
    seg = read_labels(scene, "segmentation")
    mask = read_labels(scene, "impostor_mask")
    impostor = np.array([False] + [inst["is_impostor"] for inst in meta["instances"]])
    np.testing.assert_array_equal(mask, impostor[seg].astype(mask.dtype))
    for view, split in enumerate(splits):
        if split == "train":
            assert mask[view].any(), view  # the impostors are seen in every train view
        else:
            assert not mask[view].any(), view
    imps = [i for i in meta["instances"] if i["is_impostor"]]
    static = [i for i in meta["instances"] if not i["is_impostor"]]
    assert imps and static
    for inst in static:
        np.testing.assert_allclose(inst["positions"], [inst["positions"][0]] * len(splits))
    for view, split in enumerate(splits):
        for k, imp in enumerate(imps):
            assert imp["present"][view] == (split == "train")
            if split != "train":
                assert imp["positions"][view][2] < -100  # parked below the floor
                continue
            c, r = _footprints(imp, view)
            for other in static + imps[k + 1:]:
                c2, r2 = _footprints(other, view)
                assert np.linalg.norm(c - c2) >= r + r2, (view, imp["asset_id"])
    train = [v for v, s in enumerate(splits) if s == "train"]
    moves = [np.linalg.norm(np.subtract(imps[0]["positions"][a], imps[0]["positions"][b])[:2])
             for a, b in zip(train[:-1], train[1:], strict=True)]
    if key.endswith("jitter"):
        assert 0 < max(moves) <= 2 * 0.4 * np.sqrt(2)
    else:
        assert min(moves) > 0


# ---------------------------------------------------------------------- matting, nvs
def test_matting_mask_is_the_salient_object(scenes):
    scene = scenes["multiview_matting"]
    meta = file_io.read_json(scene / "metadata.json")
    salient = np.array([False] + [inst["is_salient"] for inst in meta["instances"]])
    assert salient.sum() == 1 and len(meta["instances"]) >= 3  # hard: clutter too
    seg, mask = read_labels(scene, "segmentation"), read_labels(scene, "mask")
    np.testing.assert_array_equal(mask, salient[seg].astype(mask.dtype))
    assert all(m.any() for m in mask)  # the salient object is in every view
    k = int(np.nonzero(salient)[0][0]) - 1
    np.testing.assert_allclose(meta["instances"][k]["positions"][0][:2], [0, 0], atol=1e-9)
    assert meta["metadata"]["background"] in HDRIS


def test_nvs_views_see_the_group(scenes):
    scene = scenes["nvs"]
    meta = file_io.read_json(scene / "metadata.json")
    assert meta["metadata"]["resolution"] == [48, 36] and meta["metadata"]["num_views"] == 4
    assert 3 <= len(meta["instances"]) <= 6 and meta["metadata"]["background"] in HDRIS
    seg = read_labels(scene, "segmentation")
    assert all(len(np.unique(s)) >= 3 for s in seg)


def test_every_recipe_packs_bit_exact(scenes, tmp_path):
    """Each recipe's scene packs under its schema (kubric/recipes/multiview_schema.py) and
    `--verify` finds every feature equal to the scene directory; the recipe's own layers are
    in the example."""
    from kubric.datasets import load, pack
    own = {"klevr": "semantic_segmentations", "toybox": "semantic_segmentations",
           "texture_nerf": "cutoff_frequencies", "robust_nerf": "impostor_masks",
           "multiview_matting": "masks", "nvs": "video"}
    for key, scene in scenes.items():
        recipe = key.split(":")[0]
        out = tmp_path / key.replace(":", "_")
        result = pack(scene.parent, out, splits="train=1", progress=False, verify=True)
        assert result.counts == {"train": 1} and not result.corrupt, result.format()
        example = load(out, "train")[0]
        assert example["metadata"]["video_name"] == scene.name
        assert example[own[recipe]].shape[:3] == (len(list(scene.glob("rgba_*.png"))), 36, 48)
