"""Float TIFF files: our minimal baseline-TIFF encoder, libtiff (``imagecodecs``) for reading.

:func:`write_tiff` stores (H, W, C) float data, C in 1..4, as little-endian 32-bit IEEE floats
(SampleFormat 3), interleaved, one strip; uncompressed by default (what upstream Kubric's
``imageio`` writer produced) or Deflate-compressed with ``compress=True``. C = 1 is tagged
BlackIsZero, C = 3/4 RGB(A); C = 2 and C = 4 declare one unspecified extra sample. Pillow, libtiff,
tifffile and imageio read these files. Values are not changed beyond the cast to float32
(NaN and inf are kept). The encoder is ours because every library measured
(``benchmarks/bench_codecs.py``: tifffile, libtiff, Pillow, OpenCV) writes the same file slower.

:func:`read_tiff` reads the first image of any TIFF libtiff reads (strips or tiles, any byte
order, compression and predictor) and returns (H, W, C) in the stored dtype.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from kubric.errors import InputError
from kubric.io.paths import PathLike, as_path, atomic_write_bytes, read_bytes

# TIFF tag ids and field types used here.
T_WIDTH, T_HEIGHT, T_BITS, T_COMPRESSION, T_PHOTOMETRIC = 256, 257, 258, 259, 262
T_STRIP_OFFSETS, T_SAMPLES, T_ROWS_PER_STRIP, T_STRIP_COUNTS = 273, 277, 278, 279
T_PLANAR, T_EXTRA_SAMPLES, T_SAMPLE_FORMAT = 284, 338, 339
SHORT, LONG = 3, 4
TYPE_FORMATS = {3: "H", 4: "I"}
COMPRESSION_NONE, COMPRESSION_DEFLATE = 1, 8


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


def decode_tiff(data: bytes, name: str = "data") -> np.ndarray:
    """Decode the first image of TIFF bytes to (H, W, C) in its stored dtype (libtiff)."""
    import imagecodecs

    try:
        arr = imagecodecs.tiff_decode(data, index=0)
    except Exception as err:  # TiffError, or IndexError when the file holds no image
        raise InputError(f"{name} is not a TIFF file libtiff can read ({type(err).__name__}: "
                         f"{err})") from None
    return arr.reshape(arr.shape[0], arr.shape[1], -1)


def read_tiff(filename: PathLike) -> np.ndarray:
    """Read a TIFF as (H, W, C) in its stored dtype (float32 for files from :func:`write_tiff`)."""
    path = as_path(filename)
    return decode_tiff(read_bytes(path), repr(str(path)))
