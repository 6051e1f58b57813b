"""The multi-view recipes' output contract (one :class:`~kubric.io.schema.Schema` per recipe).

A multi-view scene is one static scene seen from ``num_views`` cameras; view ``i`` is frame ``i``
of the scene directory, so the dimension ``T`` of these schemas counts **views**. Every recipe
shares :data:`MULTIVIEW_BASE` (scene metadata, the per-view split, the camera of every view, the
instances, RGB, instance segmentation, exact depth, normals, object coordinates) and adds the
layers and instance fields it writes (:mod:`kubric.recipes.multiview_base` and the recipe
modules). Names follow the MOVi schemas where the meaning is the same (``video``,
``segmentations``, ``camera/matrices_world``, ``metadata/video_name``), so the ``video``,
``frames`` and ``nerf_rays`` tasks read multi-view datasets too; ``multiview`` (all views of a
scene) and ``svr`` (one view of the object) are theirs (:mod:`kubric.datasets.tasks`).

Differences from MOVi: ``depth`` is stored as the scene's float32 samples (zlib), bit-exact, not
quantised to uint16 (pixels that see no surface hold ``metadata/background_depth``); there are
no flows, no physics fields and no collision events (nothing moves).
"""

from __future__ import annotations

from kubric.io.layers import LayerFormat
from kubric.io.schema import NAMES_FROM_SCENES, Feature, Schema, register_schema
from kubric.recipes.movi_schema import CAMERA_LENS

F = Feature
_T3, _T4 = ("T", 3), ("T", 4)
_LABELS = "labels"

MULTIVIEW_BASE = Schema("multiview", (
    # ---------------------------------------------------------------- metadata
    F("metadata/video_name", "str", (), "scene_name", "text",
      doc="scene id (directory name; named as MOVi's so every task finds it)"),
    F("metadata/width", "int32", (), "meta:resolution.0", unit="px", doc="image width W"),
    F("metadata/height", "int32", (), "meta:resolution.1", unit="px", doc="image height H"),
    F("metadata/num_views", "int32", (), "meta:num_views", doc="views T (view i = frame i)"),
    F("metadata/num_instances", "uint16", (), "meta:num_instances",
      doc="instances N (segmentation labels 1..N)"),
    F("metadata/seed", "int64", (), "meta:seed", doc="the scene's seed"),
    F("metadata/background", "str", (), "meta:background", "text",
      doc="HDRI id, dome colour '#rrggbbaa', 'transparent' or 'black'"),
    F("metadata/background_depth", "float32", (), "meta:background_depth", unit="m",
      doc="depth of pixels whose ray hits no surface"),
    F("metadata/look_at", "float32", (3,), "meta:look_at", unit="m",
      doc="the point every camera looks at, world frame"),
    F("metadata/dropped_objects", "int32", (), "meta:dropped_objects",
      doc="objects left out for want of a free place"),
    F("views/split", "uint8", ("T",), "meta:views", convert="split_index",
      doc="split of each view: 0 train, 1 val, 2 test (as transforms_{train,val,test}.json)"),
    # ---------------------------------------------------------------- camera
    *CAMERA_LENS,
    F("camera/positions", "float32", _T3, "camera:positions", unit="m",
      doc="camera centre per view, world frame"),
    F("camera/quaternions", "float32", _T4, "camera:quaternions",
      doc="camera orientation per view, WXYZ (Blender camera axes)"),
    F("camera/matrices_world", "float32", ("T", 4, 4), "camera:matrices_world",
      doc="camera → world per view, Blender camera axes (x right, y up, looking down −z): "
          "the transform_matrix of transforms_*.json"),
    F("camera/intrinsics_pixels", "float32", (3, 3), "camera:intrinsics_pixels", unit="px",
      doc="OpenCV pixel intrinsics (x right, y down, +z forward; pixel centres +0.5)"),
    F("camera/K", "float32", (3, 3), "camera:K", doc="upstream's normalised intrinsics"),
    # ---------------------------------------------------------------- instances
    F("instances/asset_id", "str", (), "instance:asset_id", "text", doc="asset id"),
    F("instances/size", "float32", (), "instance:size",
      doc="largest extent (m), or the KuBasic scale for KuBasic shapes"),
    F("instances/positions", "float32", _T3, "instance:positions", unit="m",
      doc="position per view, world frame (static: the same in every view, except "
          "robust_nerf's impostors)"),
    F("instances/quaternions", "float32", _T4, "instance:quaternions",
      doc="orientation per view, WXYZ"),
    F("instances/bboxes_3d", "float32", ("T", 8, 3), "instance:bboxes_3d", unit="m",
      doc="world corners of the scaled local box; corner order (x, y, z) ∈ {min, max}³"),
    F("instances/image_positions", "float32", ("T", 2), "instance:image_positions",
      doc="projected centre, normalised (x, y), y down"),
    F("instances/bboxes", "float32", ("V", 4), "instance:bboxes", "bbox",
      doc="normalised (ymin, xmin, ymax, xmax) in the views where visible"),
    F("instances/bbox_frames", "int32", ("V",), "instance:bbox_frames",
      doc="the views of bboxes"),
    F("instances/visibility", "uint16", ("T",), "instance:visibility", unit="px",
      doc="visible pixels per view"),
    # ---------------------------------------------------------------- dense layers
    F("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png",
      doc="RGB of each view (alpha dropped)"),
    F("segmentations", "uint8", ("T", "H", "W", 1), "layer:segmentation", "png",
      doc="0 = background, k = instances[k − 1]"),
    F("depth", "float32", ("T", "H", "W", 1), "layer:depth", "zlib", unit="m",
      doc="distance to the camera centre along the pixel's ray, the scene's float32 samples"),
    F("normal", "uint16", ("T", "H", "W", 3), "layer:normal", "png",
      doc="world-space unit normal n stored as (n + 1) / 2 · 65535"),
    F("object_coordinates", "uint16", ("T", "H", "W", 3), "layer:object_coordinates", "png",
      doc="surface point in the object's box, [0, 1]³ · 65535"),
), description="Shared by the multi-view recipes; T counts views.")

_COLOR = F("instances/color", "float32", (3,), "instance:color", doc="linear RGB")
_SEMANTIC = (
    F("semantic_segmentations", "uint8", ("T", "H", "W", 1), "layer:semantic", "png",
      doc="semantic class per pixel: 0 = background, k = metadata/semantic_classes[k]"),
    F("metadata/semantic_classes", "str", ("C",), "meta:semantic_classes", "text",
      doc="class names; index 0 is 'background'"),
    F("instances/category", "str", (), "instance:category", "text",
      doc="the object's semantic class name"),
    F("instances/semantic_id", "int32", (), "instance:semantic_id",
      doc="its index in metadata/semantic_classes"),
)
_SEMANTIC_LAYER = {"semantic": LayerFormat("semantic_{:05d}.png", 1, _LABELS)}


def _register(name: str, features=(), layers=None, description: str = "") -> Schema:
    return register_schema(MULTIVIEW_BASE.extend(name, features, layers, description))


KLEVR = _register("klevr", _SEMANTIC + (_COLOR,), _SEMANTIC_LAYER,
                  "KLEVR: upright KuBasic shapes on a grey floor, semantic labels.")
TOYBOX = _register("toybox", _SEMANTIC, _SEMANTIC_LAYER,
                   "ToyBox5 / ToyBox13: categorised objects on an HDRI, semantic labels.")
TEXTURE_NERF = _register("texture_nerf", (
    F("bands", "uint8", ("T", "H", "W", 1), "layer:band", "png",
      doc="band label: 0 = no cube, k = interval k − 1 of metadata/bands"),
    F("cutoff_frequencies", "float32", ("T", "H", "W", 1), "layer:cutoff", "zlib",
      doc="cut-off (cycles per face) of the cube the pixel sees, 0 elsewhere"),
    F("metadata/bands", "float32", ("B", 2), "meta:bands",
      doc="cut-off intervals [low, high) of the band labels (cycles per face)"),
    F("instances/cutoff_frequency", "float32", (), "instance:cutoff_frequency",
      doc="texture cut-off (cycles per face)"),
    F("instances/band", "int32", (), "instance:band", doc="band label (1-based)"),
), {"band": LayerFormat("band_{:05d}.png", 1, _LABELS),
    "cutoff": LayerFormat("cutoff_{:05d}.tiff", 1, "tiff")},
    "Texture-structure NeRF: cubes with band-limited textures of known cut-off.")
ROBUST_NERF = _register("robust_nerf", (
    F("impostor_masks", "uint8", ("T", "H", "W", 1), "layer:impostor_mask", "png",
      doc="1 where an impostor is visible"),
    F("instances/is_impostor", "bool", (), "instance:is_impostor",
      doc="moves between train views"),
    F("instances/present", "bool", ("T",), "instance:present",
      doc="in the scene in this view (impostors: train views only)"),
    F("instances/shape", "str", (), "instance:shape", "text", doc="KuBasic shape"),
    _COLOR,
), {"impostor_mask": LayerFormat("impostor_mask_{:05d}.png", 1, _LABELS)},
    "Robust NeRF: a static scene plus impostors in the train views.")
MULTIVIEW_MATTING = _register("multiview_matting", (
    F("masks", "uint8", ("T", "H", "W", 1), "layer:mask", "png",
      doc="1 where the salient object is visible"),
    F("instances/is_salient", "bool", (), "instance:is_salient", doc="the salient object"),
), {"mask": LayerFormat("mask_{:05d}.png", 1, _LABELS)},
    "Multi-view object matting: one salient object (and clutter) on an HDRI.")
NVS = _register("nvs", description="Conditional novel view synthesis: objects on an HDRI.")
COMPLEX_BRDF = _register("complex_brdf", (
    F("instances/material", "int64", (), "instance:material", "class_label",
      names=("metal", "rubber"), doc="specular metal or Lambertian rubber"),
    _COLOR,
    F("metadata/lights", "float32", (3, 3), "meta:lights", unit="m",
      doc="positions of the three point lights"),
), description="Complex BRDFs: one metal or rubber object, 3 point lights, fixed orbit.")
SVR = _register("svr", (
    F("alpha", "uint8", ("T", "H", "W", 1), "layer:rgba[3:4]", "png",
      doc="alpha of each view: 0 = transparent background"),
    F("instances/category", "int64", (), "instance:category", "class_label",
      names=NAMES_FROM_SCENES,
      doc="the asset's category; ids index the sorted categories of the packed scenes"),
    F("instances/asset_index", "int32", (), "instance:asset_index",
      doc="index of the asset among the source's assets of the recipe's split"),
), description="Single-view reconstruction / pre-training: one object, random views, "
               "transparent background.")

POINTS_FILE = "points.npz"
#: The labelled point cloud of KLEVR / ToyBox (``points.npz``, written unless
#: ``write_points=false``): pack with ``kubric pack DIR --schema klevr_points`` (or
#: ``toybox_points``) to add these features.
POINT_FEATURES = (
    F("points/xyz", "float32", ("P", 3), f"npz:{POINTS_FILE}:xyz", unit="m",
      doc="surface point of every pixel that sees a surface, world frame"),
    F("points/rgb", "uint8", ("P", 3), f"npz:{POINTS_FILE}:rgb", doc="its RGB"),
    F("points/class", "uint16", ("P",), f"npz:{POINTS_FILE}:class",
      doc="its semantic class (index in metadata/semantic_classes)"),
    F("points/instance", "uint16", ("P",), f"npz:{POINTS_FILE}:instance",
      doc="its segmentation label (0 = background, k = instances[k − 1])"),
    F("points/view", "uint16", ("P",), f"npz:{POINTS_FILE}:view", doc="the view it was seen in"),
    F("points/pixel", "uint16", ("P", 2), f"npz:{POINTS_FILE}:pixel", unit="px",
      doc="(row, col) of its pixel in that view"),
)
POINT_SCHEMAS = {s.name: register_schema(s.extend(
    f"{s.name}_points", POINT_FEATURES, description=f"{s.description} With the labelled point "
    "cloud (points.npz).")) for s in (KLEVR, TOYBOX)}

#: the schemas by recipe name
MULTIVIEW_SCHEMAS = {s.name: s for s in (KLEVR, TOYBOX, TEXTURE_NERF, ROBUST_NERF,
                                         MULTIVIEW_MATTING, NVS, COMPLEX_BRDF, SVR)}
