"""Annotations computed after rendering and simulation: pure functions over arrays and the scene
model (no engine imports). :mod:`kubric.post_processing` and :mod:`kubric.utils` re-export them
under upstream Kubric's names."""

from kubric.annotations.metadata import (
    CAMERA_CONVENTIONS,
    bboxes_3d_over_time,
    describe_background,
    get_camera_info,
    get_instance_info,
    get_scene_metadata,
    library_versions,
    process_collisions,
)
from kubric.annotations.segmentation import (
    adjust_segmentation_idxs,
    bounding_boxes,
    compute_bboxes,
    compute_visibility,
    instance_labels,
    pixel_counts,
    visible_sorted,
)

__all__ = [
    "CAMERA_CONVENTIONS", "bboxes_3d_over_time", "describe_background", "get_camera_info",
    "get_instance_info", "get_scene_metadata", "library_versions", "process_collisions",
    "adjust_segmentation_idxs", "bounding_boxes", "compute_bboxes", "compute_visibility",
    "instance_labels", "pixel_counts", "visible_sorted",
]
