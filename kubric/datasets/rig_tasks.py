"""Loader tasks of camera-rig datasets (scenes made with ``--set cameras=stereo|ring``;
:mod:`kubric.recipes.rig_options`). Importing :mod:`kubric.datasets.tasks` registers them.
A rig dataset's further cameras are the features ``cameras/NAME/...`` (nested:
``example["cameras"][NAME]["video"]``); the reference camera's are the usual top-level ones.

``stereo`` — one item per (scene, frame) of a stereo dataset:

* ``left``, ``right`` (H, W, 3) uint8: the rectified pair's images;
* ``disparity`` (H, W) float32 pixels of the left image: x_left − x_right, f·B/Z (0 where
  nothing is hit);
* ``baseline`` metres, ``intrinsics_pixels`` (3, 3) OpenCV (shared by both cameras),
  ``left_camera_to_world`` / ``right_camera_to_world`` (4, 4, Blender camera axes), ``frame``,
  ``video_name``.

``multicamera_video`` — one item per scene of any rig dataset, with a **camera axis** first:

* ``video`` (C, T, H, W, 3) uint8, the reference camera first, then ``cameras/...`` in the
  dataset's order (``camera_names`` (C,): ``reference`` then the names);
* ``camera_to_world`` (C, T, 4, 4), ``extrinsics_opencv`` (C, T, 4, 4 world → OpenCV camera),
  ``intrinsics_pixels`` (C, 3, 3); ``video_name``.
"""

from __future__ import annotations

import numpy as np

from kubric.datasets.task_registry import register_task

_PER_CAMERA = ("video", "camera/matrices_world", "camera/intrinsics_pixels",
               "camera/extrinsics_opencv")


@register_task("stereo", features=("video", "disparity", "camera", "cameras", "metadata"),
               per_frame=True,
               requires=("video", "disparity", "cameras/right/video", "camera/rig/baseline",
                         "camera/intrinsics_pixels", "camera/matrices_world",
                         "cameras/right/camera/matrices_world", "metadata/video_name"))
def stereo_task(example, frame):
    """One frame of a stereo pair: left, right, disparity (px) and the cameras."""
    right = example["cameras"]["right"]
    cam = example["camera"]
    return {"left": example["video"][frame], "right": right["video"][frame],
            "disparity": example["disparity"][frame, ..., 0],
            "baseline": np.float32(cam["rig"]["baseline"]),
            "intrinsics_pixels": cam["intrinsics_pixels"],
            "left_camera_to_world": cam["matrices_world"][frame],
            "right_camera_to_world": right["camera"]["matrices_world"][frame],
            "frame": np.int32(frame), "video_name": example["metadata"]["video_name"]}


def _camera_names(schema) -> list[str]:
    names = []
    for f in schema.names:
        parts = f.split("/")
        if parts[0] == "cameras" and len(parts) > 2 and parts[1] not in names:
            names.append(parts[1])
    return names


@register_task("multicamera_video", features=("video", "camera", "cameras", "metadata"),
               requires=_PER_CAMERA + ("cameras", "metadata/video_name"), wants_schema=True)
def multicamera_video_task(example, frame, schema=None):
    """Every camera's video with a camera axis first, and each camera's poses."""
    views = [example] + [example["cameras"][n] for n in _camera_names(schema)]
    return {"video": np.stack([v["video"] for v in views]),
            "camera_to_world": np.stack([v["camera"]["matrices_world"] for v in views]),
            "extrinsics_opencv": np.stack([v["camera"]["extrinsics_opencv"] for v in views]),
            "intrinsics_pixels": np.stack([v["camera"]["intrinsics_pixels"] for v in views]),
            "camera_names": ["reference", *_camera_names(schema)],
            "video_name": example["metadata"]["video_name"]}
