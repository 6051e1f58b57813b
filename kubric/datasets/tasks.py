"""Tasks: which features a loader decodes and how it turns an example into a training item.

A task is registered with :func:`register_task`; ``kubric.datasets.load(dir, split,
task=NAME, **options)`` uses it. Built in:

* ``None`` / ``"all"``: the whole example (every feature, regular nested numpy dict);
* ``video``: ``{"video": (T', H', W', 3) uint8, "video_name"}`` with options ``frame_stride``
  (keep every k-th frame), ``num_frames`` (keep the first n after striding) and ``resize``
  ((height, width), area-averaged when shrinking, bilinear otherwise);
* ``frames``: one item per (scene, frame): ``image`` (H, W, 3) uint8, ``intrinsics_pixels``
  (3, 3; OpenCV), ``camera_to_world`` (4, 4; Blender camera axes), ``frame``, ``video_name``;
* ``nerf_rays``: one item per (scene, frame): ``ray_origins`` and unit ``ray_directions``
  (H, W, 3) in world space for every pixel centre, ``rgb`` (H, W, 3) float32 in [0, 1] and
  ``depth`` (H, W) in metres (distance along the ray: ``origin + depth · direction`` is the
  surface point), plus ``frame`` and ``video_name``; on multi-view datasets a frame is a view;
* ``multiview`` and ``svr`` (multi-view datasets): :mod:`kubric.datasets.multiview_tasks`;
* ``point_tracks`` (datasets packed with a ``<recipe>_tracks`` schema, e.g. ``kubric pack DIR
  --schema movi_e_tracks``): TAP-Vid's training fields ``video`` (T, H, W, 3) uint8,
  ``query_points`` (P, 3) (t, y, x), ``target_points`` (P, T, 2) (x, y) in pixels (centres at
  +0.5), ``occluded`` (P, T) bool, plus ``video_name``.

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

import dataclasses
from collections.abc import Callable

import numpy as np

from kubric.datasets.layout import DatasetError
from kubric.datasets.scene_reader import dequantise

#: task options that count frames: whole numbers ≥ 1 (checked when the source is made)
COUNT_OPTIONS = {"frame_stride", "num_frames"}


@dataclasses.dataclass(frozen=True)
class Task:
    """A registered task (see module doc). ``requires``: feature names (or name prefixes such as
    ``camera``) a dataset must have for the task to serve it (default: ``features``);
    ``extra_features(schema, options)`` adds top-level features to decode that depend on the
    options and the dataset (e.g. ``multiview``'s optional layers); ``wants_schema`` passes the
    dataset's schema to ``fn`` as ``schema=``."""

    name: str
    fn: Callable | None
    features: tuple[str, ...] | None = None
    per_frame: bool = False
    options: tuple[str, ...] = ()
    doc: str = ""
    requires: tuple[str, ...] = ()
    extra_features: Callable | None = None
    wants_schema: bool = False

    def check_options(self, options: dict) -> dict:
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise DatasetError(f"task {self.name!r}: unknown option(s) {unknown}; options: "
                               f"{list(self.options) or 'none'}")
        for name in COUNT_OPTIONS & set(options):
            value = options[name]
            if value is not None and (isinstance(value, bool) or not isinstance(
                    value, (int, np.integer)) or value < 1):
                raise DatasetError(f"task {self.name!r}: {name} must be a whole number ≥ 1, "
                                   f"got {value!r}")
        return dict(options)


    def missing(self, schema) -> list[str]:
        """The required feature names (or prefixes) ``schema`` lacks."""
        names = schema.names
        return [r for r in self.requires or self.features or ()
                if r not in names and not any(n.startswith(r + "/") for n in names)]

    def decode_keys(self, schema, options: dict) -> tuple[str, ...] | None:
        """Top-level features to decode (None: all)."""
        if self.features is None:
            return None
        extra = tuple(self.extra_features(schema, options)) if self.extra_features else ()
        return tuple(dict.fromkeys(self.features + extra))

    def __call__(self, example: dict, frame, source) -> dict:
        if self.fn is None:
            return example
        if self.wants_schema:
            return self.fn(example, frame, schema=source.schema, **source.task_options)
        return self.fn(example, frame, **source.task_options)


TASKS: dict[str, Task] = {}


def register_task(name: str, features: tuple[str, ...] | None = None, per_frame: bool = False,
                  options: tuple[str, ...] = (), requires: tuple[str, ...] = (),
                  extra_features: Callable | None = None, wants_schema: bool = False):
    """Decorator registering ``fn(example, frame, **options) -> dict`` as task ``name``
    (:class:`Task` for ``requires``, ``extra_features`` and ``wants_schema``)."""
    def wrap(fn):
        TASKS[name] = Task(name, fn, tuple(features) if features else None, per_frame,
                           tuple(options), (fn.__doc__ or "").strip().split("\n")[0],
                           tuple(requires), extra_features, wants_schema)
        return fn
    return wrap


def servable_tasks(schema) -> list[str]:
    """The names of the registered tasks that a dataset of ``schema`` can serve."""
    return [name for name in sorted(TASKS) if not TASKS[name].missing(schema)]


def check_servable(task: Task, schema, where: str) -> None:
    """One-line :class:`DatasetError` when ``task`` cannot read a dataset of ``schema``."""
    missing = task.missing(schema)
    if missing:
        raise DatasetError(f"task {task.name!r} cannot read {where} (schema {schema.name!r}): it "
                           f"needs {missing}; this dataset serves the tasks "
                           f"{', '.join(servable_tasks(schema))}")


TASKS["all"] = Task("all", None, None, False, (), "every feature, nested numpy dict")


def get_task(name) -> Task:
    if isinstance(name, Task):
        return name
    if name is None:
        return TASKS["all"]
    if name not in TASKS:
        raise DatasetError(f"unknown task {name!r} (tasks: {', '.join(sorted(TASKS))})")
    return TASKS[name]


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
    return {"image": example["video"][frame].copy(),  # the source keeps the scene for its next frame
            "intrinsics_pixels": camera["intrinsics_pixels"].copy(),
            "camera_to_world": camera["matrices_world"][frame].copy(), "frame": np.int32(frame),
            "video_name": example["metadata"]["video_name"]}


def pixel_rays(intrinsics_pixels: np.ndarray, camera_to_world: np.ndarray, height: int,
               width: int) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray origins and unit directions (H, W, 3) through every pixel centre.

    ``intrinsics_pixels`` is OpenCV's (x right, y down, +z forward, pixel (r, c) centred at
    (c + 0.5, r + 0.5)); ``camera_to_world`` maps Blender camera axes (x right, y up, −z
    forward) to the world.
    """
    rows, cols = np.meshgrid(np.arange(height) + 0.5, np.arange(width) + 0.5, indexing="ij")
    pixels = np.stack([cols, rows, np.ones_like(rows)], axis=-1)
    cv_dirs = pixels @ np.linalg.inv(np.asarray(intrinsics_pixels, np.float64)).T
    blender_dirs = cv_dirs * np.array([1.0, -1.0, -1.0])
    matrix = np.asarray(camera_to_world, np.float64)
    dirs = blender_dirs @ matrix[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = np.broadcast_to(matrix[:3, 3], dirs.shape)
    return origins.astype(np.float32), dirs.astype(np.float32)


def metric_depth(example: dict, frame) -> np.ndarray:
    """Depth (H, W) float32 metres of one frame: the stored float32 samples (multi-view
    datasets), or uint16 samples scaled by ``metadata/depth_range`` (MOVi)."""
    depth = example["depth"][frame, ..., 0]
    if depth.dtype.kind == "f":
        return depth.astype(np.float32, copy=True)
    return dequantise(depth, example["metadata"]["depth_range"])


@register_task("nerf_rays", features=("video", "depth", "camera", "metadata"), per_frame=True,
               requires=("video", "depth", "camera/intrinsics_pixels", "camera/matrices_world",
                         "metadata/video_name"))
def nerf_rays_task(example, frame):
    """Per-pixel world rays, RGB and metric depth of one frame."""
    camera = example["camera"]
    height, width = example["video"].shape[1:3]
    origins, dirs = pixel_rays(camera["intrinsics_pixels"], camera["matrices_world"][frame],
                               height, width)
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


from kubric.datasets import multiview_tasks  # noqa: E402,F401  (registers multiview, svr)
