"""The MOVi recipes' output contract (one :class:`~kubric.io.schema.Schema` per variant).

Feature names and dtypes are those of upstream's published MOVi TFDS datasets (version 1.0.0),
so code written for them reads ours; features marked *addition* are new names (per-frame camera
matrices, pixel intrinsics, the seed, ...). Differences in storage, not in values: upstream stored
``video`` / ``normal`` / ``object_coordinates`` as ``tfds.features.Video`` (needs TensorFlow to
declare); here they are sequences of PNG images, which decode to the same arrays. A–F share
:data:`MOVI_BASE`; each variant adds its instance extras.
"""

from __future__ import annotations

from kubric.annotations.tracks import PACKED_TRACK_FIELDS
from kubric.assets import clevr
from kubric.io.scene_dir import TRACKS_FILE
from kubric.io.schema import Feature, Schema, register_schema

F = Feature
_T3, _T4 = ("T", 3), ("T", 4)
ADD = "Addition: "
#: the camera's lens features, the same in every schema (MOVi, multi-view, vbr)
CAMERA_LENS = (
    F("camera/focal_length", "float32", (), "camera:focal_length", unit="mm",
      doc="lens focal length"),
    F("camera/sensor_width", "float32", (), "camera:sensor_width", unit="mm",
      doc="sensor width"),
    F("camera/field_of_view", "float32", (), "camera:field_of_view", unit="rad",
      doc="horizontal"),
    F("camera/distortion_model", "str", (), "camera:distortion_model", "text",
      doc=ADD + "lens model: none, opencv (Brown-Conrady) or fisheye (Kannala-Brandt)"),
    F("camera/distortion_coefficients", "float32", (8,), "camera:distortion_coefficients",
      doc=ADD + "OpenCV's order (opencv: k1,k2,p1,p2,k3,k4,k5,k6; fisheye: k1..k4, then 0)"),
)

MOVI_BASE = Schema("movi", (
    # ---------------------------------------------------------------- metadata
    F("metadata/video_name", "str", (), "scene_name", "text", doc="scene id (directory name)"),
    F("metadata/width", "int32", (), "meta:resolution.0", unit="px", doc="image width W"),
    F("metadata/height", "int32", (), "meta:resolution.1", unit="px", doc="image height H"),
    F("metadata/num_frames", "int32", (), "meta:num_frames", doc="rendered frames T"),
    F("metadata/num_instances", "uint16", (), "meta:num_instances",
      doc="instances N (segmentation labels 1..N)"),
    F("metadata/depth_range", "float32", (2,), "range:depth", unit="m",
      doc="min, max of depth: depth = q / 65535 · (max − min) + min"),
    F("metadata/forward_flow_range", "float32", (2,), "range:forward_flow", unit="px",
      doc="min, max of forward_flow (same decoding)"),
    F("metadata/backward_flow_range", "float32", (2,), "range:backward_flow", unit="px",
      doc="min, max of backward_flow (same decoding)"),
    F("metadata/seed", "int64", (), "meta:seed", doc=ADD + "the scene's seed"),
    F("metadata/frame_rate", "int32", (), "meta:frame_rate", unit="1/s", doc=ADD + "frames per s"),
    # ---------------------------------------------------------------- instances
    F("instances/asset_id", "str", (), "instance:asset_id", "text",
      doc="asset id (addition for A/B)"),
    F("instances/mass", "float32", (), "instance:mass", unit="kg", doc="mass"),
    F("instances/friction", "float32", (), "instance:friction",
      doc="Coulomb friction coefficient"),
    F("instances/restitution", "float32", (), "instance:restitution",
      doc="restitution (bounciness)"),
    F("instances/positions", "float32", _T3, "instance:positions", unit="m",
      doc="centre of mass, world frame"),
    F("instances/quaternions", "float32", _T4, "instance:quaternions", doc="WXYZ"),
    F("instances/velocities", "float32", _T3, "instance:velocities", unit="m/s",
      doc="linear velocity per frame, world frame"),
    F("instances/angular_velocities", "float32", _T3, "instance:angular_velocities",
      unit="rad/s", doc="angular velocity per frame, world frame"),
    F("instances/bboxes_3d", "float32", ("T", 8, 3), "instance:bboxes_3d", unit="m",
      doc="world corners of the scaled local box; corner order (x, y, z) ∈ {min, max}³"),
    F("instances/image_positions", "float32", ("T", 2), "instance:image_positions",
      doc="projected centre, normalised (x, y), y down"),
    F("instances/bboxes", "float32", ("V", 4), "instance:bboxes", "bbox",
      doc="normalised (ymin, xmin, ymax, xmax) in the frames where visible"),
    F("instances/bbox_frames", "int32", ("V",), "instance:bbox_frames",
      doc="the frames of bboxes"),
    F("instances/visibility", "uint16", ("T",), "instance:visibility", unit="px",
      doc="visible pixels per frame"),
    # ---------------------------------------------------------------- camera
    *CAMERA_LENS,
    F("camera/positions", "float32", _T3, "camera:positions", unit="m",
      doc="camera centre per frame, world frame"),
    F("camera/quaternions", "float32", _T4, "camera:quaternions", doc="WXYZ"),
    F("camera/matrices_world", "float32", ("T", 4, 4), "camera:matrices_world",
      doc=ADD + "camera → world, Blender camera axes (x right, y up, looking down −z)"),
    F("camera/intrinsics_pixels", "float32", (3, 3), "camera:intrinsics_pixels", unit="px",
      doc=ADD + "OpenCV pixel intrinsics (x right, y down, +z forward; pixel centres +0.5)"),
    F("camera/extrinsics_opencv", "float32", ("T", 4, 4), "camera:extrinsics_opencv",
      doc=ADD + "world → OpenCV camera (x right, y down, looking down +z) per frame"),
    F("camera/K", "float32", (3, 3), "camera:K",
      doc=ADD + "upstream's normalised intrinsics"),
    # ---------------------------------------------------------------- events
    F("events/collisions/instances", "uint16", (2,), "collision:instances",
      convert="negative_to_uint16_max", doc="instance indices; 65535 = floor / other"),
    F("events/collisions/frame", "int32", (), "collision:frame", convert="floor",
      doc="frame the collision falls in"),
    F("events/collisions/force", "float32", (), "collision:force", unit="N",
      doc="largest normal force of the event"),
    F("events/collisions/position", "float32", (3,), "collision:position", unit="m",
      doc="contact point, world frame"),
    F("events/collisions/image_position", "float32", (2,), "collision:image_position",
      doc="normalised (x, y), projected at the event's frame"),
    F("events/collisions/contact_normal", "float32", (3,), "collision:contact_normal",
      doc="unit contact normal, world frame"),
    # ---------------------------------------------------------------- dense layers
    F("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png", doc="RGB (alpha dropped)"),
    F("segmentations", "uint8", ("T", "H", "W", 1), "layer:segmentation", "png",
      doc="0 = background, k = instances[k − 1]"),
    F("forward_flow", "uint16", ("T", "H", "W", 2), "layer:forward_flow", "zlib", unit="px",
      doc="(Δrow, Δcol) to the next frame, scaled by metadata/forward_flow_range"),
    F("backward_flow", "uint16", ("T", "H", "W", 2), "layer:backward_flow", "zlib", unit="px",
      doc="(Δrow, Δcol) to the previous frame, scaled by metadata/backward_flow_range"),
    F("depth", "uint16", ("T", "H", "W", 1), "layer:depth", "png", unit="m",
      doc="distance to the camera centre, scaled by metadata/depth_range"),
    F("normal", "uint16", ("T", "H", "W", 3), "layer:normal", "png",
      doc="world-space unit normal n stored as (n + 1) / 2 · 65535"),
    F("object_coordinates", "uint16", ("T", "H", "W", 3), "layer:object_coordinates", "png",
      doc="surface point in the object's box, [0, 1]³ · 65535"),
), description="Shared by MOVi-A … F.")

#: class names (label order) of the CLEVR / KuBasic features, from :mod:`kubric.assets.clevr`
SHAPES_B = clevr.KUBASIC_SHAPES
COLORS = tuple(clevr.COLORS)
MATERIALS = tuple(clevr.MATERIALS)

MOVI_A = register_schema(MOVI_BASE.extend("movi_a", (
    F("instances/shape_label", "int64", (), "instance:shape", "class_label",
      names=clevr.SHAPES, doc="CLEVR shape"),
    F("instances/size_label", "int64", (), "instance:size_label", "class_label",
      names=tuple(clevr.SIZES), doc=f"CLEVR size: scale {clevr.SIZES['small']} (small) or "
      f"{clevr.SIZES['large']} (large)"),
    F("instances/color", "float32", (3,), "instance:color", doc="linear RGB"),
    F("instances/color_label", "int64", (), "instance:color_label", "class_label", names=COLORS,
      doc="CLEVR colour name"),
    F("instances/material_label", "int64", (), "instance:material", "class_label",
      names=MATERIALS, doc="metal or rubber"),
), description="MOVi-A: CLEVR shapes, 8 colours, 2 sizes, metal / rubber."))

MOVI_B = register_schema(MOVI_BASE.extend("movi_b", (
    F("instances/shape_label", "int64", (), "instance:shape", "class_label", names=SHAPES_B,
      doc="KuBasic shape"),
    F("instances/color", "float32", (3,), "instance:color", doc="linear RGB"),
    F("instances/material_label", "int64", (), "instance:material", "class_label",
      names=MATERIALS, doc="metal or rubber"),
    F("instances/size", "float32", (), "instance:size", doc=ADD + "object scale"),
    F("background_color", "float32", (3,), "meta:background", convert="hex_to_rgb",
      doc="dome colour"),
), description="MOVi-B: 11 KuBasic shapes, random hue, random scale."))

#: upstream MOVi-C–F's ``instances/category`` class names (the Google Scanned Objects
#: categories, "None" for an uncategorised object), in label order
GSO_CATEGORIES = ("Action Figures", "Bag", "Board Games", "Bottles and Cans and Cups", "Camera",
                  "Car Seat", "Consumer Goods", "Hat", "Headphones", "Keyboard", "Legos",
                  "Media Cases", "Mouse", "None", "Shoe", "Stuffed Toys", "Toys")
#: the instance metadata field (metadata.json) holding an instance's GSO_CATEGORIES name
MOVI_CATEGORY = "movi_category"


def movi_category(metadata) -> str:
    """An instance's ``instances/category`` name: its asset's ``category`` (or else the first of
    its ``categories``) that is one of :data:`GSO_CATEGORIES`; "None" when neither is (an
    uncategorised asset, or one of another collection, e.g. pybullet_data's "random_urdfs")."""
    extra = metadata.get("categories")
    candidates = [metadata.get("category"), *(extra if isinstance(extra, list | tuple) else ())]
    return next((str(c) for c in candidates if str(c) in GSO_CATEGORIES), "None")


_C_EXTRAS = (
    F("background", "str", (), "meta:background", "text", doc="HDRI id"),
    F("instances/category", "int64", (), f"instance:{MOVI_CATEGORY}", "class_label",
      names=GSO_CATEGORIES, doc="upstream's GSO category of the asset (the asset source's "
      "category; \"None\" where that is not one of these)"),
    F("instances/scale", "float32", (), "instance:scale", unit="m", doc="largest extent"),
    F("instances/is_dynamic", "bool", (), "instance:is_dynamic",
      doc="moves in the simulation (false for settled static objects)"),
)
MOVI_C = register_schema(MOVI_BASE.extend("movi_c", _C_EXTRAS,
                                          description="MOVi-C: mesh objects on an HDRI dome."))
MOVI_D = register_schema(MOVI_C.extend("movi_d", description="MOVi-D: settled static objects "
                                       "and a few dynamic ones."))
MOVI_E = register_schema(MOVI_C.extend("movi_e", description="MOVi-E: as D, moving camera."))
MOVI_F = register_schema(MOVI_C.extend("movi_f", (
    F("metadata/motion_blur", "float32", (), "meta:motion_blur", unit="frames",
      doc="shutter length (0 = no motion blur), drawn U(0, max_motion_blur)"),
), description="MOVi-F: as E, motion blur."))

#: Point tracks (``tracks.npz``, written with ``--set tracks=N``; docs/tracks.md). Every MOVi
#: variant has a ``<name>_tracks`` schema with these features: pack with
#: ``kubric pack DIR --schema movi_e_tracks`` and read with the ``point_tracks`` task.
TRACK_FEATURES = tuple(F(f"tracks/{key}", dtype, shape, f"npz:{TRACKS_FILE}:{key}", unit=unit,
                         doc=doc) for key, dtype, shape, unit, doc in PACKED_TRACK_FIELDS)
MOVI_TRACKS = {schema.name: register_schema(schema.extend(
    f"{schema.name}_tracks", TRACK_FEATURES,
    description=f"{schema.description} With point tracks (tracks.npz)."))
    for schema in (MOVI_A, MOVI_B, MOVI_C, MOVI_D, MOVI_E, MOVI_F)}
