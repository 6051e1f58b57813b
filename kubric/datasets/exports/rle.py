"""COCO's run-length encoding of binary masks, in NumPy (pycocotools is only used by the tests).

A COCO RLE is ``{"size": [H, W], "counts": ...}``. The mask is read **column by column**
(Fortran order: down the first column, then the second, ...) and ``counts`` alternates run
lengths of 0s and 1s, starting with 0s (a mask whose first pixel is 1 starts with a 0-length run).

* uncompressed: ``counts`` is that list of ints;
* compressed (what pycocotools' ``encode`` returns, as a str): every count ``x`` (from the third
  on, as the difference to the count two places before it) is written as 5-bit groups, least
  significant first; each group is a character ``48 + g``, with bit 0x20 of ``g`` set while more
  groups follow, and the last group's bit 0x10 carrying the sign (a signed LEB128 in base 32).
"""

from __future__ import annotations

import numpy as np


def mask_runs(mask: np.ndarray) -> list[int]:
    """Run lengths of a (H, W) boolean mask in column-major order, starting with 0s."""
    mask = np.asarray(mask)
    if mask.ndim != 2:
        raise ValueError(f"mask must be 2-D (H, W), got shape {mask.shape}")
    flat = mask.astype(bool).ravel(order="F")
    if flat.size == 0:
        return [0]
    edges = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate(([0], edges, [flat.size]))
    runs = np.diff(bounds).tolist()
    return [0] + runs if flat[0] else runs


def compress_counts(counts: list[int]) -> str:
    """The compressed string of a list of run lengths (module doc)."""
    out = []
    for i, value in enumerate(counts):
        x = int(value) - int(counts[i - 2]) if i > 2 else int(value)
        while True:
            group = x & 0x1F
            x >>= 5  # arithmetic shift: a negative x tends to -1
            more = x != -1 if group & 0x10 else x != 0
            out.append(chr(48 + (group | 0x20 if more else group)))
            if not more:
                break
    return "".join(out)


def decompress_counts(text: str) -> list[int]:
    """Inverse of :func:`compress_counts`."""
    counts: list[int] = []
    pos = 0
    while pos < len(text):
        x, shift = 0, 0
        while True:
            group = ord(text[pos]) - 48
            pos += 1
            x |= (group & 0x1F) << shift
            shift += 5
            if not group & 0x20:
                if group & 0x10:
                    x -= 1 << shift
                break
        if len(counts) > 2:
            x += counts[-2]
        counts.append(x)
    return counts


def encode(mask: np.ndarray, compressed: bool = True) -> dict:
    """COCO RLE of a (H, W) mask: ``{"size": [H, W], "counts": str or list[int]}``."""
    runs = mask_runs(mask)
    h, w = np.asarray(mask).shape
    return {"size": [int(h), int(w)], "counts": compress_counts(runs) if compressed else runs}


def decode(rle: dict) -> np.ndarray:
    """The (H, W) bool mask of a COCO RLE (compressed or not)."""
    h, w = (int(v) for v in rle["size"])
    counts = rle["counts"]
    runs = decompress_counts(counts) if isinstance(counts, str) else [int(c) for c in counts]
    if sum(runs) != h * w:
        raise ValueError(f"RLE runs sum to {sum(runs)}, expected H·W = {h * w}")
    values = np.zeros(len(runs), dtype=bool)
    values[1::2] = True
    return np.repeat(values, runs).reshape((w, h)).T


__all__ = ["compress_counts", "decode", "decompress_counts", "encode", "mask_runs"]
