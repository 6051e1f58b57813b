"""PFM (Portable Float Map): the float image format of the LASR / VCN flow files.

Layout (as the Middlebury / SceneFlow readers that LASR uses expect): a text header of three
lines, ``PF`` (3 channels) or ``Pf`` (1 channel), ``"<width> <height>"``, and a scale whose sign
gives the byte order (negative = little-endian), then float32 samples row by row from the
**bottom** row of the image to the top one. :func:`write_pfm` writes little-endian with scale −1;
:func:`read_pfm` reads either byte order and returns rows top to bottom.
"""

from __future__ import annotations

import numpy as np

from kubric.errors import InputError
from kubric.io.paths import PathLike, as_path, atomic_write_bytes


def encode_pfm(image: np.ndarray) -> bytes:
    """The bytes of a PFM file holding ``image``: (H, W) or (H, W, 1) → ``Pf``, (H, W, 3) →
    ``PF``; every value must be finite."""
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[..., 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) or 0 in arr.shape[:2]:
        raise ValueError(f"a PFM image is (H, W), (H, W, 1) or (H, W, 3) with H, W ≥ 1; got "
                         f"shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number) or not np.all(np.isfinite(arr)):
        raise ValueError("a PFM image must hold finite numbers")
    header = b"PF\n" if arr.ndim == 3 else b"Pf\n"
    header += f"{arr.shape[1]} {arr.shape[0]}\n-1.0\n".encode("ascii")
    return header + np.ascontiguousarray(arr[::-1], dtype="<f4").tobytes()


def write_pfm(image: np.ndarray, path: PathLike) -> None:
    """Write ``image`` (see :func:`encode_pfm`) to ``path`` atomically."""
    atomic_write_bytes(encode_pfm(image), as_path(path))


def decode_pfm(data: bytes) -> np.ndarray:
    """(H, W) or (H, W, 3) float32 array (rows top to bottom) from PFM bytes."""
    lines, pos = [], 0
    while len(lines) < 3:  # three header lines (a comment line starting with # is skipped)
        end = data.find(b"\n", pos)
        if end < 0:
            raise InputError("not a PFM file: truncated header")
        line = data[pos:end].strip()
        pos = end + 1
        if not line.startswith(b"#"):
            lines.append(line)
    kind, dims, scale = lines
    if kind not in (b"PF", b"Pf"):
        raise InputError(f"not a PFM file: header {kind[:10]!r} (expected PF or Pf)")
    try:
        width, height = (int(v) for v in dims.split())
        scale_value = float(scale)
    except ValueError:
        raise InputError(f"not a PFM file: bad size {dims[:30]!r} or scale {scale[:30]!r}") \
            from None
    channels = 3 if kind == b"PF" else 1
    count = width * height * channels
    body = data[pos:pos + 4 * count]
    if width < 1 or height < 1 or len(body) != 4 * count:
        raise InputError(f"PFM file: {width}×{height}×{channels} samples expected, "
                         f"{len(data) - pos} bytes of data found")
    arr = np.frombuffer(body, dtype="<f4" if scale_value < 0 else ">f4")
    shape = (height, width, 3) if channels == 3 else (height, width)
    return arr.reshape(shape)[::-1].astype(np.float32)


def read_pfm(path: PathLike) -> np.ndarray:
    """Read a PFM file (see :func:`decode_pfm`)."""
    return decode_pfm(as_path(path).read_bytes())
