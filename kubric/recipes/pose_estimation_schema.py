"""The ``pose_estimation`` recipe's output contract: MOVi's features plus COCO keypoints per
person instance (docs/characters.md), and a ``pose_estimation_tracks`` variant with the point
tracks (``tracks.npz``)."""

from __future__ import annotations

from kubric.io.schema import Feature as F
from kubric.io.schema import register_schema
from kubric.recipes.movi_schema import MOVI_BASE, TRACK_FEATURES

_K = ("T", 17)
SCHEMA = register_schema(MOVI_BASE.extend("pose_estimation", (
    F("instances/keypoints_2d", "float32", _K + (2,), "instance:keypoints_2d", unit="px",
      doc="COCO keypoints (x, y) per frame, pixel centres at +0.5"),
    F("instances/keypoints_3d", "float32", _K + (3,), "instance:keypoints_3d", unit="m",
      doc="COCO keypoints per frame, world frame"),
    F("instances/keypoints_camera", "float32", _K + (3,), "instance:keypoints_camera",
      unit="m", doc="COCO keypoints per frame, camera frame (Blender axes)"),
    F("instances/keypoints_visibility", "uint8", _K, "instance:keypoints_visibility",
      doc="COCO flag: 0 outside the image, 1 occluded, 2 visible"),
), description="pose_estimation: people performing motion clips in a random room, COCO "
   "keypoints per person per frame."))
TRACKS_SCHEMA = register_schema(SCHEMA.extend(
    "pose_estimation_tracks", TRACK_FEATURES,
    description=f"{SCHEMA.description} With point tracks (tracks.npz)."))
