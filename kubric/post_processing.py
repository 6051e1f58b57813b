"""Upstream Kubric's ``kubric.post_processing`` names (segmentation-based annotations).

See :mod:`kubric.annotations.segmentation` for shapes and label conventions.
"""

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
    "adjust_segmentation_idxs", "bounding_boxes", "compute_bboxes", "compute_visibility",
    "instance_labels", "pixel_counts", "visible_sorted",
]
