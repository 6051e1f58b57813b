"""Tasks: which features a loader decodes and how it turns an example into a training item.

A task is registered with :func:`register_task`; ``kubric.datasets.load(dir, split,
task=NAME, **options)`` uses it. Built in:

* ``None`` / ``"all"``: the whole example (every feature, regular nested numpy dict);
* ``video``: ``{"video": (T', H', W', 3) uint8, "video_name"}`` with options ``frame_stride``
  (keep every k-th frame), ``num_frames`` (keep the first n after striding) and ``resize``
  ((height, width), area-averaged when shrinking, bilinear otherwise);
* ``frames``: one item per (scene, frame): ``image`` (H, W, 3) uint8, ``intrinsics_pixels``
  (3, 3; OpenCV), ``camera_to_world`` (4, 4; Blender camera axes), ``frame``, ``video_name``,
  and where the dataset records the lens ``distortion_model`` and ``distortion_coefficients``
  (OpenCV's order, zero-padded to 8: :mod:`kubric.core.lenses`);
* ``nerf_rays``: one item per (scene, frame): ``ray_origins`` and unit ``ray_directions``
  (H, W, 3) in world space for every pixel centre (through the camera's lens model when the
  dataset records one: ``camera/distortion_model``), ``rgb`` (H, W, 3) float32 in [0, 1] and
  ``depth`` (H, W) in metres (distance along the ray: ``origin + depth · direction`` is the
  surface point), plus ``frame`` and ``video_name``; on multi-view datasets a frame is a view;
* ``multiview`` and ``svr`` (multi-view datasets): :mod:`kubric.datasets.multiview_tasks`;
* ``amodal_segmentation`` and ``scene_flow`` (datasets of scenes made with ``--set
  extra_layers=...``): :mod:`kubric.datasets.extra_tasks`;
* ``point_tracks`` (datasets packed with a ``<recipe>_tracks`` schema, e.g. ``kubric pack DIR
  --schema movi_e_tracks``): TAP-Vid's training fields ``video`` (T, H, W, 3) uint8,
  ``query_points`` (P, 3) (t, y, x), ``target_points`` (P, T, 2) (x, y) in pixels (centres at
  +0.5), ``occluded`` (P, T) bool, plus ``video_name``;
* ``person_keypoints`` (``pose_estimation`` datasets): ``video`` (T, H, W, 3) uint8,
  ``keypoints_2d`` (N, T, 17, 2) (x, y) in pixels (centres at +0.5), ``keypoints_3d``
  (N, T, 17, 3) world metres, ``keypoints_visibility`` (N, T, 17) COCO flags (0 outside the
  image, 1 occluded, 2 visible) for the N people (instances), plus ``video_name``.

Adding a task: declare the features it needs in the recipe's schema (e.g.
``Feature("tracks/target_points", ..., source="npz:tracks.npz:target_points")``), then::

    @register_task("my_task", features=("video", "tracks", "metadata"))
    def my_task(example, frame):
        return {"video": example["video"], "tracks": example["tracks"]["target_points"]}

``features`` are top-level names of the packed example (only those are decoded); ``per_frame``
makes one item per frame (``frame`` is then the frame index, else None). Loading a dataset with
a task whose ``requires`` it lacks fails in one line naming the tasks the dataset serves.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import lenses
from kubric.datasets.layout import DatasetError
from kubric.datasets.task_registry import (  # noqa: F401  (the registry's public names)
    TASKS,
    Task,
    check_servable,
    get_task,
    register_task,
    servable_tasks,
)
from kubric.io.layers import LAYERS


def resize_frames(frames: np.ndarray, size) -> np.ndarray:
    """(T, H, W, C) → (T, h, w, C) for ``size`` = (h, w): area average when shrinking, bilinear
    when growing (OpenCV); dtype kept."""
    import cv2
    h, w = (int(v) for v in size)
    if h < 1 or w < 1:
        raise DatasetError(f"resize must be (height, width) ≥ 1, got {size}")
    shrink = h <= frames.shape[1] and w <= frames.shape[2]
    mode = cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
    out = [cv2.resize(f, (w, h), interpolation=mode) for f in frames]
    return np.stack([o.reshape(h, w, -1) for o in out])


@register_task("video", features=("video", "metadata"),
               options=("frame_stride", "num_frames", "resize"),
               requires=("video", "metadata/video_name"))
def video_task(example, frame, frame_stride: int = 1, num_frames: int | None = None,
               resize=None):
    """RGB clips, optionally subsampled in time and resized."""
    if int(frame_stride) < 1:
        raise DatasetError(f"frame_stride must be ≥ 1, got {frame_stride}")
    video = example["video"][::int(frame_stride)]
    if num_frames is not None:
        video = video[:int(num_frames)]
    if resize is not None:
        video = resize_frames(video, resize)
    return {"video": video, "video_name": example["metadata"]["video_name"]}


@register_task("frames", features=("video", "camera", "metadata"), per_frame=True,
               requires=("video", "camera/intrinsics_pixels", "camera/matrices_world",
                         "metadata/video_name"))
def frames_task(example, frame):
    """Single RGB frames with their camera (OpenCV intrinsics, camera-to-world pose)."""
    camera = example["camera"]
    out = {"image": example["video"][frame].copy(),  # the source keeps the scene for its next frame
           "intrinsics_pixels": camera["intrinsics_pixels"].copy(),
           "camera_to_world": camera["matrices_world"][frame].copy(), "frame": np.int32(frame),
           "video_name": example["metadata"]["video_name"]}
    if "distortion_model" in camera:  # the lens, where the dataset records one
        out["distortion_model"] = camera["distortion_model"]
        out["distortion_coefficients"] = np.asarray(camera["distortion_coefficients"]).copy()
    return out


def pixel_rays(intrinsics_pixels: np.ndarray, camera_to_world: np.ndarray, height: int,
               width: int, lens=None) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray origins and unit directions (H, W, 3) through every pixel centre.

    ``intrinsics_pixels`` is OpenCV's (x right, y down, +z forward, pixel (r, c) centred at
    (c + 0.5, r + 0.5)); ``camera_to_world`` maps Blender camera axes (x right, y up, −z
    forward) to the world; ``lens``: the camera's lens model
    (:func:`kubric.core.lenses.from_camera_record`; None = pinhole; NaN directions where its
    image has no ray).
    """
    origins, dirs = geo.pinhole_rays(intrinsics_pixels, camera_to_world,
                                     geo.pixel_centres(height, width), lens)
    return origins.astype(np.float32), dirs.astype(np.float32)


def metric_depth(example: dict, frame) -> np.ndarray:
    """Depth (H, W) float32 metres of one frame, decoded by the depth layer's kind: the stored
    float32 samples (multi-view datasets, or ``units="physical"``), or uint16 samples scaled by
    ``metadata/depth_range`` (MOVi)."""
    depth = example["depth"][frame, ..., 0]
    value_range = example["metadata"].get("depth_range") if depth.dtype.kind in "ui" else None
    return LAYERS["depth"].type.decode(depth, value_range, "feature 'depth'").copy()


@register_task("nerf_rays", features=("video", "depth", "camera", "metadata"), per_frame=True,
               requires=("video", "depth", "camera/intrinsics_pixels", "camera/matrices_world",
                         "metadata/video_name"))
def nerf_rays_task(example, frame):
    """Per-pixel world rays, RGB and metric depth of one frame."""
    camera = example["camera"]
    height, width = example["video"].shape[1:3]
    origins, dirs = pixel_rays(camera["intrinsics_pixels"], camera["matrices_world"][frame],
                               height, width, lenses.from_camera_record(camera))
    depth = metric_depth(example, frame)
    return {"ray_origins": origins, "ray_directions": dirs,
            "rgb": example["video"][frame].astype(np.float32) / 255.0, "depth": depth,
            "frame": np.int32(frame), "video_name": example["metadata"]["video_name"]}


@register_task("point_tracks", features=("video", "tracks", "metadata"),
               requires=("video", "tracks/query_points", "tracks/target_points",
                         "tracks/occluded", "metadata/video_name"))
def point_tracks_task(example, frame):
    """TAP-Vid's fields from a dataset packed with a ``<recipe>_tracks`` schema."""
    tracks = example["tracks"]
    return {"video": example["video"], "query_points": tracks["query_points"],
            "target_points": tracks["target_points"], "occluded": tracks["occluded"],
            "video_name": example["metadata"]["video_name"]}


@register_task("person_keypoints", features=("video", "instances", "metadata"),
               requires=("video", "instances/keypoints_2d", "instances/keypoints_3d",
                         "instances/keypoints_visibility", "metadata/video_name"))
def person_keypoints_task(example, frame):
    """The people's COCO keypoints from a dataset whose instances carry them (pose_estimation)."""
    inst = example["instances"]
    return {"video": example["video"], "keypoints_2d": inst["keypoints_2d"],
            "keypoints_3d": inst["keypoints_3d"],
            "keypoints_visibility": inst["keypoints_visibility"],
            "video_name": example["metadata"]["video_name"]}


# registers multiview, svr; amodal_segmentation, scene_flow; stereo, multicamera_video
from kubric.datasets import extra_tasks, multiview_tasks, rig_tasks  # noqa: E402,F401
