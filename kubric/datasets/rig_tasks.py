"""Loader tasks of camera-rig datasets (scenes made with ``--set cameras=stereo|ring|random``;
:mod:`kubric.recipes.rig_options`). Importing :mod:`kubric.datasets.tasks` registers them.
A rig dataset's further cameras are the features ``cameras/NAME/...`` (nested:
``example["cameras"][NAME]["video"]``); the reference camera's are the usual top-level ones; the
cameras' geometry also has a camera axis R (``camera/rig/matrices_world`` (R, T, 4, 4), ...).

``stereo`` — one item per (scene, frame) of a stereo dataset:

* ``left``, ``right`` (H, W, 3) uint8: the rectified pair's images;
* ``disparity`` (H, W) float32 pixels of the left image: x_left − x_right, f·B/Z (0 where
  nothing is hit);
* ``baseline`` metres, ``intrinsics_pixels`` (3, 3) OpenCV (shared by both cameras),
  ``left_camera_to_world`` / ``right_camera_to_world`` (4, 4, Blender camera axes), ``frame``,
  ``video_name``.

``multicamera_video`` — one item per scene of any rig dataset, with a **camera axis** first:

* ``video`` (R, T, H, W, 3) uint8, the cameras in the rig's order (``camera_names`` (R,), the
  reference first);
* ``camera_to_world`` (R, T, 4, 4), ``extrinsics_opencv`` (R, T, 4, 4 world → OpenCV camera),
  ``intrinsics_pixels`` (R, 3, 3): the packed camera-axis features ``camera/rig/...``;
  ``video_name``.
"""

from __future__ import annotations

import numpy as np

from kubric.datasets.task_registry import register_task

_RIG_AXIS = ("camera/rig/camera_names", "camera/rig/matrices_world",
             "camera/rig/extrinsics_opencv", "camera/rig/intrinsics_pixels")


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


@register_task("multicamera_video", features=("video", "camera", "cameras", "metadata"),
               requires=("video", "cameras", "metadata/video_name") + _RIG_AXIS)
def multicamera_video_task(example, frame):
    """Every camera's video with a camera axis first, and each camera's poses."""
    rig = example["camera"]["rig"]
    names = list(rig["camera_names"])
    return {"video": np.stack([example["video"]] + [example["cameras"][n]["video"]
                                                    for n in names[1:]]),
            "camera_to_world": rig["matrices_world"],
            "extrinsics_opencv": rig["extrinsics_opencv"],
            "intrinsics_pixels": rig["intrinsics_pixels"], "camera_names": names,
            "video_name": example["metadata"]["video_name"]}
