"""Decoded layer frames → RGB(A) pictures: the one colouriser of layers, used by ``kubric view``
and by ``kubric inspect``'s contact sheets. Each layer is drawn by its layer kind
(:class:`kubric.io.encodings.LayerKind`, the colour maps of :mod:`kubric.io.colour_maps`):

* ``image8`` (``rgba`` / ``rgb``): as stored (alpha kept; composited over black on sheets);
* ``tiff`` (``depth`` / ``z``, and e.g. texture_nerf's cut-offs): a perceptual colour map
  (viridis-like: near = dark purple, far = yellow) over ``[lo, hi]`` (default: the frame's
  surfaces); background (no surface, ≥ 0.999 · background depth) black;
* ``scaled`` (flows): the Middlebury colour wheel (Baker et al. 2011): hue = direction of
  (Δcol, Δrow), saturation = magnitude / ``hi`` (the largest magnitude of the frame unless
  given), beyond ``hi`` the colour darkens;
* ``signed_unit`` (``normal``): (n + 1) / 2 as RGB; ``unit`` (``object_coordinates``, ``uv``):
  the values as RGB;
* ``labels`` (``segmentation``): the label palette (:mod:`kubric.io.palette`: the colours of
  segmentation PNGs; 0 black, then distinct hues); :func:`outline` draws only the label
  boundaries, transparent elsewhere, for the overlay; :func:`fill` every object pixel in its
  colour, the background transparent (the filled overlay, blended over the main layer);
* event streams (``events.h5``): :func:`event_picture` accumulates the events of a time
  interval per pixel, drawn by the sign of ON − OFF counts (:data:`EVENT_COLOURS`).
"""

from __future__ import annotations

import numpy as np

from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.io.colour_maps import (  # noqa: F401  (this module's public names before)
    DEPTH_ANCHORS,
    WHEEL_SEGMENTS,
    colour_wheel,
    depth_picture,
    depth_range,
    flow_picture,
    segmentation_picture,
)
from kubric.io.encodings import LAYER_KINDS, LayerKind, layer_kind
from kubric.io.layers import LAYERS
from kubric.io.palette import label_palette  # the colours of segmentation PNGs and sheets
from kubric.io.png_io import encode_png

#: the standard layers, drawn by their kind
STANDARD_PICTURES = tuple(LAYERS)


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


def fill(labels: np.ndarray) -> np.ndarray:
    """(H, W, 4) uint8: every pixel of label > 0 in its palette colour (alpha 255), the
    background (label 0) transparent (alpha 0)."""
    lab = labels[..., 0].astype(np.int64)
    rgba = np.zeros((*lab.shape, 4), dtype=np.uint8)
    rgba[..., :3] = label_palette(max(int(lab.max()) + 1, 2))[lab]
    rgba[..., 3] = np.where(lab > 0, 255, 0)
    return rgba


#: accumulated event frame colours by the sign of (ON − OFF) events at a pixel
EVENT_COLOURS = {"none": (0, 0, 0), "on": (230, 57, 70), "off": (69, 123, 237),
                 "balanced": (150, 150, 150)}


def event_picture(x, y, p, height: int, width: int) -> np.ndarray:
    """(H, W, 3) uint8 accumulated event frame of events at columns ``x``, rows ``y``,
    polarities ``p`` (1 ON, 0 OFF): per pixel, more ON than OFF events ``EVENT_COLOURS["on"]``
    (red), more OFF ``"off"`` (blue), as many of each (at least one) ``"balanced"`` (grey),
    none black."""
    x, y = np.asarray(x, np.int64), np.asarray(y, np.int64)
    if x.size and (x.min() < 0 or y.min() < 0 or x.max() >= width or y.max() >= height):
        raise ValueError(f"event pixels outside the {width}x{height} image: columns "
                         f"{x.min()}..{x.max()}, rows {y.min()}..{y.max()}")
    sign = np.where(np.asarray(p) > 0, 1, -1)
    flat = y * width + x
    net = np.bincount(flat, weights=sign, minlength=height * width).reshape(height, width)
    count = np.bincount(flat, minlength=height * width).reshape(height, width)
    out = np.zeros((height, width, 3), dtype=np.uint8)
    out[(count > 0) & (net == 0)] = EVENT_COLOURS["balanced"]
    out[net > 0] = EVENT_COLOURS["on"]
    out[net < 0] = EVENT_COLOURS["off"]
    return out


def kind_of(layer: str, kind: str | LayerKind | None = None) -> LayerKind:
    """The layer kind that draws ``layer``: a standard layer's own, else ``kind`` (a layer a
    recipe declares); KeyError (one line) when there is none."""
    if layer in LAYERS:
        return LAYERS[layer].type
    if kind is None:
        raise KeyError(f"no picture for layer {layer!r}; allowed: {', '.join(STANDARD_PICTURES)}, "
                       "or a layer of a known kind")
    try:
        return layer_kind(kind)
    except ValueError:
        raise KeyError(f"no picture for layer kind {kind!r}; allowed: "
                       f"{sorted(LAYER_KINDS)}") from None


def picture(layer: str, frame: np.ndarray, lo: float | None = None,
            hi: float | None = None, kind: str | LayerKind | None = None) -> np.ndarray:
    """The (H, W, 3|4) uint8 picture of one decoded frame (module doc); ``lo`` / ``hi``: the
    range of a depth-like layer or, for flows, ``hi`` = the magnitude shown fully saturated. A
    layer a recipe declares is drawn by its ``kind``."""
    return kind_of(layer, kind).draw(frame, lo, hi)


def to_png(pixels: np.ndarray) -> bytes:
    return encode_png(np.ascontiguousarray(pixels))


def layer_pictures(name: str, layer: np.ndarray, background: float = BACKGROUND_DEPTH,
                   kind: str | LayerKind | None = None) -> np.ndarray:
    """(T, H, W, C) layer → (T, H, W, 3) uint8 pictures on one scale for all frames (depth over
    the scene's nearest and farthest surface, flows saturated at the scene's largest
    magnitude); RGBA is composited over black."""
    return kind_of(name, kind).pictures(layer, background)
