"""Ground truth for what happens inside one exposure: depth of field and motion blur
(docs/conventions.md, "Time inside a frame").

**Defocus** (:func:`defocus`): the diameter, in pixels, of the circle of confusion of the surface
seen through each pixel centre, for the perspective camera's thin lens as Cycles renders it —
aperture diameter ``A = f / N`` (focal length f, f-number N ``aperture_fstop``), focal plane at
``z = s`` (``focus_distance``, metres along the view axis), field of view fixed by f::

    c_px = (f / N) · |1/z − 1/s| · (f / sensor_width) · W

with f / N in metres, z the surface's distance **along the view axis** (the ``z`` layer, not
``depth``, which is the distance to the camera centre) and W the image width in pixels. Cycles
samples a point L on the aperture disk (radius A / 2) and aims it at the pinhole ray's point on
the plane z = s; a surface point at z then lands L·(1/s − 1/z) away (in tangent units) from its
pinhole projection, so its blur disk has the diameter above. (The textbook sensor-side
``A·f·|z − s| / (z·(s − f))`` differs by the factor s / (s − f) because it moves the sensor
back to focus; Cycles keeps the field of view.) Background pixels (z = 10000 m) get the
diameter of a point at that distance.

**Exposure coverage** (:func:`coverage_archive`, :func:`coverage_fractions`): for a shutter of
length ``s`` frames centred on each frame time (Cycles' ``motion_blur_position = 'CENTER'``), K
sub-frame times ``f + s·((k + ½)/K − ½)``, k = 0 … K−1 (the midpoints of K equal parts of the
open shutter); the fraction of the exposure at which pixel (r, c) shows instance i is the number
of those times at which its pixel-centre ray first hits i, divided by K. Stored sparsely in
``coverage.npz``: one entry per (frame, pixel, label) with a count > 0.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.errors import InputError

#: the scene file of the exposure coverage
COVERAGE_FILE = "coverage.npz"
COVERAGE_VERSION = 1
#: (key, dtype, shape, unit, doc) of every array of ``coverage.npz`` (one row per entry P)
COVERAGE_FIELDS = (
    ("frame", "uint16", ("P",), "", "frame index (0-based, into the rendered frames)"),
    ("y", "uint16", ("P",), "px", "pixel row"),
    ("x", "uint16", ("P",), "px", "pixel column"),
    ("label", "uint16", ("P",), "", "0 = background, k = instances[k − 1]"),
    ("count", "uint16", ("P",), "", "sub-frame times (of num_samples) at which the pixel-centre "
     "ray hits the label; fraction of the exposure = count / num_samples"),
)


def defocus(camera, z) -> np.ndarray:
    """Circle-of-confusion diameter in pixels (module doc) of z-depths ``z`` (..., H, W[, 1]),
    metres along the view axis, for the perspective ``camera``'s lens (``focal_length``,
    ``sensor_width``, ``aperture_fstop``, ``focus_distance``) at its scene's resolution.
    Returns float32 of ``z``'s shape."""
    if geo.is_orthographic(camera) or not hasattr(camera, "aperture_fstop"):
        raise ValueError(f"defocus: {camera.uid} is not a perspective camera (a thin lens needs "
                         "focal_length, aperture_fstop and focus_distance)")
    s = float(camera.focus_distance)
    if s <= 0:
        raise ValueError(f"defocus: {camera.uid} focus_distance={s} must be > 0 m")
    z = np.asarray(z, np.float64)
    if np.any(~np.isfinite(z)) or np.any(z <= 0):
        raise ValueError("defocus: z must be finite and > 0 m (background = "
                         f"{geo.BACKGROUND_DEPTH} m), got min {np.nanmin(z)}")
    width, _ = geo.image_size(camera)
    f_mm = float(camera.focal_length)
    aperture_m = f_mm * 1e-3 / float(camera.aperture_fstop)
    focal_px = f_mm / float(camera.sensor_width) * width
    return (aperture_m * np.abs(1.0 / z - 1.0 / s) * focal_px).astype(np.float32)


def shutter_offsets(shutter: float, samples: int) -> np.ndarray:
    """(K,) sub-frame offsets (frames, relative to the frame time) of ``samples`` = K ≥ 1
    midpoints of a shutter of length ``shutter`` ≥ 0 frames centred on the frame."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 1:
        raise ValueError(f"coverage samples must be an integer ≥ 1, got {samples!r}")
    if not np.isfinite(shutter) or shutter < 0:
        raise ValueError(f"shutter length must be ≥ 0 frames, got {shutter!r}")
    return float(shutter) * ((np.arange(samples) + 0.5) / samples - 0.5)


def coverage_archive(labels, shutter: float) -> dict[str, np.ndarray]:
    """``coverage.npz`` arrays from sub-frame labels (T, K, H, W) (instance labels as written:
    0 = background, k = instances[k − 1]) rendered at :func:`shutter_offsets` (shutter, K)."""
    labels = np.asarray(labels)
    if labels.ndim != 4 or labels.dtype.kind not in "ui" or 0 in labels.shape:
        raise ValueError(f"coverage: expected integer labels (T, K, H, W), got {labels.dtype} "
                         f"{labels.shape}")
    t, k, h, w = labels.shape
    if max(t, h, w, k, int(labels.max()) + 1) > np.iinfo(np.uint16).max:
        raise ValueError(f"coverage: (T, K, H, W) {labels.shape} or labels up to "
                         f"{labels.max()} do not fit uint16")
    top = int(labels.max()) + 1
    pixel = np.arange(t * h * w, dtype=np.int64).reshape(t, 1, h, w)
    keys, counts = np.unique((pixel * top + labels).ravel(), return_counts=True)
    pix, label = np.divmod(keys, top)
    frame, rest = np.divmod(pix, h * w)
    y, x = np.divmod(rest, w)
    return {"format_version": np.int32(COVERAGE_VERSION), "num_samples": np.int32(k),
            "shutter": np.float32(shutter), "offsets": shutter_offsets(shutter, k),
            "frame": frame.astype(np.uint16), "y": y.astype(np.uint16),
            "x": x.astype(np.uint16), "label": label.astype(np.uint16),
            "count": counts.astype(np.uint16)}


def coverage_fractions(archive, label: int, shape) -> np.ndarray:
    """(T, H, W) float32 fraction of the exposure at which each pixel shows ``label`` (0 =
    background), from a ``coverage.npz`` archive (a mapping of its arrays) of frames (T, H, W)
    ``shape``."""
    try:
        k = int(archive["num_samples"])
        rows = [np.asarray(archive[key]) for key in ("frame", "y", "x", "label", "count")]
    except KeyError as err:
        raise InputError(f"coverage archive lacks {err}; has {sorted(archive)}") from None
    frame, y, x, lab, count = rows
    out = np.zeros(tuple(int(v) for v in shape), np.float32)
    sel = lab == label
    out[frame[sel], y[sel], x[sel]] = count[sel] / k
    return out
