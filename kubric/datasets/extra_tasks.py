"""Loader tasks of the opt-in scene-model layers (datasets packed from scenes made with
``--set extra_layers=...``; :mod:`kubric.recipes.extra_layers`). Importing
:mod:`kubric.datasets.tasks` registers them.

``amodal_segmentation`` — one item per scene, for amodal / object-permanence models:

* ``video`` (T, H, W, 3) uint8; ``segmentations`` (T, H, W) uint8 visible labels (0 background,
  k = instance k − 1);
* ``amodal_masks`` (N, T, H, W) bool: instance k's full silhouette (unpacked from the bit planes
  of ``amodal_segmentations`` with :func:`kubric.io.bitmask.unpack_masks`);
* ``amodal_bboxes`` (N, T, 4) normalised (ymin, xmin, ymax, xmax), 0 where the mask is empty;
  ``visible_fraction`` (N, T) float32; plus ``video_name``.

``scene_flow`` — one item per (scene, frame):

* ``image`` (H, W, 3) uint8; ``depth`` (H, W) float32 metres (distance to the camera centre);
* ``forward_scene_flow`` / ``backward_scene_flow`` (H, W, 3) float32 metres, world frame (and
  ``..._camera``, the camera frame, where the dataset has them);
* ``intrinsics_pixels`` (3, 3) OpenCV pixel intrinsics, ``camera_to_world`` (4, 4) of this frame
  and ``next_camera_to_world`` / ``previous_camera_to_world`` (Blender camera axes; the frame's
  own at the ends of the video, where the flow points outside the rendered range); ``frame``,
  ``video_name``.
"""

from __future__ import annotations

import numpy as np

from kubric.datasets.task_registry import register_task
from kubric.io.bitmask import unpack_masks
from kubric.io.layers import LAYERS

_CAMERA_FLOW = ("forward_scene_flow_camera", "backward_scene_flow_camera")


@register_task("amodal_segmentation",
               features=("video", "segmentations", "amodal_segmentations", "instances",
                         "metadata"),
               requires=("video", "segmentations", "amodal_segmentations",
                         "instances/amodal_bboxes", "instances/visible_fraction",
                         "metadata/num_instances", "metadata/video_name"))
def amodal_segmentation_task(example, frame):
    """Visible and amodal masks of every instance over the video."""
    n = int(example["metadata"]["num_instances"])
    inst = example["instances"]
    return {"video": example["video"], "segmentations": example["segmentations"][..., 0],
            "amodal_masks": np.moveaxis(unpack_masks(example["amodal_segmentations"], n), 1, 0),
            "amodal_bboxes": inst["amodal_bboxes"], "visible_fraction": inst["visible_fraction"],
            "video_name": example["metadata"]["video_name"]}


def _camera_flow(schema, options):
    return tuple(name for name in _CAMERA_FLOW if name in schema.names)


@register_task("scene_flow",
               features=("video", "depth", "forward_scene_flow", "backward_scene_flow",
                         "camera", "metadata"), per_frame=True,
               requires=("video", "depth", "forward_scene_flow", "backward_scene_flow",
                         "camera/intrinsics_pixels", "camera/matrices_world",
                         "metadata/video_name"),
               extra_features=_camera_flow)
def scene_flow_task(example, frame):
    """One frame's image, metric depth and scene flow with the cameras it spans."""
    cams = example["camera"]["matrices_world"]
    last = len(cams) - 1
    depth = example["depth"][frame, ..., 0]  # MOVi: uint16 over metadata/depth_range
    value_range = example["metadata"].get("depth_range") if depth.dtype.kind in "ui" else None
    item = {"image": example["video"][frame],
            "depth": LAYERS["depth"].type.decode(depth, value_range, "feature 'depth'").copy(),
            "intrinsics_pixels": example["camera"]["intrinsics_pixels"],
            "camera_to_world": cams[frame], "next_camera_to_world": cams[min(frame + 1, last)],
            "previous_camera_to_world": cams[max(frame - 1, 0)],
            "frame": np.int32(frame), "video_name": example["metadata"]["video_name"]}
    for name in ("forward_scene_flow", "backward_scene_flow") + _CAMERA_FLOW:
        if name in example:
            item[name] = example[name][frame]
    return item
