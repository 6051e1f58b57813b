"""Loader tasks of the multi-view datasets (``klevr``, ``toybox``, ``texture_nerf``,
``robust_nerf``, ``multiview_matting``, ``nvs``, ``complex_brdf``, ``svr``; schemas in
:mod:`kubric.recipes.multiview_schema`). Importing :mod:`kubric.datasets.tasks` registers them.

Camera conventions (both tasks):

* ``intrinsics_pixels`` (3, 3): OpenCV pinhole intrinsics in pixels — camera axes x right,
  y down, +z forward; image origin at the top-left corner, pixel (row r, col c) centred at
  (c + 0.5, r + 0.5);
* ``camera_to_world`` (4, 4): camera → world in **Blender / OpenGL camera axes** (x right, y up,
  looking down −z), world z up, metres — the ``transform_matrix`` of the scene's NeRF
  ``transforms_*.json`` files;
* ``world_to_camera`` (4, 4): world → camera in **OpenCV axes**, i.e.
  ``diag(1, −1, −1, 1) · inverse(camera_to_world)``, so a world point X lands on pixel
  ``(u, v) = (p_x / p_z, p_y / p_z)`` with ``p = intrinsics_pixels · (world_to_camera · X)[:3]``.

``multiview`` — one item per scene (all its views, or those of one split):

* ``scene_name``; ``views`` (V,) int32 view indices; ``split`` (V,) uint8 (0 train, 1 val,
  2 test, as ``transforms_{train,val,test}.json``);
* ``images`` (V, H, W, 3) uint8; ``intrinsics_pixels`` (3, 3); ``camera_to_world`` and
  ``world_to_camera`` (V, 4, 4) float32;
* the layers named by option ``layers`` (default: those of ``depth``, ``segmentation``,
  ``semantic``, ``alpha`` the dataset has): ``depth`` (V, H, W) float32 metres (distance to the
  camera centre along the pixel's ray), ``segmentation`` (V, H, W) uint8 (0 background,
  k = instance k − 1), ``semantic`` → ``semantic_segmentation`` (V, H, W) uint8 (0 background,
  k = ``semantic_classes[k]``) plus ``semantic_classes`` (list of names) — KLEVR / ToyBox —,
  ``alpha`` (V, H, W) uint8 (svr), ``normal`` (V, H, W, 3) float32 in [−1, 1] (world frame),
  ``object_coordinates`` (V, H, W, 3) float32 in [0, 1];
* options: ``view_split`` (``"train"``, ``"val"`` or ``"test"``: only the views of that split
  of the scene's ``split_ratio``; the dataset split is ``load``'s ``split``) and ``layers``.

``svr`` — one item per (scene, view) of an ``svr`` dataset:

* ``image`` (H, W, 4) uint8 RGBA, alpha 0 on the transparent background (the scene's PNG);
* ``category`` (str) and ``category_id`` (int64): the asset's category and its index in
  ``schema["instances/category"].names`` — the sorted categories of all scenes packed into the
  dataset (stored in the dataset; TFDS's ``ClassLabel`` gives the same mapping);
* ``asset_id`` (str); ``intrinsics_pixels``, ``camera_to_world``, ``world_to_camera`` as above;
* ``object_position`` (3,) metres and ``object_quaternion`` (4,) WXYZ: the object's pose (world
  frame; the same in every view); ``view`` int32, ``split`` uint8, ``scene_name``.
"""

from __future__ import annotations

import numpy as np

from kubric.datasets.layout import DatasetError
from kubric.datasets.task_registry import register_task

#: ``multiview`` layer option → (top-level feature, key in the item)
MULTIVIEW_LAYERS = {
    "depth": ("depth", "depth"),
    "segmentation": ("segmentations", "segmentation"),
    "semantic": ("semantic_segmentations", "semantic_segmentation"),
    "alpha": ("alpha", "alpha"),
    "normal": ("normal", "normal"),
    "object_coordinates": ("object_coordinates", "object_coordinates"),
}
DEFAULT_LAYERS = ("depth", "segmentation", "semantic", "alpha")
#: the layers given as float32 decoded by their layer kind, with their channels
FLOAT_LAYERS = ("normal", "object_coordinates")
SPLIT_NAMES = ("train", "val", "test")
#: Blender / OpenGL camera axes → OpenCV camera axes
BLENDER_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
_CAMERA = ("video", "camera/intrinsics_pixels", "camera/matrices_world", "views/split",
           "metadata/video_name")


def world_to_camera_opencv(camera_to_world: np.ndarray) -> np.ndarray:
    """(…, 4, 4) camera → world (Blender camera axes) → world → camera in OpenCV axes
    (float32, computed in float64)."""
    matrices = np.linalg.inv(np.asarray(camera_to_world, np.float64))
    return (BLENDER_TO_OPENCV @ matrices).astype(np.float32)


def _top_level(schema) -> set[str]:
    return {f.name.split("/", 1)[0] for f in schema.features}


def _layers(schema, options: dict) -> list[str]:
    """The layer names option ``layers`` selects (checked against the dataset)."""
    top = _top_level(schema)
    layers = options.get("layers")
    if layers is None:
        return [name for name in DEFAULT_LAYERS if MULTIVIEW_LAYERS[name][0] in top]
    layers = [layers] if isinstance(layers, str) else list(layers)
    unknown = [name for name in layers if name not in MULTIVIEW_LAYERS]
    if unknown:
        raise DatasetError(f"task 'multiview': layers {unknown} are not among "
                           f"{list(MULTIVIEW_LAYERS)}")
    absent = [name for name in layers if MULTIVIEW_LAYERS[name][0] not in top]
    if absent:
        have = [n for n, (feature, _) in MULTIVIEW_LAYERS.items() if feature in top]
        raise DatasetError(f"task 'multiview': this {schema.name} dataset has no layers "
                           f"{absent}; it has {have}")
    return layers


def _check_view_split(view_split) -> None:
    if view_split is not None and view_split not in SPLIT_NAMES:
        raise DatasetError(f"task 'multiview': view_split {view_split!r} is not one of "
                           f"{SPLIT_NAMES} (or None for every view)")


def _multiview_features(schema, options: dict) -> tuple[str, ...]:
    """The optional layers to decode; checks the options when the source is made."""
    _check_view_split(options.get("view_split"))
    return tuple(MULTIVIEW_LAYERS[name][0] for name in _layers(schema, options))


def _views(example: dict, view_split) -> np.ndarray:
    splits = np.asarray(example["views"]["split"])
    if view_split is None:
        return np.arange(len(splits))
    _check_view_split(view_split)
    return np.flatnonzero(splits == SPLIT_NAMES.index(view_split))


@register_task("multiview", features=("video", "camera", "views", "metadata"),
               options=("view_split", "layers"), requires=_CAMERA,
               extra_features=_multiview_features, wants_schema=True)
def multiview_task(example, frame, schema, view_split=None, layers=None):
    """All views of a scene (or one split's): images, cameras, optional layers."""
    views = _views(example, view_split)
    camera = example["camera"]
    to_world = camera["matrices_world"][views]
    item = {"scene_name": example["metadata"]["video_name"], "views": views.astype(np.int32),
            "split": example["views"]["split"][views].astype(np.uint8),
            "images": example["video"][views],
            "intrinsics_pixels": camera["intrinsics_pixels"].copy(),
            "camera_to_world": to_world.copy(),
            "world_to_camera": world_to_camera_opencv(to_world)}
    for name in _layers(schema, {"layers": layers} if layers is not None else {}):
        feature, key = MULTIVIEW_LAYERS[name]
        value = example[feature][views]
        kind = schema.layer_kind(feature)[1]
        # float layers (normal, object coordinates) keep C; the others are one channel
        item[key] = kind.decode(value, None, feature) if name in FLOAT_LAYERS else value[..., 0]
        if name == "semantic":
            item["semantic_classes"] = list(example["metadata"]["semantic_classes"])
    return item


@register_task("svr", features=("video", "alpha", "camera", "views", "instances", "metadata"),
               per_frame=True, wants_schema=True,
               requires=_CAMERA + ("alpha", "instances/category", "instances/asset_id",
                                   "instances/positions", "instances/quaternions"))
def svr_task(example, frame, schema):
    """One view of the object: RGBA image, category (name, id), camera, object pose."""
    instances = example["instances"]
    if len(instances["category"]) != 1:
        raise DatasetError(f"task 'svr': scene {example['metadata']['video_name']!r} holds "
                           f"{len(instances['category'])} instances, expected exactly 1")
    names = schema["instances/category"].names
    category_id = np.int64(instances["category"][0])
    camera = example["camera"]
    to_world = camera["matrices_world"][frame]
    image = np.concatenate([example["video"][frame], example["alpha"][frame]], axis=-1)
    return {"image": image, "category": names[category_id], "category_id": category_id,
            "asset_id": instances["asset_id"][0],
            "intrinsics_pixels": camera["intrinsics_pixels"].copy(),
            "camera_to_world": to_world.copy(),
            "world_to_camera": world_to_camera_opencv(to_world),
            "object_position": instances["positions"][0, frame].copy(),
            "object_quaternion": instances["quaternions"][0, frame].copy(),
            "view": np.int32(frame), "split": np.uint8(example["views"]["split"][frame]),
            "scene_name": example["metadata"]["video_name"]}
