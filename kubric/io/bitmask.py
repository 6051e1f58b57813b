"""Multi-label bit masks: up to :data:`MAX_MASKS` overlapping per-frame masks (the amodal
segmentation of every instance) packed as the bits of one 4-channel 16-bit image per frame.

Mask ``k`` (0-based; instance ``k + 1`` of a scene directory) is bit ``k % 16`` of channel
``k // 16``: a pixel's four uint16 samples are one 64-bit word whose set bits name the masks that
cover it. A 16-bit RGBA PNG stores a frame losslessly; zero channels (scenes with ≤ 16, 32, 48
instances) and the large empty regions compress to almost nothing (docs/scene-format.md).
"""

from __future__ import annotations

import numpy as np

#: bits per channel and channels per frame
BITS, PLANES = 16, 4
#: the most masks one frame holds
MAX_MASKS = BITS * PLANES


def pack_masks(masks) -> np.ndarray:
    """(..., N, H, W) bool masks → (..., H, W, 4) uint16 bit planes (module doc); N ≤ 64."""
    masks = np.asarray(masks, dtype=bool)
    if masks.ndim < 3:
        raise ValueError(f"pack_masks: expected (..., N, H, W) masks, got shape {masks.shape}")
    n = masks.shape[-3]
    if n > MAX_MASKS:
        raise ValueError(f"pack_masks: {n} masks; at most {MAX_MASKS} fit the 4 × 16 bits")
    out = np.zeros(masks.shape[:-3] + masks.shape[-2:] + (PLANES,), np.uint16)
    for k in range(n):
        out[..., k // BITS] |= masks[..., k, :, :].astype(np.uint16) << np.uint16(k % BITS)
    return out


def unpack_masks(planes, num_masks: int) -> np.ndarray:
    """(..., H, W, 4) uint16 bit planes → (..., num_masks, H, W) bool (the inverse of
    :func:`pack_masks`)."""
    planes = np.asarray(planes)
    if planes.ndim < 3 or planes.shape[-1] != PLANES or planes.dtype.kind not in "ui":
        raise ValueError(f"unpack_masks: expected (..., H, W, {PLANES}) integer bit planes, got "
                         f"shape {planes.shape} dtype {planes.dtype}")
    if not 0 <= int(num_masks) <= MAX_MASKS:
        raise ValueError(f"unpack_masks: num_masks={num_masks} must be in 0..{MAX_MASKS}")
    masks = [(planes[..., k // BITS] >> (k % BITS)) & 1 for k in range(int(num_masks))]
    shape = planes.shape[:-3] + (0,) + planes.shape[-3:-1]
    return np.stack(masks, axis=-3).astype(bool) if masks else np.zeros(shape, bool)


def mask_counts(planes) -> np.ndarray:
    """(..., H, W) number of masks covering each pixel of (..., H, W, 4) bit planes."""
    planes = np.asarray(planes).astype(np.uint64)
    word = planes[..., 0] | planes[..., 1] << 16 | planes[..., 2] << 32 | planes[..., 3] << 48
    counts = np.zeros(word.shape, np.int64)
    while word.any():
        counts += (word & 1).astype(np.int64)
        word >>= np.uint64(1)
    return counts
