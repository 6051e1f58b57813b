"""Rolling shutter in the raycast backend (no bpy): every row at its own read time
(:mod:`kubric.core.rolling_shutter`, docs/conventions.md).

Row r of frame f is cast with the camera and every object posed at
``t_r = f + d · ((r + 0.5) / H − 1/2)`` (``d``: the camera's ``rolling_shutter_duration``), so each
non-flow layer of row r is exactly the global-shutter layer of the scene posed at ``t_r`` (one
pose of the scene, one Embree scene and one row of rays per row).

Flow under a rolling shutter (``forward_flow`` / ``backward_flow``, (Δrow, Δcol) px): the surface
point seen through pixel centre (r, c) at ``t_r`` is followed on its object to frame f ± 1, where
its image position is the rolling-shutter fixed point (the point and the camera at the time of
the row it lands on, :func:`kubric.core.rolling_shutter.rolling_points`); flow = that
position − the pixel centre; 0 on background and where the point has no image position.
On a Deformable every row's mesh is the simulated mesh at ``t_r`` (linear between keyed frames),
on a skinned character the mesh skinned at ``t_r`` (``Character.deformed_vertices``: its bone
rotations nlerped, pose and root offset interpolated at ``t_r``), and the followed point is the
material point (triangle, barycentric) of that mesh.
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


def rolling_flow_ends(camera, geometry, hits, frame, resolution) -> np.ndarray:
    """(n, 2) rolling-shutter pixel positions (x, y) in ``frame`` of the surface points ``hits``
    = (local (n, 3) points in the unscaled local frames of objects owner (n,) (indices into
    ``geometry.entries``), their triangles tid (n,) and barycentrics bary (n, 3)): a rigid
    object's point moves with its pose, a deformable's is the material point on its mesh as
    simulated at each time."""
    local, owner, tid, bary = hits
    owner = np.asarray(owner)
    deforming = {k: (asset, start) for k, asset, start, _ in geometry.deforming}

    def world_at(times, idx):
        out = np.empty((len(idx), 3))
        for k in np.unique(owner[idx]):
            sel = np.flatnonzero(owner[idx] == k)
            pts = idx[sel]
            if k in deforming:
                asset, start = deforming[k]
                corners = geometry.faces[tid[pts]] - start
                out[sel] = rolling_shutter.at_each_time(
                    times[sel], lambda t, s, a=asset, c=corners, b=bary[pts]:
                    np.einsum("nk,nkj->nj", b[s], a.deformed_vertices(t)[c[s]]))
            else:
                out[sel] = rolling_shutter.posed_points(geometry.entries[k][1], local[pts],
                                                        times[sel])
        return out

    xy, _, _ = rolling_shutter.rolling_points(camera, world_at, len(owner), frame, resolution)
    return xy
