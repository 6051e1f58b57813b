"""Per-instance annotations computed from a segmentation layer. Pure numpy.

Segmentation layers are integer arrays shaped (T, H, W) or (T, H, W, 1). Label 0 is background;
label ``k ≥ 1`` is the k-th asset of the list the layer was made for (``assets[k-1]``), unless that
asset has a ``segmentation_id`` set (then that id is its label). The renderer labels with the
scene's asset list (``scene.assets``); after :func:`adjust_segmentation_idxs` the labels refer to
the visibility-sorted instance list written to ``metadata.json``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def _as_segmentation(segmentation) -> np.ndarray:
    """(T, H, W) integer view of a (T, H, W[, 1]) segmentation array."""
    seg = np.asarray(segmentation)
    if seg.ndim == 4 and seg.shape[-1] == 1:
        seg = seg[..., 0]
    if seg.ndim != 3:
        raise ValueError(f"segmentation must have shape (T, H, W) or (T, H, W, 1), got {seg.shape}")
    if not np.issubdtype(seg.dtype, np.integer):
        raise TypeError(f"segmentation must hold integer labels, got dtype {seg.dtype}")
    if seg.size and seg.min() < 0:
        raise ValueError(f"segmentation labels must be ≥ 0, got minimum {seg.min()}")
    return seg


def instance_labels(assets: Sequence) -> np.ndarray:
    """(N,) label of each asset in a layer made for ``assets``: its ``segmentation_id`` if set,
    otherwise its 1-based position in the list."""
    labels = []
    for i, asset in enumerate(assets):
        override = getattr(asset, "segmentation_id", None)
        labels.append(i + 1 if override is None else int(override))
    return np.asarray(labels, dtype=np.int64)


def pixel_counts(segmentation, labels) -> np.ndarray:
    """(len(labels), T) number of pixels carrying each label in each frame (int64)."""
    seg = _as_segmentation(segmentation)
    labels = np.asarray(labels, dtype=np.int64).reshape(-1)
    counts = np.zeros((labels.size, seg.shape[0]), dtype=np.int64)
    if labels.size == 0:
        return counts
    top = int(max(labels.max(), seg.max() if seg.size else 0)) + 1
    for t in range(seg.shape[0]):
        per_label = np.bincount(seg[t].ravel().astype(np.int64), minlength=top)
        counts[:, t] = per_label[labels]
    return counts


def compute_visibility(segmentation, assets: Sequence) -> np.ndarray:
    """Visible pixel count of every asset in every frame.

    Args:
      segmentation: (T, H, W[, 1]) labels made for ``assets`` (see module doc).
      assets: the asset list the labels refer to (usually ``scene.assets``).

    Returns:
      (len(assets), T) int64 pixel counts. Each asset also gets ``metadata["visibility"]``
      (a (T,) int64 array), as upstream Kubric's workers expect.
    """
    counts = pixel_counts(segmentation, instance_labels(assets))
    for asset, row in zip(assets, counts, strict=True):
        asset.metadata["visibility"] = row
    return counts


def visible_sorted(assets: Sequence, min_pixels: int = 1) -> list:
    """The assets with ``metadata["visibility"]`` summing to ≥ ``min_pixels`` (≥ 1 in some frame
    by default), ordered by total visible pixels, descending (ties keep the input order)."""
    totals = []
    for asset in assets:
        vis = asset.metadata.get("visibility")
        if vis is None:
            raise ValueError(f"{asset.uid} has no metadata['visibility']: run "
                             "compute_visibility first")
        totals.append(int(np.sum(vis)))
    order = sorted(range(len(assets)), key=lambda i: -totals[i])
    return [assets[i] for i in order if totals[i] >= max(1, min_pixels)]


def adjust_segmentation_idxs(segmentation, old_assets: Sequence, new_assets: Sequence,
                             ignored_label: int = 0) -> np.ndarray:
    """Relabel a segmentation made for ``old_assets`` so that label k = ``new_assets[k-1]``.

    Pixels of assets not in ``new_assets`` (and unknown labels) become ``ignored_label``.
    Keeps the input's shape and dtype.
    """
    seg = np.asarray(segmentation)
    flat = _as_segmentation(seg)
    old_labels = instance_labels(old_assets)
    top = int(max(old_labels.max() if old_labels.size else 0, flat.max() if flat.size else 0)) + 1
    lut = np.full(top, ignored_label, dtype=np.int64)
    new_index = {id(a): k for k, a in enumerate(new_assets, start=1)}
    for asset, label in zip(old_assets, old_labels, strict=True):
        k = new_index.get(id(asset))
        if k is not None:
            lut[label] = k
    if len(new_assets) > np.iinfo(seg.dtype).max:
        raise ValueError(f"{len(new_assets)} instances do not fit in a {seg.dtype} segmentation")
    lut[0] = ignored_label
    return lut[seg].astype(seg.dtype)


def bounding_boxes(segmentation, label: int) -> tuple[np.ndarray, np.ndarray]:
    """2D boxes of one label over time.

    Returns ``(bboxes, frames)``: ``bboxes`` (N, 4) float32 normalised ``(ymin, xmin, ymax,
    xmax)`` with ``ymin = row_min / H`` and ``ymax = (row_max + 1) / H`` (so the box contains
    every labelled pixel entirely), for the N frames (0-based indices into the layer) where the
    label is present; ``frames`` (N,) int64.
    """
    seg = _as_segmentation(segmentation)
    _, h, w = seg.shape
    boxes, frames = [], []
    for t in range(seg.shape[0]):
        mask = seg[t] == label
        rows = np.flatnonzero(mask.any(axis=1))
        if rows.size == 0:
            continue
        cols = np.flatnonzero(mask.any(axis=0))
        boxes.append((rows[0] / h, cols[0] / w, (rows[-1] + 1) / h, (cols[-1] + 1) / w))
        frames.append(t)
    return (np.asarray(boxes, dtype=np.float32).reshape(-1, 4),
            np.asarray(frames, dtype=np.int64))


def compute_bboxes(segmentation, assets: Sequence) -> list[tuple[np.ndarray, np.ndarray]]:
    """2D boxes of every asset (label k = ``assets[k-1]``, see module doc).

    Returns one ``(bboxes (N, 4), bbox_frames (N,))`` pair per asset (see :func:`bounding_boxes`)
    and stores them as ``metadata["bboxes"]`` and ``metadata["bbox_frames"]``.
    """
    seg = _as_segmentation(segmentation)
    result = []
    for asset, label in zip(assets, instance_labels(assets), strict=True):
        boxes, frames = bounding_boxes(seg, int(label))
        asset.metadata["bboxes"] = boxes
        asset.metadata["bbox_frames"] = frames
        result.append((boxes, frames))
    return result
