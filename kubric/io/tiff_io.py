"""Float TIFF files: a minimal baseline-TIFF encoder and a strip reader.

:func:`write_tiff` stores (H, W, C) float data, C in 1..4, as little-endian 32-bit IEEE floats
(SampleFormat 3), interleaved, one strip; uncompressed by default (what upstream Kubric's
``imageio`` writer produced) or Deflate-compressed with ``compress=True``. C = 1 is tagged
BlackIsZero, C = 3/4 RGB(A); C = 2 and C = 4 declare one unspecified extra sample. Pillow, libtiff,
tifffile and imageio read these files. Values are not changed beyond the cast to float32
(NaN and inf are kept).

:func:`read_tiff` reads the first image of a TIFF with strips (not tiles), little- or
big-endian, uncompressed or Deflate (codes 8 and 32946), predictor 1 or 2 (horizontal differencing
of integers), chunky or planar layout, and returns (H, W, C) in the stored dtype.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from kubric.io.paths import PathLike, as_path, atomic_write_bytes, read_bytes

# TIFF tag ids and field types used here.
T_WIDTH, T_HEIGHT, T_BITS, T_COMPRESSION, T_PHOTOMETRIC = 256, 257, 258, 259, 262
T_STRIP_OFFSETS, T_SAMPLES, T_ROWS_PER_STRIP, T_STRIP_COUNTS = 273, 277, 278, 279
T_PLANAR, T_PREDICTOR, T_EXTRA_SAMPLES, T_SAMPLE_FORMAT = 284, 317, 338, 339
T_TILE_WIDTH = 322
SHORT, LONG = 3, 4
TYPE_FORMATS = {1: "B", 3: "H", 4: "I", 16: "Q"}  # BYTE, SHORT, LONG, LONG8 (BigTIFF)
COMPRESSION_NONE, COMPRESSION_DEFLATE, COMPRESSION_DEFLATE_OLD = 1, 8, 32946


def encode_tiff(data: np.ndarray, compress: bool = False, compress_level: int = 2) -> bytes:
    """Encode validated (H, W, C) float data, C in 1..4, as little-endian float32 TIFF bytes."""
    height, width, channels = data.shape
    pixels = np.ascontiguousarray(data, dtype="<f4").tobytes()
    if compress:
        pixels = zlib.compress(pixels, compress_level)
    entries = [
        (T_WIDTH, LONG, [width]),
        (T_HEIGHT, LONG, [height]),
        (T_BITS, SHORT, [32] * channels),
        (T_COMPRESSION, SHORT, [COMPRESSION_DEFLATE if compress else COMPRESSION_NONE]),
        (T_PHOTOMETRIC, SHORT, [2 if channels >= 3 else 1]),
        (T_STRIP_OFFSETS, LONG, [0]),  # patched below
        (T_SAMPLES, SHORT, [channels]),
        (T_ROWS_PER_STRIP, LONG, [height]),
        (T_STRIP_COUNTS, LONG, [len(pixels)]),
        (T_PLANAR, SHORT, [1]),
    ]
    if channels in (2, 4):
        entries.append((T_EXTRA_SAMPLES, SHORT, [0]))
    entries.append((T_SAMPLE_FORMAT, SHORT, [3] * channels))
    ifd_offset = 8
    ifd_size = 2 + 12 * len(entries) + 4
    extra = bytearray()  # values longer than 4 bytes, stored after the IFD
    extra_start = ifd_offset + ifd_size
    data_offset = extra_start + sum(
        2 * len(v) for _, t, v in entries if t == SHORT and len(v) > 2)
    data_offset += data_offset % 2  # word-align the image data
    ifd = bytearray(struct.pack("<H", len(entries)))
    for tag, ftype, values in entries:
        if tag == T_STRIP_OFFSETS:
            values = [data_offset]
        fmt = "<" + TYPE_FORMATS[ftype] * len(values)
        payload = struct.pack(fmt, *values)
        if len(payload) <= 4:
            ifd += struct.pack("<HHI", tag, ftype, len(values)) + payload.ljust(4, b"\0")
        else:
            ifd += struct.pack("<HHII", tag, ftype, len(values), extra_start + len(extra))
            extra += payload
    ifd += struct.pack("<I", 0)  # no next IFD
    header = b"II" + struct.pack("<HI", 42, ifd_offset)
    body = header + bytes(ifd) + bytes(extra)
    body += b"\0" * (data_offset - len(body))
    return body + pixels


def check_float_image(data, what: str) -> np.ndarray:
    """``data`` as (H, W, C) float, C in 1..4; other shapes/dtypes raise naming the value."""
    arr = np.asarray(data)
    if arr.ndim != 3 or arr.shape[2] not in (1, 2, 3, 4) or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{what}: expected an (H, W, C) array with C in 1..4, got shape "
                         f"{arr.shape}")
    if arr.dtype.kind != "f":
        raise TypeError(f"{what}: TIFF layers are float32; got dtype {arr.dtype} (allowed: "
                        "float16, float32, float64)")
    return arr


def write_tiff(data: np.ndarray, filename: PathLike, compress: bool = False) -> None:
    """Write float (H, W, C) data, C in 1..4, as a float32 TIFF, atomically."""
    arr = check_float_image(data, f"write_tiff({str(filename)!r})")
    atomic_write_bytes(encode_tiff(arr, compress=compress), filename)


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


def read_tiff(filename: PathLike) -> np.ndarray:
    """Read a TIFF as (H, W, C) in its stored dtype (float32 for files from :func:`write_tiff`)."""
    path = as_path(filename)
    return decode_tiff(read_bytes(path), repr(str(path)))
