"""The colour maps the layer kinds draw with (:mod:`kubric.io.encodings`; shown by ``kubric
view`` and ``kubric inspect`` through :mod:`kubric.annotations.pictures`).

* depth-like values: a perceptual colour map (viridis-like: near = dark purple, far = yellow)
  over ``[lo, hi]``; background (no surface, ≥ 0.999 · background depth, or NaN) black;
* flows: the Middlebury colour wheel (Baker et al. 2011): hue = direction of (Δcol, Δrow),
  saturation = magnitude / ``max_flow`` (the largest magnitude of the frame unless given),
  beyond ``max_flow`` the colour darkens;
* labels: the label palette (:mod:`kubric.io.palette`: the colours of segmentation PNGs).
"""

from __future__ import annotations

import numpy as np

from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.io.palette import label_palette

#: colour-map anchors (sRGB 0..1) at evenly spaced positions, viridis-like
DEPTH_ANCHORS = np.array([[0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530],
                          [0.207, 0.372, 0.553], [0.164, 0.471, 0.558], [0.128, 0.567, 0.551],
                          [0.135, 0.659, 0.518], [0.267, 0.749, 0.441], [0.478, 0.821, 0.318],
                          [0.741, 0.873, 0.150], [0.993, 0.906, 0.144]])
#: Middlebury colour wheel: (number of hues, from colour, to colour) per segment
WHEEL_SEGMENTS = ((15, (255, 0, 0), (255, 255, 0)), (6, (255, 255, 0), (0, 255, 0)),
                  (4, (0, 255, 0), (0, 255, 255)), (11, (0, 255, 255), (0, 0, 255)),
                  (13, (0, 0, 255), (255, 0, 255)), (6, (255, 0, 255), (255, 0, 0)))


def colour_wheel() -> np.ndarray:
    """(55, 3) float colours of the Middlebury flow wheel, starting at red (direction +x)."""
    rows = []
    for count, start, end in WHEEL_SEGMENTS:
        t = np.arange(count)[:, None] / count
        rows.append(np.asarray(start) * (1 - t) + np.asarray(end) * t)
    return np.concatenate(rows) / 255.0


def depth_range(depth: np.ndarray, background: float = BACKGROUND_DEPTH) -> tuple[float, float]:
    """(nearest, farthest) surface depth of a frame (background left out); (0, 1) when empty."""
    hit = depth[depth < background * 0.999]
    return (float(hit.min()), float(hit.max())) if hit.size else (0.0, 1.0)


def depth_picture(depth: np.ndarray, lo: float, hi: float,
                  background: float = BACKGROUND_DEPTH) -> np.ndarray:
    """(H, W, 1) depth-like values → (H, W, 3) uint8 on the colour map over [lo, hi]."""
    d = depth[..., 0].astype(np.float64)
    t = np.clip((d - lo) / max(hi - lo, 1e-9), 0.0, 1.0) * (len(DEPTH_ANCHORS) - 1)
    t = np.where(np.isfinite(t), t, 0.0)  # NaN samples: drawn as background below
    i = np.minimum(np.floor(t).astype(int), len(DEPTH_ANCHORS) - 2)
    f = (t - i)[..., None]
    rgb = DEPTH_ANCHORS[i] * (1 - f) + DEPTH_ANCHORS[i + 1] * f
    rgb[~(d < background * 0.999)] = 0.0  # also NaN
    return (rgb * 255 + 0.5).astype(np.uint8)


def flow_picture(flow: np.ndarray, max_flow: float | None = None) -> np.ndarray:
    """(H, W, 2) (Δrow, Δcol) → (H, W, 3) uint8 on the Middlebury wheel."""
    dy, dx = flow[..., 0].astype(np.float64), flow[..., 1].astype(np.float64)
    mag = np.hypot(dx, dy)
    scale = max_flow if max_flow else max(float(mag.max()), 1e-9)
    r = mag / scale
    wheel = colour_wheel()
    k = (np.arctan2(-dy, -dx) / np.pi + 1) / 2 * (len(wheel) - 1)
    k0 = np.floor(k).astype(int)
    k1 = (k0 + 1) % len(wheel)
    f = (k - k0)[..., None]
    col = wheel[k0] * (1 - f) + wheel[k1] * f
    inside = (r <= 1)[..., None]
    col = np.where(inside, 1 - r[..., None] * (1 - col), col * 0.75)
    return (np.clip(col, 0, 1) * 255 + 0.5).astype(np.uint8)


def unit_picture(values: np.ndarray) -> np.ndarray:
    """(H, W, C) values in [0, 1] → uint8 (C = 1 repeated to grey RGB); clipped."""
    rgb = np.clip(values, 0, 1) * 255 + 0.5
    return np.repeat(rgb, 3, axis=-1).astype(np.uint8) if values.shape[-1] == 1 else \
        rgb.astype(np.uint8)


def segmentation_picture(labels: np.ndarray) -> np.ndarray:
    """(H, W, 1) integer labels → (H, W, 3) uint8 in the label palette."""
    lab = labels[..., 0].astype(np.int64)
    return label_palette(max(int(lab.max()) + 1, 2))[lab]
