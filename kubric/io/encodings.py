"""Every encoding, declared once: each is a class, registered under the name schemas and recipes
store (``LayerFormat.kind``, ``Feature.encoding``), so stored schema JSON keeps working.

**Layer kinds** (:data:`LAYER_KINDS`: how a scene directory stores a per-frame layer) know

* their *file form*: :meth:`LayerKind.encoder` checks a (T, H, W, C) layer and returns the frame
  encoder (``kubric.io.layers.write_image_dict``), :meth:`LayerKind.read` the stored samples of
  one file;
* their *packed form* (what ``kubric pack`` stores — upstream Kubric's layout):
  :meth:`LayerKind.packed` turns the stored samples into a feature of a given dtype,
  :meth:`LayerKind.value_range` is the [min, max] a ``range:`` feature holds;
* their *decode*, one per kind: :meth:`LayerKind.decode` maps stored or packed integer samples to
  physical units (flow in pixels over the per-scene range, depth in metres, normals as unit
  vectors in [−1, 1], object coordinates and UV in [0, 1]); floats are already physical;
* how they *draw* themselves (:meth:`LayerKind.draw`, :meth:`LayerKind.pictures`: ``kubric
  view`` and ``kubric inspect``).

=================  =======================================  =====================================
kind               file                                     decode of integer samples q
=================  =======================================  =====================================
``image8``         8-bit PNG (colour)                       none (uint8 colour)
``tiff``           float32 TIFF (metres)                    ``q / 65535 · (max − min) + min``
``labels``         8-bit palette / 16-bit grey PNG          none (integer labels)
``scaled``         16-bit PNG over the scene's range        ``q / 65535 · (max − min) + min``
``signed_unit``    16-bit PNG of [−1, 1]                    ``q / 65535 · 2 − 1``
``unit``           16-bit PNG of [0, 1]                     ``q / 65535``
``bitmask``        16-bit 4-channel PNG of bit planes       none (bits; :mod:`kubric.io.bitmask`)
``vector``         zlib float32 TIFF, 3 channels (metres)   as ``tiff``
``edge_bits``      8-bit grey PNG of edge flags             none (bits)
=================  =======================================  =====================================

(``signed_unit`` / ``unit`` files written from uint8 samples decode as ``k / 255`` of the
interval.) **Feature encodings** (:data:`FEATURE_ENCODINGS`: how a packed example stores a
feature: ``none``, ``png``, ``zlib``, ``text``, ``class_label``, ``bbox``) know their contract
(:meth:`FeatureEncoding.check`), the value the packer stores (:meth:`FeatureEncoding.stored`),
their TFDS feature connector and serialisable value, and the dtype the loader gives.

Adding one is one class with :func:`register`: ``@register class Mine(LayerKind): name = ...``.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping

import numpy as np

from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.errors import InputError
from kubric.io import bitmask, colour_maps, png_io, tiff_io

#: the largest 16-bit sample
UINT16_MAX = png_io.UINT16_MAX
#: float noise a [−1, 1] / [0, 1] layer may exceed its interval by (clipped when written)
RANGE_TOLERANCE = 1e-4


class LayerKind(abc.ABC):
    """How one kind of layer is stored, packed, decoded and drawn (module doc)."""

    #: the stored name (``LayerFormat.kind``)
    name: str = ""
    #: one line for the docs
    doc: str = ""
    #: its layers get ``{"min", "max"}`` in ``data_ranges.json`` when written
    records_range: bool = False
    #: its files decode only with the ``data_ranges.json`` range
    range_in_file: bool = False
    #: the viewer offers a [lo, hi] range to draw it over (the scene's first frame's)
    adjustable_range: bool = False

    # ------------------------------------------------------------------ file form
    @abc.abstractmethod
    def encoder(self, arr: np.ndarray, what: str) -> tuple[Callable, dict | None]:
        """(frame encoder → file bytes, the layer's range for data_ranges.json or None) of a
        checked (T, H, W, C) layer."""

    def read(self, data: bytes, what: str) -> np.ndarray:
        """The stored (H, W, C) samples of one file."""
        return png_io.decode_png(data, what)[0]

    # ------------------------------------------------------------------ decode (one per kind)
    def decode(self, samples: np.ndarray, value_range=None, what: str = "") -> np.ndarray:
        """Stored or packed samples → physical values (identity for colour and labels)."""
        return samples

    def from_file(self, samples: np.ndarray, value_range=None, what: str = "") -> np.ndarray:
        """A file's samples decoded as ``read_image_dict`` gives them (the renderer's layer)."""
        return self.decode(samples, value_range, what)

    def needs_range(self, dtype) -> bool:
        """Whether :meth:`decode` of samples of ``dtype`` needs the per-scene range."""
        return False

    # ------------------------------------------------------------------ packed form
    def value_range(self, samples: Callable, stored: Mapping | None, what: str) -> np.ndarray:
        """[min, max] float32 a ``range:`` feature holds: that of the finite samples
        (``samples()``: the layer's stored samples; ``stored``: its data_ranges.json entry)."""
        samples = samples()
        finite = samples[np.isfinite(samples)]
        if finite.size != samples.size:
            raise InputError(f"{what} has NaN / inf samples")
        return np.array([finite.min(), finite.max()], dtype=np.float32)

    def packed(self, samples: np.ndarray, dtype: np.dtype, value_range: Callable,
               what: str) -> np.ndarray:
        """The stored samples as a feature of ``dtype`` (``value_range()``: the layer's range,
        asked for only when needed); integers must fit."""
        if samples.dtype == dtype:
            return samples
        if samples.dtype.kind in "ui" and dtype.kind in "ui" and samples.size and \
                samples.max() > np.iinfo(dtype).max:
            raise InputError(f"{what} holds values up to {samples.max()}, the feature is {dtype}")
        return samples.astype(dtype)

    # ------------------------------------------------------------------ drawing
    @abc.abstractmethod
    def draw(self, frame: np.ndarray, lo: float | None = None, hi: float | None = None,
             background: float = BACKGROUND_DEPTH) -> np.ndarray:
        """(H, W, C) decoded frame → (H, W, 3|4) uint8 picture."""

    def scale(self, layer: np.ndarray, background: float = BACKGROUND_DEPTH) -> tuple:
        """(lo, hi) that draws every frame of a (T, H, W, C) layer on one scale."""
        return None, None

    def pictures(self, layer: np.ndarray, background: float = BACKGROUND_DEPTH) -> np.ndarray:
        """(T, H, W, C) decoded layer → (T, H, W, 3) uint8 pictures on one scale."""
        lo, hi = self.scale(layer, background)
        return np.stack([self.draw(frame, lo, hi, background)[..., :3] for frame in layer])


class FeatureEncoding:
    """How a packed example stores one kind of feature (module doc)."""

    name: str = ""
    doc: str = ""
    #: (T, ...) per-frame arrays: the loader stacks them
    per_frame: bool = False

    def check(self, feature, what: str) -> None:
        """Raise ValueError (one line) where ``feature`` breaks this encoding's contract."""
        if feature.names:
            raise ValueError(f"{what}: class labels need names and encoding 'class_label'")

    def stored(self, feature, value, what: str):
        """A scene's value → the value the packed example holds (before the dtype cast)."""
        return value

    def value_dtype(self, feature) -> np.dtype:
        """The dtype of the value the packer and the loader give."""
        return np.dtype(feature.dtype)

    def connector(self, tfds, feature, shape: tuple, dtype):
        """The TFDS feature connector (``shape``: the concrete shape)."""
        if feature.shape and feature.shape[0] == "V":
            return tfds.features.Sequence(tfds.features.Tensor(shape=shape[1:], dtype=dtype))
        return tfds.features.Tensor(shape=shape, dtype=dtype)

    def serialisable(self, tfds, feature, value):
        """The packed value in the form TFDS's connector encodes."""
        return value


#: layer kinds by stored name
LAYER_KINDS: dict[str, LayerKind] = {}
#: feature encodings by stored name
FEATURE_ENCODINGS: dict[str, FeatureEncoding] = {}


def register(cls: type) -> type:
    """Class decorator: add an instance of a :class:`LayerKind` / :class:`FeatureEncoding`
    subclass to its registry under ``cls.name``; returns the class."""
    table = LAYER_KINDS if issubclass(cls, LayerKind) else FEATURE_ENCODINGS \
        if issubclass(cls, FeatureEncoding) else None
    if table is None or not cls.name:
        raise TypeError(f"register: {cls.__name__} is not a named LayerKind or FeatureEncoding")
    table[cls.name] = cls()
    return cls


def layer_kind(kind) -> LayerKind:
    """The registered layer kind of a name (or a kind / kind class itself); ValueError naming
    the known kinds otherwise."""
    if isinstance(kind, type) and issubclass(kind, LayerKind):
        kind = kind.name
    if isinstance(kind, LayerKind):
        kind = kind.name
    if not isinstance(kind, str) or kind not in LAYER_KINDS:
        raise ValueError(f"layer kind {kind!r} is not one of {tuple(LAYER_KINDS)}")
    return LAYER_KINDS[kind]


def feature_encoding(name: str) -> FeatureEncoding:
    """The registered feature encoding ``name``; ValueError naming the known ones otherwise."""
    if not isinstance(name, str) or name not in FEATURE_ENCODINGS:
        raise ValueError(f"encoding {name!r} is not one of {tuple(FEATURE_ENCODINGS)}")
    return FEATURE_ENCODINGS[name]


def dequantise(q: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """16-bit samples of [lo, hi] → float32 ``q / 65535 · (hi − lo) + lo`` (the inverse of
    :func:`kubric.io.png_io.scale_to_uint16`, exact to half a step)."""
    return png_io.unscale_from_uint16(q, lo, hi)


def _with_zero_channel(encode_png: Callable, quantise: Callable) -> Callable:
    """Frame encoder quantising one (H, W, C) frame at a time (C = 2 gets a zero third channel,
    as upstream's flow PNGs): a layer's 16-bit copy and float64 temporaries never exist whole."""
    def encode(frame: np.ndarray) -> bytes:
        q = quantise(frame)
        if q.shape[-1] == 2:
            q = np.concatenate([q, np.zeros_like(q[..., :1])], axis=-1)
        return encode_png(q)
    return encode


# ------------------------------------------------------------------------------ layer kinds
@register
class Image8(LayerKind):
    name = "image8"
    doc = "uint8 colour → 8-bit PNG"

    def encoder(self, arr, what):
        if arr.dtype != np.uint8:
            raise TypeError(f"{what}: expected dtype uint8 (8-bit PNG), got {arr.dtype}")
        return png_io.encode_png, None

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        return frame

    def pictures(self, layer, background=BACKGROUND_DEPTH):
        """RGBA composited over black."""
        rgb = layer[..., :3].astype(np.float32)
        alpha = layer[..., 3:4].astype(np.float32) / 255.0 if layer.shape[-1] == 4 else 1.0
        return (rgb * alpha).astype(np.uint8)


@register
class Tiff(LayerKind):
    name = "tiff"
    doc = "float (metres for depth) → float32 TIFF; packed as float32 or quantised to uint16"
    records_range = True
    adjustable_range = True

    def encoder(self, arr, what):
        if arr.dtype.kind != "f":
            raise TypeError(f"{what}: expected float depth values, got dtype {arr.dtype}")
        finite = arr[np.isfinite(arr)]  # NaN / inf pixels are stored but left out of the range
        value_range = {"min": float(finite.min()), "max": float(finite.max())} if finite.size \
            else None
        return tiff_io.encode_tiff, value_range

    def read(self, data, what):
        return tiff_io.decode_tiff(data, what).astype(np.float32, copy=False)

    def needs_range(self, dtype):
        return np.dtype(dtype).kind in "ui"

    def decode(self, samples, value_range=None, what=""):
        if samples.dtype.kind == "f":
            return samples.astype(np.float32, copy=False)
        if value_range is None:
            raise InputError(f"{what}: quantised samples need the layer's range to decode")
        return dequantise(samples, *png_io.range_pair(value_range, what))

    def packed(self, samples, dtype, value_range, what):
        if samples.dtype.kind == "f" and dtype == np.uint16:
            lo, hi = (float(v) for v in value_range())
            return png_io.scale_to_uint16(samples, lo, hi)
        return super().packed(samples, dtype, value_range, what)

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """The depth colour map over [lo, hi] (default: the frame's surfaces), background
        black."""
        if lo is None or hi is None:
            lo, hi = colour_maps.depth_range(frame, background)
        return colour_maps.depth_picture(frame, lo, hi, background)

    def scale(self, layer, background=BACKGROUND_DEPTH):
        return colour_maps.depth_range(layer, background)


@register
class Labels(LayerKind):
    name = "labels"
    doc = "integer labels → 8-bit palette PNG (largest label ≤ 255) or 16-bit grey PNG"

    def encoder(self, arr, what):
        labels, max_label = png_io.check_labels(arr.reshape(-1, arr.shape[2], 1), what)
        bitdepth = 8 if max_label <= 255 else 16
        return (lambda frame: png_io.encode_labels(frame, max_label, None, bitdepth, what)), None

    def from_file(self, samples, value_range=None, what=""):
        return samples.astype(np.uint32)  # the renderer's dtype; packed labels keep theirs

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        return colour_maps.segmentation_picture(frame)


class Quantised16(LayerKind):
    """A float layer stored as 16-bit samples of an interval: :meth:`interval` is [lo, hi]."""

    @abc.abstractmethod
    def interval(self, value_range, what: str) -> tuple[float, float]:
        """[lo, hi] of the 16-bit samples (from the scene's range where it has one)."""

    @abc.abstractmethod
    def quantise(self, arr: np.ndarray, what: str) -> tuple[Callable, dict | None]:
        """(per-frame quantiser, range for data_ranges.json) of a checked float layer."""

    def encoder(self, arr, what):
        quantise, value_range = self.quantise(arr, what)
        return _with_zero_channel(png_io.encode_png, quantise), value_range

    def decode(self, samples, value_range=None, what=""):
        if samples.dtype.kind == "f":
            return samples.astype(np.float32, copy=False)
        lo, hi = self.interval(value_range, what)
        if samples.dtype == np.uint8 and not self.range_in_file:  # written from uint8 samples
            return (lo + samples.astype(np.float64) * ((hi - lo) / 255.0)).astype(np.float32)
        if samples.dtype != np.uint16:
            raise InputError(f"{what}: expected 16-bit samples, got {samples.dtype}")
        return dequantise(samples, lo, hi)


@register
class Scaled(Quantised16):
    name = "scaled"
    doc = "float → 16-bit PNG over ONE [min, max] per layer per scene (data_ranges.json)"
    records_range = True
    range_in_file = True

    def interval(self, value_range, what):
        if value_range is None:
            raise InputError(f"{what}: a scaled layer needs its range to decode")
        return png_io.range_pair(value_range, what)

    def needs_range(self, dtype):
        return np.dtype(dtype).kind in "ui"

    def quantise(self, arr, what):
        value_range = png_io.float_range(arr, what)
        lo, hi = value_range["min"], value_range["max"]
        return (lambda frame: png_io.scale_to_uint16(frame, lo, hi)), value_range

    def value_range(self, samples, stored, what):
        if stored is None:
            raise InputError(f"{what}: data_ranges.json has no range for it")
        return np.array([stored["min"], stored["max"]], dtype=np.float32)

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """Flows (C = 2): the colour wheel saturated at ``hi``; other channel counts: the
        frame's values over their own range as RGB."""
        if frame.shape[-1] != 2:
            span = max(float(np.ptp(frame)), 1e-9)
            return colour_maps.unit_picture((frame - frame.min()) / span)
        return colour_maps.flow_picture(frame, hi)

    def scale(self, layer, background=BACKGROUND_DEPTH):
        if layer.shape[-1] != 2:
            return None, None
        return None, max(float(np.hypot(layer[..., 0], layer[..., 1]).max()), 1e-9)


class FixedInterval(Quantised16):
    """16-bit samples of a fixed interval (:attr:`lo`, :attr:`hi`); uint8 / uint16 input is
    stored as it is (already quantised, as upstream accepted)."""

    lo, hi = 0.0, 1.0

    def interval(self, value_range, what):
        return self.lo, self.hi

    def encoder(self, arr, what):
        if arr.dtype in (np.uint8, np.uint16):
            return png_io.encode_png, None
        return super().encoder(arr, what)

    def quantise(self, arr, what):
        if arr.dtype.kind != "f":
            raise TypeError(f"{what}: expected float values in [{self.lo}, {self.hi}] or "
                            f"quantised uint8 / uint16 samples, got dtype {arr.dtype}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{what}: values must be finite, found NaN or inf")
        vmin, vmax = float(arr.min()), float(arr.max())
        if vmin < self.lo - RANGE_TOLERANCE or vmax > self.hi + RANGE_TOLERANCE:
            raise ValueError(f"{what}: values must lie in [{self.lo}, {self.hi}], got range "
                             f"[{vmin}, {vmax}]")
        return (lambda frame: png_io.scale_to_uint16(frame, self.lo, self.hi)), None

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """The values mapped from the interval to [0, 1] as RGB."""
        return colour_maps.unit_picture((frame - self.lo) / (self.hi - self.lo))


@register
class SignedUnit(FixedInterval):
    name = "signed_unit"
    doc = "float in [−1, 1] (unit normals) → 16-bit PNG of round((n + 1) / 2 · 65535)"
    lo = -1.0


@register
class Unit(FixedInterval):
    name = "unit"
    doc = "float in [0, 1] (object coordinates, UV) → 16-bit PNG of round(x · 65535)"


class BitFlags(LayerKind):
    """Integer bit flags stored as they are in a PNG of :attr:`dtype` samples."""

    dtype = np.uint8
    #: zlib level: sparse bits compress ~2.5× better at 9 than at the default 2, at little cost
    #: (docs/scene-format.md#amodal-segmentation)
    compress_level = 9

    def encoder(self, arr, what):
        if arr.dtype != self.dtype:
            raise TypeError(f"{what}: expected {np.dtype(self.dtype).name} {self.name} samples, "
                            f"got {arr.dtype}")
        return (lambda frame: png_io.encode_png(frame, compress_level=self.compress_level)), None


@register
class Bitmask(BitFlags):
    name = "bitmask"
    doc = ("overlapping masks as bits → 16-bit 4-channel PNG: mask k is bit k % 16 of channel "
           "k // 16 (kubric.io.bitmask; amodal segmentation)")
    dtype = np.uint16

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """How many masks cover each pixel, in the label palette."""
        return colour_maps.segmentation_picture(bitmask.mask_counts(frame)[..., None])


@register
class Vector(Tiff):
    name = "vector"
    doc = ("float 3-vectors (metres; scene flow) → zlib-compressed float32 TIFF, 0 where "
           "nothing is hit")
    adjustable_range = False  # drawn over its own largest length

    def encoder(self, arr, what):
        if arr.dtype.kind != "f" or not np.isfinite(arr).all():
            raise TypeError(f"{what}: expected finite float vectors, got dtype {arr.dtype}")
        return (lambda frame: tiff_io.encode_tiff(frame, compress=True)), \
            {"min": float(arr.min()), "max": float(arr.max())}

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """The vector's length on the depth colour map over [0, hi]; zero vectors black."""
        length = np.linalg.norm(frame, axis=-1, keepdims=True)
        length = np.where(length > 0, length, background)
        return colour_maps.depth_picture(length, 0.0, hi or float(length[length < background]
                                                                  .max(initial=1.0)), background)

    def scale(self, layer, background=BACKGROUND_DEPTH):
        return 0.0, float(np.linalg.norm(layer, axis=-1).max(initial=0.0)) or 1.0


@register
class EdgeBits(BitFlags):
    name = "edge_bits"
    doc = ("per-pixel edge flags → 8-bit grey PNG: bits 0–3 a boundary towards the pixel "
           "above / below / left / right, bits 4–7 this pixel occludes across that edge")

    def draw(self, frame, lo=None, hi=None, background=BACKGROUND_DEPTH):
        """White: boundary pixels on the occluding side; grey: on the occluded side."""
        bits = frame[..., 0]
        grey = np.where(bits >> 4, 255, np.where(bits & 15, 96, 0)).astype(np.uint8)
        return np.repeat(grey[..., None], 3, axis=-1)


# ------------------------------------------------------------------------------ feature encodings
@register
class NoEncoding(FeatureEncoding):
    name = "none"
    doc = "a tensor (or, with a leading V, a sequence of them)"


class _Frames(FeatureEncoding):
    per_frame = True


@register
class Png(_Frames):
    name = "png"
    doc = "(T, H, W, C) uint8 / uint16, one PNG per frame: Sequence(Image(png))"

    def check(self, feature, what):
        super().check(feature, what)
        if feature.shape[:1] != ("T",) or len(feature.shape) != 4 or \
                feature.dtype not in ("uint8", "uint16"):
            raise ValueError(f"{what}: png features are (T, H, W, C) uint8 / uint16")

    def connector(self, tfds, feature, shape, dtype):
        return tfds.features.Sequence(tfds.features.Image(shape=shape[1:], dtype=dtype,
                                                          encoding_format="png"),
                                      length=shape[0])

    def serialisable(self, tfds, feature, value):
        return [png_io.encode_png(np.ascontiguousarray(frame)) for frame in value]


@register
class Zlib(_Frames):
    name = "zlib"
    doc = "(T, ...) arrays, zlib-compressed per frame: Sequence(Tensor(zlib))"

    def connector(self, tfds, feature, shape, dtype):
        return tfds.features.Sequence(tfds.features.Tensor(
            shape=shape[1:], dtype=dtype, encoding=tfds.features.Encoding.ZLIB), length=shape[0])


@register
class Text(FeatureEncoding):
    name = "text"
    doc = "a string (or, with one named dimension, a list of strings)"

    def connector(self, tfds, feature, shape, dtype):
        return tfds.features.Sequence(tfds.features.Text()) if feature.shape else \
            tfds.features.Text()


@register
class ClassLabel(FeatureEncoding):
    name = "class_label"
    doc = "a name of ``names``, stored as its int64 index"

    def check(self, feature, what):
        if not feature.names:
            raise ValueError(f"{what}: class labels need names and encoding 'class_label'")

    def stored(self, feature, value, what):
        if value not in feature.names:
            raise ValueError(f"{what}: {value!r} is not one of {feature.names}")
        return np.int64(feature.names.index(value))

    def value_dtype(self, feature):
        return np.dtype(np.int64)

    def connector(self, tfds, feature, shape, dtype):
        return tfds.features.ClassLabel(names=list(feature.names))


@register
class BBox(FeatureEncoding):
    name = "bbox"
    doc = "normalised (ymin, xmin, ymax, xmax) boxes: Sequence(BBoxFeature)"

    def connector(self, tfds, feature, shape, dtype):
        return tfds.features.Sequence(tfds.features.BBoxFeature())

    def serialisable(self, tfds, feature, value):
        to_boxes = lambda boxes: [tfds.features.BBox(*(float(c) for c in b)) for b in boxes]
        return [to_boxes(v) for v in value] if feature.sequence else to_boxes(value)
