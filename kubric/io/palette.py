"""The label palette: one colour per segmentation label, shared by the 8-bit palette PNGs of
:func:`kubric.file_io.write_palette_png` and the contact sheets of ``kubric inspect``, so a label
has the same colour in both.

Label 0 (background) is black; label ``k ≥ 1`` has hue ``k · φ mod 1`` (φ = golden-ratio
conjugate 0.618…, so consecutive labels are far apart on the hue circle), saturation cycling
0.95 / 0.7 / 0.5 every three labels and value alternating 1.0 / 0.75, rounded to 0–255. The
colours depend only on the label, so they are the same for every frame, scene and ``n``.
"""

from __future__ import annotations

import colorsys
import functools

import numpy as np

_GOLDEN = 0.6180339887498949
_SATURATIONS = (0.95, 0.7, 0.5)
_VALUES = (1.0, 0.75)


def label_colour(k: int) -> tuple[int, int, int]:
    """The sRGB colour (0–255) of label ``k`` (see module doc)."""
    if k == 0:
        return (0, 0, 0)
    hue = (k * _GOLDEN) % 1.0
    rgb = colorsys.hsv_to_rgb(hue, _SATURATIONS[(k // 3) % 3], _VALUES[k % 2])
    return tuple(round(255 * c) for c in rgb)


@functools.lru_cache(maxsize=8)
def _palette(n: int) -> np.ndarray:
    palette = np.array([label_colour(k) for k in range(n)], dtype=np.uint8).reshape(n, 3)
    palette.setflags(write=False)
    return palette


def label_palette(n: int = 256) -> np.ndarray:
    """(n, 3) uint8 colours of labels 0..n-1 (a fresh, writable array)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"label_palette needs a positive number of labels, got {n!r}")
    return _palette(int(n)).copy()


__all__ = ["label_colour", "label_palette"]
