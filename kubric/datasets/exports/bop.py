"""``kubric export bop SCENES --out DIR``: a BOP 6D object-pose dataset.

Layout (BOP's, as the BOP toolkit reads it)::

    DIR/models/obj_{obj_id:06d}.ply      one model per (asset, scale): mm, origin at the box centre
    DIR/models/models_info.json          {obj_id: diameter, min_x/y/z, size_x/y/z} (mm)
    DIR/models/models_index.json         (addition) {obj_id: asset_id, scale, source, license}
    DIR/SPLIT/{scene_id:06d}/            scene_id = the scene's seed; image id = frame index
                                         (camera rigs: c · T + frame for camera c, below)
        rgb/{im_id:06d}.png              RGB (the RGBA frame without alpha)
        depth/{im_id:06d}.png            uint16 z-depth: mm = value · depth_scale; 0 = no surface
        mask/{im_id:06d}_{gt:06d}.png    the object's full silhouette (255), as if unoccluded
        mask_visib/{im_id:06d}_{gt:06d}.png   its visible pixels (our segmentation label)
        scene_camera.json                {im_id: cam_K, depth_scale, cam_R_w2c, cam_t_w2c}
        scene_gt.json                    {im_id: [{cam_R_m2c, cam_t_m2c (mm), obj_id}, ...]}
        scene_gt_info.json               {im_id: [{bbox_obj, bbox_visib, px_count_all,
                                          px_count_valid, px_count_visib, visib_fract}, ...]}
        licenses.json                    (addition) every asset the images show and its
                                         licence (:mod:`kubric.datasets.exports.licences`)

``gt`` indexes the scene's rigid instances: ``metadata["instances"]`` (every instance, visible or
not) without the people (instances with ``keypoints_2d`` or a ``character_id``): BOP models are
rigid meshes, a character deforms, so people are left out and counted in the summary (their
pixels belong to no object's mask).
Conventions: camera axes are OpenCV's (x right, y down, looking down +z: ours with y and z
negated); ``cam_K`` puts pixel centres at integer coordinates (our ``intrinsics_pixels`` with
``cx``, ``cy`` minus 0.5); rotations row-major; lengths in mm. ``mask``: the object's mesh
rasterised at its pose (a pixel is in when its centre falls inside a projected triangle, as our
annotation pass samples pixel centres) united with its visible pixels, so ``mask_visib`` ⊆
``mask`` always; a scene made with ``extra_layers=amodal`` gives ``mask`` from its amodal layer
instead (cast from the scene model at pixel centres, objects behind the camera included). Boxes are
``[x, y, w, h]`` in pixels (``[-1, -1, -1, -1]`` when empty). A scene is written into a hidden
folder renamed when complete; ``models_info.json`` is written last.

Camera rigs (``cameras=stereo|ring|random``): one BOP scene holds every camera's frames as images of
their own, as BOP's multi-view scenes hold several viewpoints of one scene: frame ``t`` of
camera ``c`` (0 = the reference, in ``metadata.camera.rig.cameras`` order) is image
``c · T + t`` (T frames; :mod:`kubric.datasets.exports.scenes`), with that camera's ``cam_K``,
``cam_R_w2c``, ``cam_t_w2c``, depth, masks and poses, and (an addition to BOP's fields)
``camera``: its name in ``scene_camera.json``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import shutil
import sys

import numpy as np

from kubric.core.lenses import pinhole_refusal
from kubric.datasets.exports import licences
from kubric.datasets.exports import models as mdl
from kubric.datasets.exports.coco import amodal_masks, mask_bbox
from kubric.datasets.exports.scenes import (
    ExportError,
    Scene,
    camera_views,
    find_scenes,
    load_scene,
    model_sources,
)
from kubric.io.output_check import OutputError
from kubric.io.png_io import encode_png

#: our camera axes (x right, y up, looking down -z) → OpenCV's
BLENDER_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
LICENSES_FILE = "licenses.json"


@dataclasses.dataclass
class BopSummary:
    path: pathlib.Path
    scenes: int
    images: int
    instances: int
    models: int
    depth_clipped: int
    skipped_incomplete: int
    people: int = 0

    def format(self) -> str:
        extra = f", {self.skipped_incomplete} incomplete scene(s) skipped" \
            if self.skipped_incomplete else ""
        if self.people:
            extra += f", {self.people} person instance(s) left out (BOP models are rigid)"
        clipped = f"; {self.depth_clipped} depth pixels beyond 65535 · depth_scale mm written " \
            "as 0" if self.depth_clipped else ""
        return (f"wrote {self.path}: {self.scenes} scene(s), {self.images} images, "
                f"{self.instances} object annotations, {self.models} models{extra}{clipped}")


def quaternion_matrix(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def world_to_camera(matrix_world) -> tuple[np.ndarray, np.ndarray]:
    """(R_w2c, t_w2c in mm) in OpenCV axes from our camera → world matrix (Blender axes)."""
    m = np.asarray(matrix_world, dtype=np.float64)
    r = BLENDER_TO_OPENCV @ m[:3, :3].T
    return r, -r @ (m[:3, 3] * 1000.0)


def z_from_distance(depth: np.ndarray, k: np.ndarray) -> np.ndarray:
    """z-depth from our depth layer (distance from the camera centre along the pixel-centre ray),
    for scenes without a ``z`` layer: z = distance / |K⁻¹ (col, row, 1)| (``k`` OpenCV's)."""
    h, w = depth.shape
    cols, rows = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    norm = np.sqrt(((cols - k[0, 2]) / k[0, 0]) ** 2 + ((rows - k[1, 2]) / k[1, 1]) ** 2 + 1.0)
    return depth.astype(np.float64) / norm


def opencv_k(intrinsics_pixels) -> np.ndarray:
    k = np.array(intrinsics_pixels, dtype=np.float64)
    k[0, 2] -= 0.5
    k[1, 2] -= 0.5
    return k


def instance_scale(instance: dict, bounds) -> np.ndarray:
    """The object's scale per axis, from its world box corners (frame 0) and unscaled bounds."""
    corners = np.asarray(instance["bboxes_3d"][0], dtype=np.float64)
    lo, hi = np.asarray(bounds, dtype=np.float64)
    edges = np.array([np.linalg.norm(corners[4] - corners[0]),
                      np.linalg.norm(corners[2] - corners[0]),
                      np.linalg.norm(corners[1] - corners[0])])
    extent = np.where(hi - lo > 0, hi - lo, 1.0)
    return np.array([float(f"{s:.6g}") for s in edges / extent])


class ModelStore:
    """Models by (asset, scale): written once to DIR/models, numbered in order of appearance."""

    def __init__(self, folder: pathlib.Path, sources):
        self.folder, self.sources = folder, sources
        self.meshes: dict[str, tuple] = {}
        self.models: dict[tuple, tuple[int, mdl.Model]] = {}
        self.info: dict[str, dict] = {}
        self.index: dict[str, dict] = {}

    def get(self, instance: dict) -> tuple[int, mdl.Model]:
        asset_id = str(instance.get("asset_id"))
        if asset_id not in self.meshes:
            source = mdl.find_asset(self.sources, asset_id)
            vertices, faces = mdl.load_mesh(source, asset_id)
            bounds = source.db[asset_id].get("kwargs", {}).get("bounds") or \
                [vertices.min(axis=0).tolist(), vertices.max(axis=0).tolist()]
            self.meshes[asset_id] = (vertices, faces, bounds, source.name,
                                     source.db[asset_id].get("license"))
        vertices, faces, bounds, source_name, licence = self.meshes[asset_id]
        scale = instance_scale(instance, bounds)
        key = (asset_id, tuple(scale.tolist()))
        if key not in self.models:
            obj_id = len(self.models) + 1
            model = mdl.make_model(vertices, faces, scale)
            path = self.folder / f"obj_{obj_id:06d}.ply"
            path.write_bytes(mdl.ply_bytes(model))
            self.info[str(obj_id)] = model.info()
            self.index[str(obj_id)] = {"asset_id": asset_id, "scale": scale.tolist(),
                                       "source": source_name, "license": licence}
            self.models[key] = (obj_id, model)
        return self.models[key]

    def finish(self) -> None:
        for name, data in (("models_index.json", self.index), ("models_info.json", self.info)):
            tmp = self.folder / f".{name}.tmp"
            tmp.write_text(json.dumps(data, indent=1) + "\n")
            os.replace(tmp, self.folder / name)


def _bbox(mask: np.ndarray) -> list[int]:
    """BOP's ``[x, y, w, h]`` of a mask; ``[-1, -1, -1, -1]`` when it is empty."""
    return mask_bbox(mask) if mask.any() else [-1, -1, -1, -1]


def _png(array: np.ndarray) -> bytes:
    return encode_png(np.ascontiguousarray(array if array.ndim == 3 else array[..., None]))


def is_person(instance: dict) -> bool:
    """A character instance (deforming: no BOP model can describe it)."""
    return "keypoints_2d" in instance or "character_id" in instance


def export_scene(scene: Scene, out: pathlib.Path, store: ModelStore, depth_scale: float
                 ) -> tuple[int, int, int]:
    """Write one scene's BOP folder (every camera of a camera-rig scene: image ids
    ``c · T + t``); returns (images, annotations, clipped depth pixels)."""
    work = out.with_name(f".{out.name}.incomplete")
    shutil.rmtree(work, ignore_errors=True)
    for sub in ("rgb", "depth", "mask", "mask_visib"):
        (work / sub).mkdir(parents=True)
    files: tuple[dict, dict, dict] = ({}, {}, {})  # scene_camera, scene_gt, scene_gt_info
    images = n_ann = clipped = 0
    for view in camera_views(scene):
        refusal = pinhole_refusal(view.metadata["camera"],
                                  f"export_bop ({scene.path.name}): BOP's cam_K")
        if refusal:
            raise ExportError(refusal)
        writer = _CameraWriter(view, work, store, depth_scale)
        for i in range(scene.num_frames):
            im = str(view.image_index(i))
            entries = writer.frame(i, view.image_index(i))
            for table, entry in zip(files, entries, strict=True):
                table[im] = entry
            images, n_ann = images + 1, n_ann + len(entries[1])
        clipped += writer.clipped
    assets = licences.as_json(licences.scene_licences(scene.metadata))
    for name, data in zip(("scene_camera.json", "scene_gt.json", "scene_gt_info.json",
                           LICENSES_FILE), (*files, assets), strict=True):
        (work / name).write_text(json.dumps(data, indent=1) + "\n")
    shutil.rmtree(out, ignore_errors=True)
    os.replace(work, out)
    return images, n_ann, clipped


class _CameraWriter:
    """One camera's frames of a scene into a BOP scene folder (``work``)."""

    def __init__(self, view: Scene, work: pathlib.Path, store: ModelStore, depth_scale: float):
        self.view, self.work, self.store, self.depth_scale = view, work, store, depth_scale
        meta = view.metadata
        self.k = opencv_k(meta["camera"]["intrinsics_pixels"])
        self.background = float(meta["metadata"].get("background_depth", 10000.0))
        instances = meta.get("instances", [])
        self.rigid = [(k, inst) for k, inst in enumerate(instances) if not is_person(inst)]
        self.amodal = amodal_masks(view, len(instances))  # (T, N, H, W) or None
        self.clipped = 0

    def frame(self, i: int, im: int) -> tuple[dict, list, list]:
        """Write frame ``i`` as image ``im``; its (scene_camera, scene_gt, scene_gt_info)
        entries."""
        view, work, k = self.view, self.work, self.k
        w, h = view.resolution
        try:
            rgba = view.read_frame("rgba", i)
            depth = view.read_frame("depth", i)[..., 0]
            seg = view.read_frame("segmentation", i)[..., 0]
        except FileNotFoundError as err:
            raise ExportError(f"{view.path.name}: {err} (the BOP export needs rgba, depth "
                              "and segmentation)") from None
        z = view.read_frame("z", i)[..., 0].astype(np.float64) \
            if (view.path / f"{view.prefix}z_{i:05d}.tiff").is_file() \
            else z_from_distance(depth, k)
        (work / "rgb" / f"{im:06d}.png").write_bytes(_png(rgba[..., :3]))
        hit = depth < self.background * 0.999
        units = np.where(hit, np.rint(z * 1000.0 / self.depth_scale), 0)
        over = units > 65535
        self.clipped += int(over.sum())
        units[over] = 0
        depth_u16 = units.astype(np.uint16)
        (work / "depth" / f"{im:06d}.png").write_bytes(_png(depth_u16))
        r_w2c, t_w2c = world_to_camera(view.metadata["camera"]["matrices_world"][i])
        cam = {"cam_K": k.ravel().tolist(), "depth_scale": self.depth_scale,
               "cam_R_w2c": r_w2c.ravel().tolist(), "cam_t_w2c": t_w2c.tolist()}
        if view.camera_name:
            cam["camera"] = view.camera_name
        gts, infos = [], []
        for g, (label, inst) in enumerate(self.rigid):
            obj_id, model = self.store.get(inst)
            r_obj = quaternion_matrix(inst["quaternions"][i])
            r = r_w2c @ r_obj
            t = r_w2c @ (np.asarray(inst["positions"][i], dtype=np.float64) * 1000.0) + t_w2c
            t = t + r @ model.centre
            visib = seg == label + 1
            if self.amodal is not None:  # the scene's exact amodal layer (extra_layers=amodal)
                full = self.amodal[i, label] | visib
            else:
                cam_pts = model.vertices @ r.T + t
                if np.any(cam_pts[:, 2] <= 1.0):
                    raise ExportError(f"{view.path.name}: frame {i}: instance {label} "
                                      f"({inst.get('asset_id')}) reaches behind the camera; its "
                                      "silhouette cannot be projected")
                px = cam_pts[:, :2] / cam_pts[:, 2:3] * [k[0, 0], k[1, 1]] + [k[0, 2], k[1, 2]]
                full = mdl.rasterise(px, model.faces, h, w) | visib
            name = f"{im:06d}_{g:06d}.png"
            (work / "mask" / name).write_bytes(_png(full.astype(np.uint8) * 255))
            (work / "mask_visib" / name).write_bytes(_png(visib.astype(np.uint8) * 255))
            n_all, n_vis = int(full.sum()), int(visib.sum())
            gts.append({"cam_R_m2c": r.ravel().tolist(), "cam_t_m2c": t.tolist(),
                        "obj_id": obj_id})
            infos.append({"bbox_obj": _bbox(full), "bbox_visib": _bbox(visib),
                          "px_count_all": n_all,
                          "px_count_valid": int((full & (depth_u16 > 0)).sum()),
                          "px_count_visib": n_vis,
                          "visib_fract": n_vis / n_all if n_all else 0.0})
        return cam, gts, infos


def export_bop(root, out, split: str = "train_pbr", depth_scale: float = 1.0,
               progress: bool = True, sources=()) -> BopSummary:
    """Write every complete scene under ``root`` (or the scene ``root``) as a BOP dataset."""
    from tqdm import tqdm

    root, out = pathlib.Path(root), pathlib.Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {str(out)!r} is a file; give a folder (the BOP dataset root)")
    if not 0 < depth_scale < float("inf"):  # inf would write every depth as 0
        raise OutputError(f"--depth-scale must be a finite number > 0 (millimetres per depth "
                          f"unit), got {depth_scale}")
    if not split or "/" in split or split.startswith("."):
        raise OutputError(f"--split {split!r}: give a folder name such as train_pbr")
    if (out / "models" / "models_info.json").exists():
        raise OutputError(f"--out {str(out)!r} already holds a BOP export (models/models_info.json"
                          "); remove it or choose another folder (object ids are numbered per "
                          "export)")
    paths, skipped = find_scenes(root)
    first = load_scene(root, paths[0])
    store = ModelStore(out / "models", model_sources(first.metadata.get("flags", {}), sources))
    store.folder.mkdir(parents=True, exist_ok=True)
    n_images = n_ann = clipped = people = 0
    with tqdm(total=len(paths), unit="scene", desc="export bop", file=sys.stderr,
              disable=not progress) as bar:
        for path in paths:
            scene = first if path == paths[0] else load_scene(root, path)
            images, anns, over = export_scene(scene, out / split / f"{scene.seed:06d}", store,
                                              depth_scale)
            n_images, n_ann, clipped = n_images + images, n_ann + anns, clipped + over
            people += sum(map(is_person, scene.metadata.get("instances", [])))
            bar.update(1)
    store.finish()
    return BopSummary(out, len(paths), n_images, n_ann, len(store.models), clipped, skipped,
                      people)


__all__ = ["BopSummary", "export_bop", "instance_scale", "opencv_k", "quaternion_matrix",
           "world_to_camera", "z_from_distance"]
