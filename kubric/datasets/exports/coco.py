"""``kubric export coco SCENES --out FILE.json``: instance annotations in COCO's format.

One COCO image per frame (per view of a multi-view scene) whose ``file_name`` is the frame's RGB
file relative to SCENES (``scene_00000007/rgba_00003.png``); one annotation per instance visible
in that frame, derived from the segmentation layer:

* ``segmentation``: the instance's pixels (label ``k`` = ``metadata["instances"][k − 1]``) as a
  COCO RLE (:mod:`kubric.datasets.exports.rle`; compressed by default);
* ``bbox``: ``[x, y, w, h]`` in pixels, ``x, y`` the top-left corner of the box in pixel-edge
  coordinates: ``[col_min, row_min, col_max + 1 − col_min, row_max + 1 − row_min]`` (= our
  metadata's normalised ``(ymin, xmin, ymax, xmax)`` times the image size);
* ``area``: the number of pixels (= ``metadata["instances"][k − 1]["visibility"][i]``);
* ``iscrowd`` 0, ``category_id`` from the recipe's labels (:mod:`.categories`);
* additions: ``instance`` (k − 1), ``asset_id`` and ``license`` (the id, in the top-level
  ``licenses``, of the asset's licence and attribution, ``{"id", "name", "url"}``, as
  ``metadata.json``'s instance ``license`` / ``license_url`` say); images add ``scene``,
  ``seed``, ``frame`` and, for multi-view scenes, ``split``; top-level ``attribution``: every
  asset the images show — objects, background HDRI, PBR image sets, people
  (:mod:`kubric.datasets.exports.licences`) — with the ``license_id`` of its licence in
  ``licenses``;
* camera-rig scenes (``cameras=stereo|ring|random``): every camera's frames are images of their own
  (``file_name`` ``scene_…/right_rgba_00003.png``, masks from that camera's segmentation layer,
  keypoints from its per-camera fields), each adding ``camera`` (its name) and its geometry
  (:func:`camera_fields`); ids: :mod:`kubric.datasets.exports.scenes`;
* scenes made with ``extra_layers=amodal``: KINS's amodal fields (:func:`kins_fields`):
  ``a_segm`` (the amodal mask, RLE), ``a_bbox``, ``a_area`` and the visible ``i_segm``,
  ``i_bbox``, ``i_area`` — for the instances visible in the frame, as KINS annotates.

Ids: :mod:`kubric.datasets.exports.scenes`. The file is written as it goes (one scene in memory;
annotations go to a hidden side file and are appended at the end) and renamed into place when
complete, so a partial file never carries the final name.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import shutil
import sys

import numpy as np

from kubric import faults
from kubric.datasets.exports import licences as asset_licences
from kubric.datasets.exports import rle
from kubric.datasets.exports.categories import scheme_for
from kubric.datasets.exports.scenes import (
    ExportError,
    Scene,
    annotation_id,
    camera_views,
    find_scenes,
    image_id,
    load_scene,
)
from kubric.io.bitmask import MAX_MASKS, unpack_masks
from kubric.io.output_check import OutputError
from kubric.io.paths import temp_name_for


@dataclasses.dataclass
class CocoSummary:
    path: pathlib.Path
    scenes: int
    images: int
    annotations: int
    categories: list[str]
    category_kind: str
    skipped_incomplete: int

    def format(self) -> str:
        skipped = f", {self.skipped_incomplete} incomplete scene(s) skipped" \
            if self.skipped_incomplete else ""
        return (f"wrote {self.path}: {self.scenes} scene(s), {self.images} images, "
                f"{self.annotations} annotations, {len(self.categories)} categories "
                f"({self.category_kind}){skipped}")


def mask_bbox(mask: np.ndarray) -> list[int]:
    """COCO ``[x, y, w, h]`` (pixels, pixel-edge coordinates) of a non-empty (H, W) mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return [int(cols[0]), int(rows[0]), int(cols[-1] + 1 - cols[0]), int(rows[-1] + 1 - rows[0])]


def scene_records(scene: Scene, scheme, compressed: bool = True):
    """(images, annotations) of one scene, as lists of dicts: every camera of a camera-rig
    scene (:func:`~kubric.datasets.exports.scenes.camera_views`), the reference first."""
    images, annotations = [], []
    for view in camera_views(scene):
        more = camera_records(view, scheme, compressed)
        images += more[0]
        annotations += more[1]
    return images, annotations


def camera_records(scene: Scene, scheme, compressed: bool = True):
    """(images, annotations) of one camera of a scene (a view of :func:`camera_views`)."""
    w, h = scene.resolution
    try:
        seg = scene.read_layer("segmentation")[..., 0]
    except FileNotFoundError as err:
        raise ExportError(str(err)) from None
    if seg.shape != (scene.num_frames, h, w):
        raise ExportError(f"{scene.path.name}: {scene.prefix}segmentation has shape "
                          f"{seg.shape[:3]}, metadata says {scene.num_frames} frames of {w}×{h}")
    instances = scene.metadata.get("instances", [])
    if seg.max(initial=0) > len(instances):
        raise ExportError(f"{scene.path.name}: segmentation label {int(seg.max())} but only "
                          f"{len(instances)} instances in metadata.json")
    views = scene.metadata["metadata"].get("views")
    amodal = amodal_masks(scene, len(instances))
    images, annotations = [], []
    for i in range(scene.num_frames):
        rgb = f"{scene.prefix}rgba_{i:05d}.png"
        if not (scene.path / rgb).is_file():
            raise ExportError(f"{scene.path.name}: frame {i} has no {rgb}")
        img = {"id": image_id(scene.seed, scene.image_index(i)), "file_name": scene.file(rgb),
               "width": w, "height": h, "scene": scene.path.name, "seed": scene.seed, "frame": i}
        if views:
            img["split"] = views[i].get("split")
        if scene.camera_name:
            img.update(camera_fields(scene.metadata["camera"], i))
            img["camera"] = scene.camera_name
        images.append(img)
        for label in np.unique(seg[i]):
            label = int(label)
            if label == 0:
                continue
            mask = seg[i] == label
            ann = {"id": annotation_id(img["id"], label), "image_id": img["id"],
                   "category_id": scheme.category_id(scene, label - 1),
                   "segmentation": rle.encode(mask, compressed), "area": int(mask.sum()),
                   "bbox": mask_bbox(mask), "iscrowd": 0, "instance": label - 1,
                   "asset_id": instances[label - 1].get("asset_id")}
            if isinstance(instances[label - 1].get("license"), str):
                ann["license"] = instances[label - 1]["license"]  # text; export_coco: an id
            ann.update(scheme.annotation_extras(scene, label - 1, i))
            if amodal is not None:
                ann.update(kins_fields(amodal[i, label - 1], ann, compressed))
            annotations.append(ann)
    return images, annotations


def camera_fields(camera: dict, frame: int) -> dict:
    """A rig camera's image fields: ``intrinsics_pixels`` (3 × 3 OpenCV pixel K, pixel centres
    at +0.5), ``distortion_coefficients`` (OpenCV's order) and ``extrinsics_opencv`` (4 × 4
    world → OpenCV camera, metres) at ``frame``, as ``metadata.json`` records them."""
    out = {"intrinsics_pixels": np.asarray(camera["intrinsics_pixels"], float).tolist(),
           "extrinsics_opencv": np.asarray(camera["extrinsics_opencv"][frame], float).tolist()}
    if "distortion_coefficients" in camera:
        out["distortion_coefficients"] = np.asarray(camera["distortion_coefficients"],
                                                    float).tolist()
    return out


def amodal_masks(scene: Scene, count: int):
    """(T, N, H, W) amodal masks of a scene (camera) made with ``extra_layers=amodal``, else
    None."""
    if not any(scene.path.glob(f"{scene.prefix}amodal_segmentation_*.png")):
        return None
    if count > MAX_MASKS:
        raise ExportError(f"{scene.path.name}: {count} instances; the amodal bit planes hold at "
                          f"most {MAX_MASKS}")
    return unpack_masks(scene.read_layer("amodal_segmentation"), count)


def kins_fields(amodal: np.ndarray, ann: dict, compressed: bool = True) -> dict:
    """KINS's amodal fields (KINS 2020 ``update_*_2020.json``, read by the amodal-instance
    segmentation codebases that train on KINS) of one visible annotation: ``a_segm`` the
    amodal mask as a COCO RLE (pycocotools decodes it, as KINS's polygons), ``a_bbox``
    ``[x, y, w, h]`` pixels, ``a_area``; ``i_segm`` / ``i_bbox`` / ``i_area`` the visible
    (inmodal) ones (= ``segmentation`` / ``bbox`` / ``area``)."""
    return {"a_segm": rle.encode(amodal, compressed), "a_bbox": mask_bbox(amodal),
            "a_area": int(amodal.sum()), "i_segm": ann["segmentation"], "i_bbox": ann["bbox"],
            "i_area": ann["area"]}


def _licence_id(ann: dict, licences: dict, scene: Scene) -> None:
    """Replace the annotation's licence text by its id in COCO's top-level ``licenses``
    (``{"id", "name": the asset's licence and attribution, "url"}``), adding it there."""
    text = ann.pop("license", None)
    if text is None:
        return
    if text not in licences:
        inst = scene.metadata["instances"][ann["instance"]]
        licences[text] = {"id": len(licences) + 1, "name": text,
                          "url": str(inst.get("license_url", ""))}
    ann["license"] = licences[text]["id"]


def _register(scene: Scene, licences: dict) -> list:
    """Every asset of ``scene`` (:mod:`kubric.datasets.exports.licences`), each licence text
    added to COCO's top-level ``licenses`` if not yet there."""
    assets = asset_licences.scene_licences(scene.metadata)
    for a in assets:
        licences.setdefault(a.license, {"id": len(licences) + 1, "name": a.license,
                                        "url": a.url})
    return assets


def _dump(item) -> str:
    return json.dumps(item, separators=(",", ":"), allow_nan=False)


def export_coco(root, out, progress: bool = True, compressed: bool = True,
                sources=()) -> CocoSummary:
    """Write every complete scene under ``root`` (or the scene ``root``) as one COCO file."""
    from tqdm import tqdm

    root = pathlib.Path(root)
    out = pathlib.Path(out)
    if out.is_dir():
        raise OutputError(f"--out {str(out)!r} is a directory; give a file name (.json)")
    if not out.parent.is_dir():
        raise OutputError(f"--out {str(out)!r}: folder {str(out.parent)!r} does not exist")
    paths, skipped = find_scenes(root)
    scheme = scheme_for(load_scene(root, paths[0]), sources)
    info = {"description": f"Kubric scenes exported from {root.resolve().name}",
            "version": "1.0", "categories_from": scheme.kind,
            "id_scheme": "image_id = seed * 10000 + frame (a camera rig's camera c: c * T + "
                         "frame, T frames); id = image_id * 10000 + label"}
    tmp, side = temp_name_for(out), temp_name_for(out.with_name(out.name + ".annotations"))
    n_images = n_annotations = 0
    try:
        with open(tmp, "w", encoding="utf-8") as main, open(side, "w+", encoding="utf-8") as anns:
            main.write('{"info":' + _dump(info) + ',"categories":'
                       + _dump(scheme.categories) + ',"images":[')
            licences: dict[str, dict] = {}
            assets: list = []
            first_scene = None
            with tqdm(total=len(paths), unit="scene", desc="export coco", file=sys.stderr,
                      disable=not progress) as bar:
                for path in paths:
                    scene = load_scene(root, path)
                    if first_scene is None:
                        first_scene = scene.recipe
                    elif scene.recipe != first_scene:
                        raise ExportError(f"{path.name}: recipe {scene.recipe!r} differs from "
                                          f"the first scene's {first_scene!r}; export each "
                                          "recipe's scenes separately")
                    for view in camera_views(scene):
                        scheme.check(view)
                    images, annotations = scene_records(scene, scheme, compressed)
                    for item in images:
                        main.write(("," if n_images else "") + _dump(item))
                        n_images += 1
                    for item in annotations:
                        _licence_id(item, licences, scene)
                        anns.write(("," if n_annotations else "") + _dump(item))
                        n_annotations += 1
                    assets.append(_register(scene, licences))
                    bar.update(1)
                    faults.point("export.scene_written")
            main.write('],"annotations":[')
            anns.seek(0)
            shutil.copyfileobj(anns, main, 1 << 16)
            attribution = [{**a.to_json(), "license_id": licences[a.license]["id"]}
                           for a in asset_licences.merged(assets)]
            main.write('],"licenses":' + _dump(list(licences.values())) + ',"attribution":'
                       + _dump(attribution) + "}\n")
        os.replace(tmp, out)
    finally:
        for p in (tmp, side):
            if p.exists():
                p.unlink()
    return CocoSummary(out, len(paths), n_images, n_annotations, scheme.names, scheme.kind,
                       skipped)


__all__ = ["CocoSummary", "camera_fields", "camera_records", "export_coco", "mask_bbox",
           "scene_records"]
