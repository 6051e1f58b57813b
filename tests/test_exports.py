"""`kubric export coco` and `kubric export bop` on real scenes (tiny MOVi-A scenes and a klevr
multi-view scene rendered by `kubric worker`), checked with independent readers: pycocotools
for COCO, trimesh / our PNG reader / the scene's own metadata and layers for BOP."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from kubric import file_io
from kubric.datasets.exports import rle
from kubric.io.layers import read_frame

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = ["resolution=64x48", "samples=2", "denoise=false"]


def kubric(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "kubric", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def worker(recipe, seed, out, options):
    cmd = ["worker", recipe, "--seed", seed, "--out", out]
    for o in options:
        cmd += ["--set", o]
    proc = kubric(*cmd)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("exports")
    for seed in (1, 4):
        worker("movi_a", seed, root / "movi_a", TINY + ["frame_end=3", "min_num_objects=6"])
    worker("movi_c", 2, root / "movi_c", TINY + ["frame_end=3", "collection_limit=8",
                                                  "max_num_objects=4"])
    worker("klevr", 2, root / "klevr", TINY + ["num_views=3", "split_ratio=1,1,1",
                                               "max_num_objects=5"])
    return root


# ------------------------------------------------------------------------------------- RLE
def test_rle_equals_pycocotools():
    mask_api = pytest.importorskip("pycocotools.mask")
    rng = np.random.RandomState(0)
    for trial in range(200):
        h, w = rng.randint(1, 30, 2)
        mask = rng.rand(h, w) < rng.rand()
        if trial % 4 == 0:
            mask[:] = trial % 8 == 0  # all-empty and all-full masks
        ours = rle.encode(mask)
        ref = mask_api.encode(np.asfortranarray(mask.astype(np.uint8)))
        assert ours["counts"] == ref["counts"].decode() and ours["size"] == list(ref["size"])
        plain = rle.encode(mask, compressed=False)
        assert (mask_api.decode(mask_api.frPyObjects(plain, h, w)) == mask).all()
        assert (rle.decode(ours) == mask).all() and (rle.decode(plain) == mask).all()


# ------------------------------------------------------------------------------------ COCO
def _check_coco(path, scenes_root, expect_kind):
    from pycocotools.coco import COCO
    coco = COCO(str(path))
    data = json.loads(path.read_text())
    assert data["info"]["categories_from"] == expect_kind
    cats = {c["id"]: c["name"] for c in data["categories"]}
    n_ann = 0
    for img in coco.dataset["images"]:
        assert (scenes_root / img["file_name"]).is_file()
        scene = scenes_root / img["scene"]
        meta = file_io.read_json(scene / "metadata.json")
        w, h = meta["metadata"]["resolution"]
        assert (img["width"], img["height"]) == (w, h)
        assert img["id"] == meta["metadata"]["seed"] * 10000 + img["frame"]
        seg = file_io.read_palette_png(scene / f"segmentation_{img['frame']:05d}.png")[..., 0]
        anns = coco.loadAnns(coco.getAnnIds(imgIds=[img["id"]]))
        assert sorted(a["instance"] + 1 for a in anns) == sorted(set(np.unique(seg)) - {0})
        for ann in anns:
            k = ann["instance"]
            inst = meta["instances"][k]
            mask = coco.annToMask(ann).astype(bool)
            assert (mask == (seg == k + 1)).all()
            assert ann["area"] == inst["visibility"][img["frame"]] == mask.sum()
            ymin, xmin, ymax, xmax = inst["bboxes"][inst["bbox_frames"].index(img["frame"])]
            np.testing.assert_allclose(ann["bbox"], [xmin * w, ymin * h, (xmax - xmin) * w,
                                                     (ymax - ymin) * h], atol=1e-4)
            assert ann["iscrowd"] == 0 and ann["id"] == img["id"] * 10000 + k + 1
            label = {"shape": inst.get("shape"), "asset category": inst.get("category"),
                     "semantic":
                     meta["metadata"].get("semantic_classes", [None])[inst.get("semantic_id", 0)]
                     }[expect_kind]
            assert cats[ann["category_id"]] == label
            n_ann += 1
    return coco, n_ann


@pytest.mark.blender
def test_coco_movi_a(scenes, tmp_path):
    pytest.importorskip("pycocotools")
    out = tmp_path / "movi_a.json"
    proc = kubric("export", "coco", scenes / "movi_a", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "export coco" in proc.stderr  # tqdm progress on stderr
    coco, n_ann = _check_coco(out, scenes / "movi_a", "shape")
    assert len(coco.dataset["images"]) == 2 * 3 and n_ann >= 2 * 3 * 3
    assert [c["name"] for c in coco.dataset["categories"]] == ["cube", "cylinder", "sphere"]
    # uncompressed RLE decodes to the same masks
    plain = tmp_path / "plain.json"
    assert kubric("export", "coco", scenes / "movi_a", "--out", plain, "--uncompressed-rle",
                  "--no-progress").returncode == 0
    plain_coco, _ = _check_coco(plain, scenes / "movi_a", "shape")
    assert isinstance(plain_coco.dataset["annotations"][0]["segmentation"]["counts"], list)


@pytest.mark.blender
def test_coco_ids_stable_across_shards(scenes, tmp_path):
    whole = tmp_path / "whole.json"
    assert kubric("export", "coco", scenes / "movi_a", "--out", whole).returncode == 0
    shard = tmp_path / "shard.json"
    one = scenes / "movi_a" / "scene_00000004"
    assert kubric("export", "coco", one, "--out", shard).returncode == 0
    a, b = json.loads(whole.read_text()), json.loads(shard.read_text())
    assert a["categories"] == b["categories"]
    ids_a = {x["id"]: x for x in a["annotations"]}
    for ann in b["annotations"]:
        assert ids_a[ann["id"]] == ann
    shard_images = {x["id"]: x["file_name"] for x in b["images"]}
    assert all(f"scene_00000004/{v}" == dict((x["id"], x["file_name"]) for x in a["images"])[k]
               for k, v in shard_images.items())


@pytest.mark.blender
def test_coco_multiview(scenes, tmp_path):
    pytest.importorskip("pycocotools")
    out = tmp_path / "klevr.json"
    assert kubric("export", "coco", scenes / "klevr", "--out", out).returncode == 0
    coco, n_ann = _check_coco(out, scenes / "klevr", "semantic")
    assert [i["split"] for i in coco.dataset["images"]] == ["train", "val", "test"]
    assert n_ann >= 3


@pytest.mark.blender
def test_coco_asset_categories(scenes, tmp_path):
    """movi_c: categories are the default objects collection's, in sorted order."""
    pytest.importorskip("pycocotools")
    from kubric import asset_tools
    out = tmp_path / "movi_c.json"
    assert kubric("export", "coco", scenes / "movi_c", "--out", out).returncode == 0
    coco, n_ann = _check_coco(out, scenes / "movi_c", "asset category")
    meta = file_io.read_json(scenes / "movi_c" / "scene_00000002" / "metadata.json")
    source = asset_tools.ensure_pybullet_collection(limit=meta["flags"]["collection_limit"])
    assert [c["name"] for c in coco.dataset["categories"]] == source.categories
    assert n_ann >= 3


def test_coco_bad_input(tmp_path):
    proc = kubric("export", "coco", tmp_path / "nope", "--out", tmp_path / "x.json")
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1
    assert "nope" in proc.stderr and "is not a directory" in proc.stderr
    (tmp_path / "empty").mkdir()
    proc = kubric("export", "coco", tmp_path / "empty", "--out", tmp_path / "x.json")
    assert proc.returncode == 1 and "no complete scene" in proc.stderr
    proc = kubric("export", "bop", tmp_path / "empty", "--out", tmp_path / "b",
                  "--depth-scale", "0")
    assert proc.returncode == 2 and "--depth-scale must be a finite number > 0" in proc.stderr


def test_one_export_command_per_registered_format(tmp_path):
    """Every module of kubric/datasets/exports/ (and of its hub/) that defines export_<its name>
    is a row of FORMATS and a `kubric export` sub-command; the old `kubric tracks export` prints
    one line naming `kubric export tapvid`."""
    import ast

    from kubric.datasets.exports import FORMATS
    defined = set()
    root = ROOT / "kubric" / "datasets" / "exports"
    for path in root.rglob("*.py"):
        module = ".".join(path.relative_to(root).with_suffix("").parts)
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef) and node.name == f"export_{path.stem}":
                defined.add(f"kubric.datasets.exports.{module}:{node.name}")
    assert defined == {row.target for row in FORMATS.values()}
    usage = kubric("export", "--help").stdout
    assert all(name in usage for name in FORMATS)
    proc = kubric("export", "tapvid", tmp_path, "--out", tmp_path / "t.pkl")
    assert proc.returncode == 1 and "no complete scene" in proc.stderr, proc.stderr
    old = kubric("tracks", "export", tmp_path, "--format", "tapvid", "--out", tmp_path / "t.pkl")
    assert old.returncode == 2 and old.stderr.count("\n") == 1
    assert "use `kubric export tapvid SCENES --out FILE.pkl`" in old.stderr


# ------------------------------------------------------------------------------------- BOP
def _png(path):
    return file_io.read_png(path)[..., 0]


@pytest.mark.blender
@pytest.mark.parametrize("recipe", ["movi_a", "movi_c", "klevr"])
def test_bop(scenes, tmp_path, recipe):
    """movi_a: two scenes, KuBasic OBJ meshes; movi_c: converted pybullet_data GLB meshes;
    klevr: a multi-view scene without a z layer (z-depth from the distance layer)."""
    import trimesh

    from kubric import asset_tools
    out = tmp_path / "bop"
    proc = kubric("export", "bop", scenes / recipe, "--out", out)
    assert proc.returncode == 0, proc.stderr
    again = kubric("export", "bop", scenes / recipe, "--out", out, "--no-progress")
    assert again.returncode == 2 and "already holds a BOP export" in again.stderr
    assert again.stderr.count("\n") == 1
    info = json.loads((out / "models" / "models_info.json").read_text())
    index = json.loads((out / "models" / "models_index.json").read_text())
    meshes = {}
    for obj_id, entry in info.items():
        mesh = trimesh.load(out / "models" / f"obj_{int(obj_id):06d}.ply", process=False)
        meshes[int(obj_id)] = mesh
        lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
        np.testing.assert_allclose([entry["min_x"], entry["min_y"], entry["min_z"]], lo, atol=1e-3)
        np.testing.assert_allclose(hi, -lo, atol=1e-3)  # origin at the box centre
        if recipe == "movi_a":  # unit-sized KuBasic shapes: the largest side is 1000 · size
            assert index[obj_id]["scale"][0] in (0.7, 1.4)
            np.testing.assert_allclose((hi - lo).max(), 1000 * index[obj_id]["scale"][0],
                                       rtol=1e-5)
    hits, gaps, errors = [], [], []
    for scene_dir in sorted((scenes / recipe).glob("scene_*")):
        meta = file_io.read_json(scene_dir / "metadata.json")
        source = asset_tools.ensure_pybullet_collection(limit=meta["flags"]["collection_limit"]) \
            if recipe == "movi_c" else asset_tools.ensure_kubasic()
        bounds = {a: source.db[a]["kwargs"]["bounds"] for a in source.all_asset_ids}
        w, h = meta["metadata"]["resolution"]
        bop = out / "train_pbr" / f"{meta['metadata']['seed']:06d}"
        cams = json.loads((bop / "scene_camera.json").read_text())
        gts = json.loads((bop / "scene_gt.json").read_text())
        infos = json.loads((bop / "scene_gt_info.json").read_text())
        for i in range(meta["metadata"]["num_frames"]):
            cam = cams[str(i)]
            k = np.reshape(cam["cam_K"], (3, 3))
            depth = _png(bop / "depth" / f"{i:06d}.png").astype(float) * cam["depth_scale"]
            if recipe != "klevr":  # depth × depth_scale = our z-depth in mm (quantised)
                z = file_io.read_tiff(scene_dir / f"z_{i:05d}.tiff")[..., 0] * 1000.0
                assert np.abs(depth - z).max() <= cam["depth_scale"] / 2 + 1e-3
            seg = file_io.read_palette_png(scene_dir / f"segmentation_{i:05d}.png")[..., 0]
            oc = read_frame(scene_dir, "object_coordinates", i).astype(float)
            r_w2c = np.reshape(cam["cam_R_w2c"], (3, 3))
            t_w2c = np.asarray(cam["cam_t_w2c"])
            assert len(gts[str(i)]) == len(meta["instances"])
            for g, (gt, gi) in enumerate(zip(gts[str(i)], infos[str(i)], strict=True)):
                inst = meta["instances"][g]
                # the world → camera transform puts the object's origin at its recorded image
                # position (normalised, pixel centres at +0.5; cam_K's centres are integers)
                p = r_w2c @ (np.asarray(inst["positions"][i]) * 1000) + t_w2c
                uv = (k @ p)[:2] / p[2]
                np.testing.assert_allclose(uv + 0.5, np.multiply(inst["image_positions"][i],
                                                                 [w, h]), atol=2e-3)
                mask = _png(bop / "mask" / f"{i:06d}_{g:06d}.png") > 0
                visib = _png(bop / "mask_visib" / f"{i:06d}_{g:06d}.png") > 0
                assert (visib == (seg == g + 1)).all() and not (visib & ~mask).any()
                assert gi["px_count_all"] == mask.sum() and gi["px_count_visib"] == visib.sum()
                assert gi["visib_fract"] == pytest.approx(gi["px_count_visib"] / gi["px_count_all"])
                # every model vertex, projected with cam_K, cam_R_m2c, cam_t_m2c, lands in the
                # object's mask (at the silhouette within half a pixel of a mask pixel centre)
                r = np.reshape(gt["cam_R_m2c"], (3, 3))
                pts = meshes[gt["obj_id"]].vertices @ r.T + gt["cam_t_m2c"]
                uv = pts[:, :2] / pts[:, 2:] * [k[0, 0], k[1, 1]] + [k[0, 2], k[1, 2]]
                inside = (uv[:, 0] > -0.5) & (uv[:, 0] < w - 0.5) & (uv[:, 1] > -0.5) & \
                    (uv[:, 1] < h - 0.5)
                centres = np.argwhere(mask)[:, ::-1]  # (x, y) of the mask's pixel centres
                for x, y in uv[inside]:
                    hit = mask[int(np.rint(y)), int(np.rint(x))]
                    # distance to the nearest mask pixel (its square, not its centre)
                    gap = np.hypot(*np.maximum(np.abs(centres - [x, y]) - 0.5, 0).T).min()
                    hits.append(hit)
                    gaps.append(gap)
                # the visible pixels' surface points (object-coordinate layer, in the asset's
                # frame) posed with cam_R_m2c, cam_t_m2c = the pixels unprojected with BOP's depth
                rows, cols = np.nonzero(visib & (depth > 0))
                if len(rows):
                    lo, hi = np.asarray(bounds[inst["asset_id"]])
                    scale = np.asarray(index[str(gt["obj_id"])]["scale"])
                    local = lo + oc[rows, cols] * (hi - lo)
                    model_pts = (local - (lo + hi) / 2) * scale * 1000.0
                    posed = model_pts @ r.T + gt["cam_t_m2c"]
                    d = depth[rows, cols]
                    seen = np.stack([(cols - k[0, 2]) / k[0, 0] * d,
                                     (rows - k[1, 2]) / k[1, 1] * d, d], axis=1)
                    errors.append(np.linalg.norm(posed - seen, axis=1))
    hits, gaps = np.asarray(hits), np.asarray(gaps)
    print(f"{hits.mean():.4f} of {len(hits)} vertices in a mask pixel; distance to the nearest "
          f"mask pixel: max {gaps.max():.3f} px, 99th percentile {np.percentile(gaps, 99):.3f}")
    # vertices on a silhouette (a sphere's rim: many) may fall just outside the pixels whose
    # centres the silhouette covers: sub-pixel (a cone's apex, a spike narrower than a pixel,
    # covers no pixel centre near its tip: up to 1.13 px measured); the rest land inside
    assert len(hits) > 100 and hits.mean() > 0.7 and np.percentile(gaps, 99) < 1.0
    assert gaps.max() < 1.5
    errors = np.concatenate(errors)
    print(f"posed surface points vs depth: median {np.median(errors):.3f} mm, max "
          f"{errors.max():.3f} mm over {len(errors)} pixels")
    assert np.median(errors) < 1.0 and errors.max() < 5.0


# ------------------------------------------------------------------ streaming (no rendering)
def synthetic_scenes(root, seeds, frames=4, size=(32, 24), instances=5):
    """Scene directories with random block segmentations (no renderer): what the COCO export
    reads (metadata, rgba, segmentation, _SUCCESS)."""
    w, h = size
    for seed in seeds:
        rng = np.random.RandomState(seed)
        seg = np.zeros((frames, h, w, 1), np.uint8)
        for t in range(frames):
            for k in range(1, instances + 1):
                r, c = rng.randint(0, h - 4), rng.randint(0, w - 4)
                seg[t, r:r + rng.randint(2, 8), c:c + rng.randint(2, 8)] = k
        scene = root / f"scene_{seed:08d}"
        file_io.write_image_dict({"rgba": rng.randint(0, 255, (frames, h, w, 4), np.uint8),
                                  "segmentation": seg}, scene)
        meta = {"flags": {"recipe": "synthetic", "seed": seed},
                "metadata": {"seed": seed, "num_frames": frames, "resolution": [w, h]},
                "camera": {"matrices_world": [np.eye(4).tolist()] * frames},
                "instances": [{"asset_id": f"thing{k}"} for k in range(instances)]}
        file_io.write_json(meta, scene / "metadata.json")
        (scene / "_SUCCESS").touch()


_PEAK = """
import json, sys, tracemalloc
from kubric.datasets.exports.coco import export_coco
export_coco(sys.argv[1], sys.argv[2] + ".warm.json", progress=False)  # imports: not counted
tracemalloc.start()
summary = export_coco(sys.argv[1], sys.argv[2], progress=False)
print(json.dumps({"peak": tracemalloc.get_traced_memory()[1], "images": summary.images,
                  "annotations": summary.annotations, "skipped": summary.skipped_incomplete,
                  "kind": summary.category_kind}))
"""


def test_coco_streams_one_scene_at_a_time(tmp_path):
    """Peak memory of an export (measured in a fresh process, so nothing the test session holds
    counts) is flat in the number of scenes."""
    peaks = {}
    for n in (20, 400):
        root = tmp_path / f"n{n}"
        synthetic_scenes(root, range(n))
        (root / ".scene_00009999.incomplete-1").mkdir()  # a worker's leftover: skipped
        out = tmp_path / f"n{n}.json"
        proc = subprocess.run([sys.executable, "-c", _PEAK, str(root), str(out)],
                              capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-2000:]
        summary = json.loads(proc.stdout.strip().splitlines()[-1])
        peaks[n] = summary["peak"]
        data = json.loads(out.read_text())
        assert summary["images"] == len(data["images"]) == 4 * n
        assert summary["annotations"] == len(data["annotations"]) > 4 * n
        assert summary["skipped"] == 1 and summary["kind"] == "object"
        assert len({a["id"] for a in data["annotations"]}) == summary["annotations"]
        for ann in data["annotations"][:50]:
            img = ann["image_id"]
            seg = file_io.read_palette_png(root / f"scene_{img // 10000:08d}" /
                                           f"segmentation_{img % 10000:05d}.png")[..., 0]
            assert (rle.decode(ann["segmentation"]) == (seg == ann["instance"] + 1)).all()
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no side files
    # 20× the scenes (1.5 MB more JSON) may not need 20× the memory: one scene at a time
    print("peak traced memory by scene count:", peaks)
    assert peaks[400] < 1.5 * peaks[20] + 512 * 1024, peaks


def test_coco_refuses_mixed_recipes_and_missing_frames(tmp_path):
    root = tmp_path / "scenes"
    synthetic_scenes(root, [3, 5], frames=2)
    meta = file_io.read_json(root / "scene_00000005" / "metadata.json")
    meta["flags"]["recipe"] = "other"
    file_io.write_json(meta, root / "scene_00000005" / "metadata.json")
    proc = kubric("export", "coco", root, "--out", tmp_path / "x.json")
    assert proc.returncode == 1 and proc.stderr.splitlines()[-1].startswith(
        "kubric export coco: error: scene_00000005: recipe 'other' differs")
    assert not (tmp_path / "x.json").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no side files left
    (root / "scene_00000003" / "rgba_00001.png").unlink()
    proc = kubric("export", "coco", root / "scene_00000003", "--out", tmp_path / "x.json")
    assert proc.returncode == 1 and "frame 1 has no rgba_00001.png" in proc.stderr
