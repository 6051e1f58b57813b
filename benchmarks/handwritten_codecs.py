"""The PNG / TIFF codec code ``kubric/io`` had before ``bench_codecs.py`` measured it against
maintained libraries: the baseline its ratios are taken against.

The PNG encoder is still the package's (``kubric.io.png_io.encode_png``, now with a per-bit-depth
zlib strategy); :func:`encode_png` here is it at the old fixed settings ("up" rows, zlib level 2,
zlib's default strategy), byte for byte what it wrote before. The readers were replaced by
libpng / libtiff through ``imagecodecs`` and live on only here: numpy unfiltering of one-filter
16-bit PNGs with pypng for anything else, Pillow for 8-bit and grey, and a strip-TIFF parser.
"""

from __future__ import annotations

import io
import struct
import zlib

import numpy as np

from kubric.io import png_io
from kubric.io.png_io import png_samples_layout

# TIFF tag ids and field types the reader needs.
T_WIDTH, T_HEIGHT, T_BITS, T_COMPRESSION = 256, 257, 258, 259
T_STRIP_OFFSETS, T_SAMPLES, T_STRIP_COUNTS = 273, 277, 279
T_PLANAR, T_PREDICTOR, T_SAMPLE_FORMAT, T_TILE_WIDTH = 284, 317, 339, 322
TYPE_FORMATS = {1: "B", 3: "H", 4: "I", 16: "Q"}
COMPRESSION_NONE, COMPRESSION_DEFLATE, COMPRESSION_DEFLATE_OLD = 1, 8, 32946


def encode_png(pixels: np.ndarray, palette: np.ndarray | None = None) -> bytes:
    """The package's encoder at its old fixed settings (zlib's default strategy everywhere)."""
    return png_io.encode_png(pixels, palette=palette, strategy="default")


def _decode_png_numpy(data: bytes, shape: tuple, name: str) -> np.ndarray | None:
    """Fast numpy decode of a non-interlaced 16-bit PNG whose rows all use one of the filters
    none / sub / up (what :func:`encode_png` writes); None for any other file (pypng reads it)."""
    if data[28] != 0:  # interlaced
        return None
    height, width, channels = shape
    idat, pos = [], 8
    while pos + 8 <= len(data):
        (length,) = struct.unpack(">I", data[pos:pos + 4])
        tag = data[pos + 4:pos + 8]
        if tag == b"IDAT":
            idat.append(data[pos + 8:pos + 8 + length])
        elif tag == b"IEND":
            break
        pos += 12 + length
    try:
        raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8)
    except zlib.error as err:
        raise ValueError(f"{name}: corrupt PNG image data ({err})") from None
    bpp, row_bytes = 2 * channels, 2 * channels * width
    if raw.size < height * (row_bytes + 1):
        raise ValueError(f"{name}: PNG image data is truncated")
    rows = raw[:height * (row_bytes + 1)].reshape(height, row_bytes + 1)
    types, body = rows[:, 0], rows[:, 1:]
    if np.all(types == 0):
        out = body
    elif np.all(types == 2):
        out = np.cumsum(body, axis=0, dtype=np.uint8)
    elif np.all(types == 1):
        out = np.cumsum(body.reshape(height, width, bpp), axis=1, dtype=np.uint8)
    else:
        return None
    return np.ascontiguousarray(out).view(">u2").reshape(shape).astype(np.uint16)


def decode_png(data: bytes, name: str = "data") -> tuple[np.ndarray, np.ndarray | None]:
    """Decode PNG bytes to ((H, W, C) samples, palette or None).

    Samples are the stored values: uint8 for 8-bit, uint16 for 16-bit, palette indices (uint8)
    for palette PNGs (the palette is returned as (N, 3) uint8).
    """
    shape, bitdepth, _ = png_samples_layout(data, name)
    if bitdepth == 16 and shape[2] > 1:  # Pillow would drop the low byte
        fast = _decode_png_numpy(data, shape, name)
        if fast is not None:
            return fast, None
        import png

        _, _, pixels, _ = png.Reader(bytes=data).read_flat()
        return np.asarray(pixels, dtype=np.uint16).reshape(shape), None
    from PIL import Image

    with Image.open(io.BytesIO(data)) as img:
        img.load()
        palette = None
        if img.mode == "P":
            pal = img.getpalette() or []
            palette = np.array(pal, dtype=np.uint8).reshape(-1, 3)
        arr = np.asarray(img)
    arr = arr.astype(np.uint16 if bitdepth == 16 else np.uint8, copy=False)
    return arr.reshape(shape), palette


def _read_ifd(data: bytes, name: str) -> tuple[str, dict[int, list[int]]]:
    if data[:4] == b"II*\0":
        endian = "<"
    elif data[:4] == b"MM\0*":
        endian = ">"
    else:
        raise ValueError(f"{name} is not a classic TIFF file (bad header {data[:4]!r})")
    (offset,) = struct.unpack(endian + "I", data[4:8])
    (count,) = struct.unpack(endian + "H", data[offset:offset + 2])
    tags: dict[int, list[int]] = {}
    for i in range(count):
        pos = offset + 2 + 12 * i
        tag, ftype, n = struct.unpack(endian + "HHI", data[pos:pos + 8])
        if ftype not in TYPE_FORMATS:
            continue  # a tag type this reader does not need (ASCII, RATIONAL, ...)
        fmt = endian + TYPE_FORMATS[ftype] * n
        size = struct.calcsize(fmt)
        if size <= 4:
            raw = data[pos + 8:pos + 8 + size]
        else:
            (where,) = struct.unpack(endian + "I", data[pos + 8:pos + 12])
            raw = data[where:where + size]
        tags[tag] = list(struct.unpack(fmt, raw))
    return endian, tags


def decode_tiff(data: bytes, name: str = "data") -> np.ndarray:
    """Decode the first image of TIFF bytes to (H, W, C) in its stored dtype."""
    endian, tags = _read_ifd(data, name)
    if T_TILE_WIDTH in tags:
        raise ValueError(f"{name}: tiled TIFF is not supported (only strips)")
    width, height = tags[T_WIDTH][0], tags[T_HEIGHT][0]
    channels = tags.get(T_SAMPLES, [1])[0]
    bits = tags.get(T_BITS, [1])
    fmt = tags.get(T_SAMPLE_FORMAT, [1])[0]
    if len(set(bits)) != 1 or len(set(tags.get(T_SAMPLE_FORMAT, [1]))) != 1:
        raise ValueError(f"{name}: mixed sample sizes/formats {bits} are not supported")
    kind = {1: "u", 2: "i", 3: "f"}.get(fmt)
    if kind is None or bits[0] % 8 or (kind == "f" and bits[0] not in (16, 32, 64)):
        raise ValueError(f"{name}: unsupported samples ({bits[0]} bits, SampleFormat {fmt})")
    dtype = np.dtype(f"{endian}{kind}{bits[0] // 8}")
    compression = tags.get(T_COMPRESSION, [1])[0]
    if compression not in (COMPRESSION_NONE, COMPRESSION_DEFLATE, COMPRESSION_DEFLATE_OLD):
        raise ValueError(f"{name}: TIFF compression {compression} is not supported (allowed: 1 "
                         "none, 8 / 32946 Deflate)")
    strips = []
    for off, n in zip(tags[T_STRIP_OFFSETS], tags[T_STRIP_COUNTS], strict=True):
        chunk = data[off:off + n]
        strips.append(chunk if compression == COMPRESSION_NONE else zlib.decompress(chunk))
    planar = tags.get(T_PLANAR, [1])[0]
    shape = (channels, height, width) if planar == 2 else (height, width, channels)
    buf = b"".join(strips)
    expected = int(np.prod(shape)) * dtype.itemsize
    if len(buf) < expected:
        raise ValueError(f"{name}: image data is truncated ({len(buf)} of {expected} bytes)")
    arr = np.frombuffer(buf[:expected], dtype=dtype).reshape(shape)
    if planar == 2:
        arr = arr.transpose(1, 2, 0)
    predictor = tags.get(T_PREDICTOR, [1])[0]
    if predictor == 2 and kind in "ui":
        arr = np.cumsum(arr, axis=1, dtype=arr.dtype)
    elif predictor != 1:
        raise ValueError(f"{name}: TIFF predictor {predictor} is not supported")
    return np.ascontiguousarray(arr.astype(dtype.newbyteorder("="), copy=False))
