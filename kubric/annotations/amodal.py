"""Per-instance amodal annotations from amodal masks and the visible segmentation. Pure numpy.

For instance k (label k + 1 of the relabelled segmentation) and frame t, with ``A`` its amodal
mask (:func:`kubric.renderer.scene_model_layers.amodal_masks`) and ``V`` its visible pixels:

* ``amodal_area[t]``: pixels of ``A`` (the full silhouette inside the image);
* ``amodal_bboxes[t]``: the box of ``A`` as the visible boxes are given — normalised
  ``(ymin, xmin, ymax, xmax)`` with ``ymax = (row_max + 1) / H`` — or ``(0, 0, 0, 0)`` where
  ``A`` is empty (the object is outside the image);
* ``visible_fraction[t]``: ``|V ∩ A| / |A|`` (1 = unoccluded, 0 = hidden or outside the
  image). With exact layers ``V ⊆ A``; the intersection keeps the fraction ≤ 1 where a
  path-traced segmentation differs from the scene model at an edge pixel.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

#: the instance metadata fields :func:`annotate_amodal` adds
AMODAL_FIELDS = ("amodal_area", "amodal_bboxes", "visible_fraction")


def amodal_boxes(masks: np.ndarray) -> np.ndarray:
    """(T, 4) float32 normalised boxes of (T, H, W) masks; zeros for empty frames."""
    _, h, w = masks.shape
    out = np.zeros((masks.shape[0], 4), np.float32)
    for t, mask in enumerate(masks):
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if rows.size:
            out[t] = (rows[0] / h, cols[0] / w, (rows[-1] + 1) / h, (cols[-1] + 1) / w)
    return out


def annotate_amodal(masks, segmentation, instances: Sequence) -> None:
    """Store :data:`AMODAL_FIELDS` in each instance's ``metadata`` (module doc).

    ``masks``: (T, N, H, W) bool, mask k of ``instances[k]``; ``segmentation``: (T, H, W[, 1])
    relabelled (label k + 1 = ``instances[k]``).
    """
    masks = np.asarray(masks, bool)
    seg = np.asarray(segmentation)
    seg = seg[..., 0] if seg.ndim == 4 else seg
    if masks.ndim != 4 or masks.shape[1] != len(instances) or \
            masks.shape[:1] + masks.shape[2:] != seg.shape:
        raise ValueError(f"annotate_amodal: masks {masks.shape} must be (T, N={len(instances)}, "
                         f"H, W) over segmentation {seg.shape}")
    for k, asset in enumerate(instances):
        amodal = masks[:, k]
        area = amodal.sum(axis=(1, 2))
        visible = (amodal & (seg == k + 1)).sum(axis=(1, 2))
        asset.metadata["amodal_area"] = area.astype(np.int64)
        asset.metadata["amodal_bboxes"] = amodal_boxes(amodal)
        asset.metadata["visible_fraction"] = np.where(
            area > 0, visible / np.maximum(area, 1), 0.0).astype(np.float32)
