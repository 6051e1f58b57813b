"""PNG files: our numpy + zlib encoder (8/16-bit, 1–4 channels, palette), libpng decoding.

Sample conventions (all images are ``(H, W, C)`` arrays, row 0 at the top):

* :func:`write_png` stores ``uint8`` data as 8-bit and ``uint16`` data as 16-bit samples; C = 1
  (grey), 3 (RGB) or 4 (RGBA). C = 2 is padded with a zero third channel and stored as RGB (as
  upstream Kubric did for flow), so it reads back with C = 3. Other integer dtypes must lie in
  [0, 65535] and are stored as 16-bit; floats must lie in [0, 1] and are stored as
  ``floor(x * 65535)`` in 16 bits — truncated exactly as upstream Kubric's ``write_png`` did, so
  the same floats give the same file (docs/compatibility.md; the scene directory's 16-bit layers
  and :func:`write_scaled_png` round instead). Nothing is ever wrapped or clipped: out-of-range
  values raise.
* :func:`write_palette_png` stores integer labels: an 8-bit palette PNG while the largest label is
  ≤ 255, otherwise a 16-bit grey PNG (labels > 65535 raise ``ValueError``).
* :func:`write_scaled_png` maps floats to 16 bits as ``round((v - min) / (max - min) * 65535)``
  and returns ``{"min": min, "max": max}``; ``max == min`` stores zeros (no division by zero).
  The decode is ``q / 65535 * (max - min) + min``, exact to half a step, ``(max - min) / 131070``.

Codecs, chosen by measurement (``benchmarks/bench_codecs.py``; README "PNG and TIFF codecs"):
the encoder is ours — it writes IHDR, optional PLTE, one IDAT and IEND, every row with the same
filter (:data:`DEFAULT_FILTER`), zlib level :data:`DEFAULT_COMPRESS_LEVEL` and the zlib strategy
of :func:`default_strategy` (run-length for 8-bit colour, where it is faster and smaller; zlib's
default for 16-bit and palette data, whose run-length files decode slower). It is as fast as
libpng at the same settings (zlib does the work) and deterministic: no timestamps or text chunks.
Reading uses libpng through ``imagecodecs`` (16-bit colour included, any filter), except palette
PNGs, which Pillow reads (it keeps the indices and the palette).
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Mapping, Sequence

import numpy as np

from kubric.errors import InputError
from kubric.io.palette import label_palette
from kubric.io.paths import PathLike, as_path, atomic_write_bytes, read_bytes

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: channels → PNG colour type (grey, grey+alpha, RGB, RGBA); 3 is the palette type.
COLOR_TYPE_FOR_CHANNELS = {1: 0, 2: 4, 3: 2, 4: 6}
CHANNELS_FOR_COLOR_TYPE = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}
PALETTE_COLOR_TYPE = 3
FILTERS = {"none": 0, "sub": 1, "up": 2, "paeth": 4}
STRATEGIES = {"default": zlib.Z_DEFAULT_STRATEGY, "filtered": zlib.Z_FILTERED, "rle": zlib.Z_RLE}
DEFAULT_FILTER = "up"
DEFAULT_COMPRESS_LEVEL = 2
UINT16_MAX = 65535


# ----------------------------------------------------------------------------------- encoding
def _chunk(tag: bytes, payload: bytes) -> bytes:
    return (struct.pack(">I", len(payload)) + tag + payload
            + struct.pack(">I", zlib.crc32(payload, zlib.crc32(tag)) & 0xFFFFFFFF))


def _filter_rows(raw: np.ndarray, bpp: int, method: str) -> np.ndarray:
    """Apply one PNG filter to every row of ``raw`` (H, row_bytes) uint8; prepend the type byte."""
    if method not in FILTERS:
        raise ValueError(f"PNG filter must be one of {sorted(FILTERS)}, got {method!r}")
    height, row_bytes = raw.shape
    out = np.empty((height, row_bytes + 1), dtype=np.uint8)
    out[:, 0] = FILTERS[method]
    body = out[:, 1:]
    if method == "none":
        body[:] = raw
    elif method == "sub":
        body[:, :bpp] = raw[:, :bpp]
        np.subtract(raw[:, bpp:], raw[:, :-bpp], out=body[:, bpp:])
    elif method == "up":
        body[:1] = raw[:1]
        np.subtract(raw[1:], raw[:-1], out=body[1:])
    else:  # paeth: predictor from the raw left (a), up (b) and up-left (c) bytes
        x = raw.astype(np.int16)
        a = np.zeros_like(x)
        a[:, bpp:] = x[:, :-bpp]
        b = np.zeros_like(x)
        b[1:] = x[:-1]
        c = np.zeros_like(x)
        c[1:, bpp:] = x[:-1, :-bpp]
        p = a + b - c
        pa, pb, pc = np.abs(p - a), np.abs(p - b), np.abs(p - c)
        pred = np.where((pa <= pb) & (pa <= pc), a, np.where(pb <= pc, b, c))
        body[:] = (x - pred).astype(np.uint8)
    return out


def default_strategy(bitdepth: int, palette: bool = False) -> str:
    """The measured zlib strategy: "rle" for 8-bit images (rendered RGBA: ~2× faster to encode,
    ~10 % smaller, faster to decode), "default" for 16-bit and palette data (run-length files
    there decode 2–4× slower, and object-coordinate ramps grow ~6×)."""
    return "rle" if bitdepth == 8 and not palette else "default"


def encode_png(pixels: np.ndarray, *, palette: np.ndarray | None = None,
               compress_level: int = DEFAULT_COMPRESS_LEVEL,
               filter_method: str = DEFAULT_FILTER, strategy: str | None = None) -> bytes:
    """Encode ``pixels`` (H, W, C) uint8/uint16, C in 1..4, as PNG bytes (already validated).

    With ``palette`` ((N, 3) uint8, N ≤ 256) the single-channel uint8 ``pixels`` are palette
    indices (colour type 3, filter "none" as the PNG spec recommends for palette images).
    ``strategy``: a zlib strategy of :data:`STRATEGIES`; None uses :func:`default_strategy`.
    """
    height, width, channels = pixels.shape
    if height < 1 or width < 1:
        raise ValueError(f"PNG image must be at least 1×1 pixels, got shape {pixels.shape}")
    bitdepth = 16 if pixels.dtype == np.uint16 else 8
    if palette is not None:
        color_type, filter_method = PALETTE_COLOR_TYPE, "none"
    else:
        color_type = COLOR_TYPE_FOR_CHANNELS[channels]
    samples = pixels.astype(">u2", copy=False) if bitdepth == 16 else pixels
    raw = np.ascontiguousarray(samples).view(np.uint8).reshape(height, -1)
    filtered = _filter_rows(raw, channels * bitdepth // 8, filter_method)
    ihdr = struct.pack(">IIBBBBB", width, height, bitdepth, color_type, 0, 0, 0)
    parts = [PNG_SIGNATURE, _chunk(b"IHDR", ihdr)]
    if palette is not None:
        parts.append(_chunk(b"PLTE", np.ascontiguousarray(palette, dtype=np.uint8).tobytes()))
    strategy = default_strategy(bitdepth, palette is not None) if strategy is None else strategy
    if strategy not in STRATEGIES:
        raise ValueError(f"zlib strategy must be one of {sorted(STRATEGIES)}, got {strategy!r}")
    deflate = zlib.compressobj(compress_level, zlib.DEFLATED, 15, 8, STRATEGIES[strategy])
    parts.append(_chunk(b"IDAT", deflate.compress(filtered) + deflate.flush()))
    parts.append(_chunk(b"IEND", b""))
    return b"".join(parts)


# --------------------------------------------------------------------------------- validation
def check_image(data, what: str, channels: Sequence[int] = (1, 2, 3, 4)) -> np.ndarray:
    """``data`` as an (H, W, C) numpy array with C in ``channels``, else a clear error."""
    arr = np.asarray(data)
    if arr.ndim != 3:
        raise ValueError(f"{what}: expected an (H, W, C) array, got shape {arr.shape}")
    if arr.shape[2] not in channels:
        raise ValueError(
            f"{what}: channel count {arr.shape[2]} (shape {arr.shape}) is not allowed; "
            f"allowed: {list(channels)}"
        )
    if arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{what}: image must be at least 1×1 pixels, got shape {arr.shape}")
    return arr


def unit_float_to_uint16(arr: np.ndarray, what: str) -> np.ndarray:
    """Floats in [0, 1] → ``floor(x * 65535)`` uint16 (upstream's truncation, computed in the
    input's own precision as upstream did); NaN or values outside [0, 1] raise."""
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: values must be finite, found NaN or inf")
    lo, hi = float(arr.min()), float(arr.max())
    if lo < 0.0 or hi > 1.0:
        raise ValueError(f"{what}: float values must lie in [0, 1], got range [{lo}, {hi}]")
    if arr.dtype.itemsize < 4:  # float16 cannot hold 65535 · x
        arr = arr.astype(np.float32)
    return (arr * UINT16_MAX).astype(np.uint16)  # astype truncates toward 0 (values are ≥ 0)


def to_png_samples(data, what: str) -> np.ndarray:
    """Validate/convert ``data`` to (H, W, C) uint8 or uint16 samples (see module docstring)."""
    arr = check_image(data, what)
    if arr.dtype in (np.uint8, np.uint16):
        return arr
    if arr.dtype.kind in "iu":
        lo, hi = int(arr.min()), int(arr.max())
        if lo < 0 or hi > UINT16_MAX:
            raise ValueError(
                f"{what}: integer values must lie in [0, 65535] for a 16-bit PNG, got range "
                f"[{lo}, {hi}] (dtype {arr.dtype}); values are never wrapped"
            )
        return arr.astype(np.uint16)
    if arr.dtype.kind == "f":
        return unit_float_to_uint16(arr, what)
    raise TypeError(
        f"{what}: dtype {arr.dtype} cannot be written as PNG (allowed: uint8, uint16, other "
        "integers in [0, 65535], floats in [0, 1])"
    )


def pad_to_png_channels(arr: np.ndarray) -> np.ndarray:
    """Pad 2-channel data with a zero third channel (stored as RGB); others unchanged."""
    if arr.shape[2] != 2:
        return arr
    return np.concatenate([arr, np.zeros_like(arr[:, :, :1])], axis=2)


# ------------------------------------------------------------------------------------ writers
def write_png(data: np.ndarray, filename: PathLike) -> None:
    """Write (H, W, C) data, C in 1..4, as an 8-bit (uint8) or 16-bit PNG, atomically."""
    samples = to_png_samples(data, f"write_png({str(filename)!r})")
    atomic_write_bytes(encode_png(pad_to_png_channels(samples)), filename)


def default_palette() -> np.ndarray:
    """The fixed 256-entry segmentation palette, (256, 3) uint8: label 0 (background) is black,
    labels 1..255 get well-separated hues (see :mod:`kubric.io.palette`, which contact sheets use
    too). Same for every frame and scene."""
    return label_palette(256)


def _check_palette(palette, max_label: int, what: str) -> np.ndarray:
    pal = np.asarray(palette)
    if pal.ndim != 2 or pal.shape[1] != 3 or not 1 <= pal.shape[0] <= 256:
        raise ValueError(f"{what}: palette must have shape (N, 3) with 1 ≤ N ≤ 256, got "
                         f"shape {pal.shape}")
    if pal.dtype.kind == "f":
        if not np.all(np.isfinite(pal)) or pal.min() < 0 or pal.max() > 1:
            raise ValueError(f"{what}: float palette values must lie in [0, 1]")
        pal = np.rint(pal * 255)
    elif pal.dtype.kind not in "iu" or pal.min() < 0 or pal.max() > 255:
        raise ValueError(f"{what}: palette must be integers in [0, 255] or floats in [0, 1], "
                         f"got dtype {pal.dtype}")
    if max_label >= pal.shape[0]:
        raise ValueError(f"{what}: label {max_label} has no palette entry (palette has "
                         f"{pal.shape[0]} colours)")
    return pal.astype(np.uint8)


def check_labels(data, what: str) -> tuple[np.ndarray, int]:
    """Validate an (H, W, 1) label image: non-negative integers ≤ 65535. Returns (array, max)."""
    arr = check_image(data, what, channels=(1,))
    if arr.dtype.kind not in "iub":
        raise TypeError(f"{what}: labels must have an integer dtype, got {arr.dtype}")
    lo, hi = int(arr.min()), int(arr.max())
    if lo < 0:
        raise ValueError(f"{what}: labels must be ≥ 0, got minimum {lo}")
    if hi > UINT16_MAX:
        raise ValueError(f"{what}: label {hi} exceeds 65535, the largest label a 16-bit PNG "
                         "can hold (labels are never wrapped)")
    return arr, hi


def encode_labels(arr: np.ndarray, max_label: int, palette=None, bitdepth: int | None = None,
                  what: str = "labels") -> bytes:
    """PNG bytes of validated labels: 8-bit palette PNG or 16-bit grey (``bitdepth`` None=auto)."""
    if bitdepth is None:
        bitdepth = 8 if max_label <= 255 else 16
    if bitdepth == 8:
        if max_label > 255:
            raise ValueError(f"{what}: label {max_label} does not fit an 8-bit palette PNG "
                             "(use bitdepth=16 or None)")
        pal = default_palette() if palette is None else _check_palette(palette, max_label, what)
        return encode_png(arr.astype(np.uint8, copy=False), palette=pal)
    if bitdepth != 16:
        raise ValueError(f"{what}: bitdepth must be None, 8 or 16, got {bitdepth!r}")
    if palette is not None:
        raise ValueError(f"{what}: a palette cannot be used for a 16-bit grey label PNG "
                         f"(largest label {max_label}); pass palette=None")
    return encode_png(arr.astype(np.uint16, copy=False))


def write_palette_png(data: np.ndarray, filename: PathLike, palette=None,
                      bitdepth: int | None = None) -> None:
    """Write (H, W, 1) integer labels as a palette PNG, or 16-bit grey above 255 labels.

    ``palette``: (N, 3) uint8 (or floats in [0, 1]) with N > the largest label; default
    :func:`default_palette`. ``bitdepth``: None chooses 8 (palette) when the largest label is
    ≤ 255, else 16 (grey); force 8 or 16 to keep one format across a scene's frames.
    """
    what = f"write_palette_png({str(filename)!r})"
    arr, max_label = check_labels(data, what)
    atomic_write_bytes(encode_labels(arr, max_label, palette, bitdepth, what), filename)


def scale_to_uint16(data: np.ndarray, min_value: float, max_value: float) -> np.ndarray:
    """``round((data - min) / (max - min) * 65535)`` as uint16; zeros when ``max == min``."""
    values = np.asarray(data, dtype=np.float64)
    span = float(max_value) - float(min_value)
    if span <= 0.0:
        return np.zeros(values.shape, dtype=np.uint16)
    scaled = np.rint((values - float(min_value)) * (UINT16_MAX / span))
    return np.clip(scaled, 0, UINT16_MAX).astype(np.uint16)


def unscale_from_uint16(q: np.ndarray, min_value: float, max_value: float) -> np.ndarray:
    """Inverse of :func:`scale_to_uint16`: ``q / 65535 * (max - min) + min`` as float32."""
    span = float(max_value) - float(min_value)
    values = np.asarray(q, dtype=np.float64) * (span / UINT16_MAX) + float(min_value)
    return values.astype(np.float32)


def float_range(data: np.ndarray, what: str) -> dict[str, float]:
    """``{"min", "max"}`` of finite float data; NaN/inf or a non-float dtype raise."""
    arr = np.asarray(data)
    if arr.dtype.kind != "f":
        raise TypeError(f"{what}: expected float data, got dtype {arr.dtype}")
    if arr.size == 0:
        raise ValueError(f"{what}: data is empty (shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: values must be finite to be scaled, found NaN or inf")
    return {"min": float(arr.min()), "max": float(arr.max())}


def write_scaled_png(data: np.ndarray, filename: PathLike) -> dict[str, float]:
    """Scale float (H, W, C) data, C in 1..4, to 16 bits over its own range and write it.

    Returns ``{"min": ..., "max": ...}`` (Python floats) needed by :func:`read_scaled_png`.
    """
    what = f"write_scaled_png({str(filename)!r})"
    arr = check_image(data, what)
    value_range = float_range(arr, what)
    q = scale_to_uint16(arr, value_range["min"], value_range["max"])
    atomic_write_bytes(encode_png(pad_to_png_channels(q)), filename)
    return value_range


# ------------------------------------------------------------------------------------ readers
def png_header(data: bytes, name: str = "data") -> dict:
    """Width, height, bitdepth and colour type from a PNG's IHDR chunk."""
    if len(data) < 33 or data[:8] != PNG_SIGNATURE or data[12:16] != b"IHDR":
        raise InputError(f"{name} is not a PNG file (bad signature or missing IHDR)")
    width, height, bitdepth, color_type = struct.unpack(">IIBB", data[16:26])
    return {"width": width, "height": height, "bitdepth": bitdepth, "color_type": color_type}


def png_samples_layout(data: bytes, name: str = "data") -> tuple[tuple[int, int, int], int, int]:
    """``((H, W, C), bitdepth, colour type)`` of PNG bytes this module reads, else a clear error."""
    header = png_header(data, name)
    bitdepth, color_type = header["bitdepth"], header["color_type"]
    if color_type not in CHANNELS_FOR_COLOR_TYPE:
        raise InputError(f"{name}: invalid PNG colour type {color_type}")
    if bitdepth not in (8, 16) and color_type != PALETTE_COLOR_TYPE:
        raise InputError(f"{name}: only 8- and 16-bit PNG samples are supported, got {bitdepth}")
    shape = (header["height"], header["width"], CHANNELS_FOR_COLOR_TYPE[color_type])
    return shape, bitdepth, color_type


def decode_png(data: bytes, name: str = "data") -> tuple[np.ndarray, np.ndarray | None]:
    """Decode PNG bytes to ((H, W, C) samples, palette or None).

    Samples are the stored values: uint8 for 8-bit, uint16 for 16-bit, palette indices (uint8)
    for palette PNGs (the palette is returned as (N, 3) uint8). Palette PNGs are read with Pillow,
    all others with libpng (``imagecodecs``; Pillow would truncate 16-bit colour to 8 bits).
    """
    shape, bitdepth, color_type = png_samples_layout(data, name)
    if color_type == PALETTE_COLOR_TYPE:
        return _decode_palette_png(data, shape, name)
    import imagecodecs

    try:
        arr = imagecodecs.png_decode(data)
    except Exception as err:  # PngError, or UnicodeDecodeError from libpng's message on garbage
        raise InputError(f"{name}: corrupt PNG data ({type(err).__name__}: {err})") from None
    if arr.dtype != (np.uint16 if bitdepth == 16 else np.uint8) or arr.size != np.prod(shape):
        raise InputError(f"{name}: decoded {arr.dtype} {arr.shape}, but the header says "
                         f"{bitdepth}-bit {shape}")
    return arr.reshape(shape), None


def _decode_palette_png(data: bytes, shape: tuple, name: str) -> tuple[np.ndarray, np.ndarray]:
    from PIL import Image

    try:
        with Image.open(io.BytesIO(data)) as img:
            img.load()
            palette = np.array(img.getpalette() or [], dtype=np.uint8).reshape(-1, 3)
            arr = np.asarray(img)
    except (OSError, SyntaxError) as err:  # Pillow raises SyntaxError for some broken chunks
        raise InputError(f"{name}: corrupt PNG data ({err})") from None
    return arr.astype(np.uint8, copy=False).reshape(shape), palette


def read_png(filename: PathLike, rescale_range=None) -> np.ndarray:
    """Read a PNG as (H, W, C) stored samples (uint8 / uint16; palette PNGs give indices).

    ``rescale_range=(min, max)`` instead returns float32 ``q / (2**bitdepth - 1) * (max - min) +
    min`` (upstream divided by ``2**bitdepth``, a small scale error fixed here).
    """
    path = as_path(filename)
    arr, _ = decode_png(read_bytes(path), repr(str(path)))
    if rescale_range is None:
        return arr
    lo, hi = range_pair(rescale_range, f"read_png({str(path)!r})")
    top = 255.0 if arr.dtype == np.uint8 else float(UINT16_MAX)
    return (arr.astype(np.float64) * ((hi - lo) / top) + lo).astype(np.float32)


def range_pair(value_range, what: str) -> tuple[float, float]:
    if isinstance(value_range, Mapping):
        if "min" not in value_range or "max" not in value_range:
            raise ValueError(f"{what}: range dict needs 'min' and 'max', got {value_range!r}")
        lo, hi = value_range["min"], value_range["max"]
    else:
        try:
            lo, hi = value_range
        except (TypeError, ValueError):
            raise ValueError(f"{what}: range must be {{'min', 'max'}} or (min, max), got "
                             f"{value_range!r}") from None
    lo, hi = float(lo), float(hi)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi < lo:
        raise ValueError(f"{what}: range must be finite with max ≥ min, got ({lo}, {hi})")
    return lo, hi


def read_scaled_png(filename: PathLike, value_range) -> np.ndarray:
    """Read a PNG written by :func:`write_scaled_png` back to float32 (H, W, C).

    ``value_range``: the dict that ``write_scaled_png`` returned (or a data_ranges.json entry),
    or a ``(min, max)`` pair. 2-channel data comes back with its zero padding channel (C = 3).
    """
    path = as_path(filename)
    lo, hi = range_pair(value_range, f"read_scaled_png({str(path)!r})")
    arr, _ = decode_png(read_bytes(path), repr(str(path)))
    if arr.dtype != np.uint16:
        raise InputError(f"read_scaled_png({str(path)!r}): expected a 16-bit PNG, got 8-bit")
    return unscale_from_uint16(arr, lo, hi)


def read_palette_png(filename: PathLike, return_palette: bool = False):
    """Read a label PNG (palette, 8-bit or 16-bit grey) as (H, W, 1) uint32 labels.

    With ``return_palette=True`` returns ``(labels, palette)``; palette is (N, 3) uint8, or None
    for a grey PNG.
    """
    path = as_path(filename)
    arr, palette = decode_png(read_bytes(path), repr(str(path)))
    if arr.shape[2] != 1:
        raise InputError(f"read_palette_png({str(path)!r}): a label PNG has 1 channel "
                         f"(palette or grey), this one has {arr.shape[2]}")
    labels = arr.astype(np.uint32)
    return (labels, palette) if return_palette else labels
