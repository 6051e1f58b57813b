"""Decoded layer frames → RGB(A) pictures: the one colouriser of layers, used by ``kubric view``
and by ``kubric inspect``'s contact sheets.

* ``rgba`` / ``rgb``: as stored (alpha kept).
* ``depth`` / ``z``: a perceptual colour map (viridis-like: near = dark purple, far = yellow)
  over ``[lo, hi]`` metres; background (no surface, ≥ 0.999 · background depth) black.
* flows: the Middlebury colour wheel (Baker et al. 2011): hue = direction of (Δcol, Δrow),
  saturation = magnitude / ``max_flow`` (the largest magnitude of the frame unless given),
  beyond ``max_flow`` the colour darkens.
* ``normal``: (n + 1) / 2 as RGB; ``object_coordinates`` and ``uv``: the values as RGB.
* ``segmentation``: the label palette (:mod:`kubric.io.palette`: the colours of segmentation
  PNGs; 0 black, then distinct hues);
  :func:`outline` draws only the label boundaries, transparent elsewhere, for the overlay.
"""

from __future__ import annotations

import numpy as np

from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.io.palette import label_palette  # the colours of segmentation PNGs and sheets
from kubric.io.png_io import encode_png

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


def depth_picture(depth: np.ndarray, lo: float, hi: float,
                  background: float = BACKGROUND_DEPTH) -> np.ndarray:
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


def segmentation_picture(labels: np.ndarray) -> np.ndarray:
    lab = labels[..., 0].astype(np.int64)
    return label_palette(max(int(lab.max()) + 1, 2))[lab]


def outline(labels: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: palette colour on pixels whose right / lower / left / upper neighbour has
    another label (boundaries of every segment, background included), alpha 0 elsewhere."""
    lab = labels[..., 0].astype(np.int64)
    edge = np.zeros(lab.shape, dtype=bool)
    edge[:, 1:] |= lab[:, 1:] != lab[:, :-1]
    edge[:, :-1] |= lab[:, 1:] != lab[:, :-1]
    edge[1:, :] |= lab[1:, :] != lab[:-1, :]
    edge[:-1, :] |= lab[1:, :] != lab[:-1, :]
    edge &= lab > 0  # draw each object's own rim, not the background's
    rgba = np.zeros((*lab.shape, 4), dtype=np.uint8)
    rgba[..., :3] = label_palette(max(int(lab.max()) + 1, 2))[lab]
    rgba[..., 3] = np.where(edge, 255, 0)
    return rgba


#: the picture of each layer kind (kubric.io.layers.LayerFormat.kind) for layers a recipe
#: declares beyond the standard ones (e.g. klevr's semantic labels, texture_nerf's cut-offs)
KIND_PICTURES = {"image8": "rgba", "labels": "segmentation", "tiff": "depth",
                 "signed_unit": "normal", "unit": "uv", "scaled": "flow"}


def picture(layer: str, frame: np.ndarray, lo: float | None = None,
            hi: float | None = None, kind: str | None = None) -> np.ndarray:
    """The (H, W, 3|4) uint8 picture of one decoded frame (module doc); ``lo`` / ``hi``: the
    depth range (metres) or, for flows, ``hi`` = the magnitude shown fully saturated. A layer a
    recipe declares is drawn by its ``kind`` (:data:`KIND_PICTURES`): labels like the
    segmentation, float TIFFs with the depth colour map over their own range."""
    own = kind is not None and layer not in STANDARD_PICTURES
    if own:
        if kind not in KIND_PICTURES:
            raise KeyError(f"no picture for layer kind {kind!r}; allowed: {sorted(KIND_PICTURES)}")
        if kind == "tiff" and (lo is None or hi is None):
            finite = frame[np.isfinite(frame)]
            lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
            if hi <= lo:
                hi = lo + 1.0
        layer = KIND_PICTURES[kind]
        if kind == "scaled" and frame.shape[-1] != 2:
            frame, layer = np.clip((frame - frame.min()) / max(np.ptp(frame), 1e-9), 0, 1), "uv"
    if layer in ("rgba", "rgb"):
        return frame
    if layer in ("depth", "z"):
        if lo is None or hi is None:
            lo, hi = depth_range(frame)
        return depth_picture(frame, lo, hi, background=np.inf if own else BACKGROUND_DEPTH)
    if layer.endswith("flow"):
        return flow_picture(frame, hi)
    if layer == "normal":
        return ((np.clip(frame, -1, 1) + 1) / 2 * 255 + 0.5).astype(np.uint8)
    if layer in ("object_coordinates", "uv"):
        rgb = np.clip(frame, 0, 1) * 255 + 0.5
        return np.repeat(rgb, 3, axis=-1).astype(np.uint8) if frame.shape[-1] == 1 else \
            rgb.astype(np.uint8)
    if layer == "segmentation":
        return segmentation_picture(frame)
    raise KeyError(f"no picture for layer {layer!r}; allowed: {', '.join(STANDARD_PICTURES)}, "
                   "or a layer of a known kind")


STANDARD_PICTURES = ("rgba", "rgb", "depth", "z", "forward_flow", "backward_flow", "flow",
                     "normal", "object_coordinates", "uv", "segmentation")


def depth_range(depth: np.ndarray, background: float = BACKGROUND_DEPTH) -> tuple[float, float]:
    """(nearest, farthest) surface depth of a frame (background left out); (0, 1) when empty."""
    hit = depth[depth < background * 0.999]
    return (float(hit.min()), float(hit.max())) if hit.size else (0.0, 1.0)


def to_png(pixels: np.ndarray) -> bytes:
    return encode_png(np.ascontiguousarray(pixels))


def layer_pictures(name: str, layer: np.ndarray,
                   background: float = BACKGROUND_DEPTH) -> np.ndarray:
    """(T, H, W, C) layer → (T, H, W, 3) uint8 pictures on one scale for all frames (depth over
    the scene's nearest and farthest surface, flows saturated at the scene's largest
    magnitude); RGBA is composited over black."""
    if name in ("rgba", "rgb"):
        rgb = layer[..., :3].astype(np.float32)
        alpha = layer[..., 3:4].astype(np.float32) / 255.0 if layer.shape[-1] == 4 else 1.0
        return (rgb * alpha).astype(np.uint8)
    lo = hi = None
    if name in ("depth", "z"):
        lo, hi = depth_range(layer, background)
    elif name.endswith("flow"):
        hi = max(float(np.hypot(layer[..., 0], layer[..., 1]).max()), 1e-9)
    return np.stack([picture(name, frame, lo, hi)[..., :3] for frame in layer])
