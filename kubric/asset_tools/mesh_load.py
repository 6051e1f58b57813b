"""Loading helpers shared by the mesh converters: colour values and the triangle-mesh parts of a
loaded file."""

from __future__ import annotations

from kubric.core.imports import uninterrupted_import
from kubric.errors import InputError


def as_rgba(value, what: str) -> tuple[float, float, float, float]:
    """Validate a colour given as 3 or 4 numbers in [0, 1]; returns RGBA (alpha 1 if absent)."""
    import numpy as np

    try:
        vals = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        vals = np.zeros(0)
    if vals.size not in (3, 4) or not np.all(np.isfinite(vals)) or \
            np.any(vals < 0) or np.any(vals > 1):
        raise InputError(f"{what}: a colour must be 3 or 4 numbers in [0, 1], got {value!r}")
    return tuple(float(v) for v in (*vals, 1.0)[:4])


def split_parts(loaded) -> list:
    """The triangle meshes of a loaded file (scene transforms applied), one per material."""
    trimesh = uninterrupted_import("trimesh")

    if isinstance(loaded, trimesh.Scene):
        if not loaded.geometry:
            raise InputError("the file holds no geometry")
        parts = list(loaded.dump(concatenate=False))
    else:
        parts = [loaded]
    for part in parts:
        if not isinstance(part, trimesh.Trimesh):
            raise InputError(f"not a triangle mesh (got {type(part).__name__}, "
                             "e.g. a point cloud)")
    return parts
