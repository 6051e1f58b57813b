"""Rolling shutter in the raycast backend (no bpy): every row at its own read time
(:mod:`kubric.core.rolling_shutter`, docs/conventions.md).

Row r of frame f is cast with the camera and every object posed at
``t_r = f + d · ((r + 0.5) / H − 1/2)`` (``d``: the camera's ``rolling_shutter_duration``), so each
non-flow layer of row r is exactly the global-shutter layer of the scene posed at ``t_r`` (one
pose of the scene, one Embree scene and one row of rays per row).

Flow under a rolling shutter (``forward_flow`` / ``backward_flow``, (Δrow, Δcol) px): the surface
point seen through pixel centre (r, c) at ``t_r`` is followed on its object to frame f ± 1, where
its image position is the rolling-shutter fixed point (the point and the camera at the time of
the row it lands on, :func:`kubric.core.rolling_shutter.rolling_projection`); flow = that
position − the pixel centre; 0 on background and where the point has no image position.
"""

from __future__ import annotations

import numpy as np

from kubric.core import rolling_shutter


def rolling_frame(renderer, camera, geometry, frame, wanted) -> dict[str, np.ndarray]:
    """{layer: (H, W, C)} of frame ``frame`` under the camera's rolling shutter (module doc)."""
    w, h = renderer.scene.resolution
    times = rolling_shutter.row_times(frame, rolling_shutter.duration_of(camera), h)
    out: dict[str, np.ndarray] = {}
    for r, t in enumerate(times):
        got = renderer.render_frame(camera, geometry, float(t), wanted, rows=[r],
                                    rolling_from=frame)
        for name, value in got.items():
            if name not in out:
                out[name] = np.empty_like(value)
            out[name][r] = value[r]
    return out


def rolling_flow_ends(camera, geometry, local, owner, frame, resolution) -> np.ndarray:
    """(n, 2) rolling-shutter pixel positions (x, y) in ``frame`` of points ``local`` (n, 3) in
    the unscaled local frames of objects ``owner`` (n,) (indices into ``geometry.entries``)."""
    owner = np.asarray(owner)
    members = [np.flatnonzero(owner == k) for k in range(len(geometry.entries))]
    groups = [(entry[1], local[sel]) for entry, sel in zip(geometry.entries, members,
                                                           strict=True)]
    xy, _, _ = rolling_shutter.rolling_projection(camera, groups, frame, resolution)
    out = np.empty((len(owner), 2))
    out[np.concatenate(members + [np.zeros(0, np.int64)])] = xy
    return out
