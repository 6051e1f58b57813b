"""Rolling shutter: the time at which each image row is read (docs/conventions.md). Pure numpy.

A camera's ``rolling_shutter_duration`` ``d`` (frames, ≥ 0; 0 = global shutter) is the readout
time from the image's top edge to its bottom edge: rows are read top to bottom and the row at
continuous pixel height ``y`` (pixel centres at ``r + 0.5``, image spans ``[0, H]``) is read at

    t(y) = frame + d · (y / H − 1/2)

so the middle of the image (``y = H/2``) is read at the frame time, the top edge at
``frame − d/2`` and the bottom edge at ``frame + d/2``; the centre of row r is read at
``frame + d · ((r + 0.5) / H − 1/2)`` (:func:`row_times`). Every exact layer of pixel (r, c) is the
global-shutter value with the scene (objects and camera) posed at its row's time.

A point's image position under the rolling shutter is the fixed point ``y = proj_y(P(t(y)), t(y))``
(the point P and the camera both at the time of the row the point lands on);
:func:`solve_rows` finds it from the frame time by one fixed-point step and then secant steps on
``proj_y(t(y)) − y``. With ``y`` clipped to the image a solution exists wherever the image
position is continuous in time; it is unique where ``d / H · |∂y/∂t|`` < 1 (∂y/∂t: the point's
vertical image speed, px/frame). It stops when ``|proj_y(t(y)) − y|`` < :data:`TOLERANCE_PX` for
every point and refuses in one line when :data:`MAX_ITERATIONS` steps do not get there. Points
above or below the image are read at the time of its nearest edge (``y`` clipped to
``[0, H]``); points without an image position (behind the camera, outside a lens's domain) keep
the frame time.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kubric.errors import InputError

#: convergence criterion of :func:`solve_rows`: every |proj_y(t(y)) − y| below this many pixels
#: (not smaller: the scene model stores poses in float32, so a point's image position is a step
#: function of time at the 1e-6 px scale)
TOLERANCE_PX = 1e-4
#: steps :func:`solve_rows` may take before refusing
MAX_ITERATIONS = 50


def duration_of(camera) -> float:
    """The camera's rolling-shutter readout duration in frames (0 for a global shutter)."""
    return float(getattr(camera, "rolling_shutter_duration", 0.0) or 0.0)


def row_offset(duration: float, y, height: int) -> np.ndarray:
    """Time offset (frames) from the frame time of the row at pixel height ``y`` (any shape)."""
    return float(duration) * (np.asarray(y, np.float64) / float(height) - 0.5)


def row_times(frame: float, duration: float, height: int) -> np.ndarray:
    """(H,) times at which the centres of rows 0 … H−1 of ``frame`` are read."""
    return float(frame) + row_offset(duration, np.arange(height) + 0.5, height)


def solve_rows(project_at: Callable, frame: float, duration: float, height: int,
               count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image positions of ``count`` points under the rolling shutter of ``frame``.

    ``project_at(times, idx)`` (idx: indices of points, times: (len(idx),) frames) returns those
    points' pixel positions (len(idx), 2) (x, y; NaN where they have none) and depths
    (len(idx),), each point and the camera posed at its own time. Returns (xy (count, 2),
    depth (count,), time (count,)) at the fixed point ``time = frame + row_offset(duration,
    clip(y, 0, H))`` (module doc: secant steps on ``proj_y(t(y)) − y``, only the points not yet
    converged are projected again; refuses in one line when they do not converge)."""
    frame = float(frame)
    every = np.arange(count)
    times = np.full(count, frame)
    xy, depth = project_at(times, every)
    if duration == 0.0 or count == 0:
        return xy, depth, times

    def time_of(y):
        rows = np.clip(y, 0.0, float(height))
        return np.where(np.isfinite(y), frame + row_offset(duration, rows, height), frame)

    # one fixed-point step: (y_prev, g_prev) = (frame-time y, its residual)
    y_prev = xy[:, 1].copy()
    times = time_of(y_prev)
    xy, depth = project_at(times, every)
    g_prev = xy[:, 1] - y_prev
    y = xy[:, 1].copy()
    active = every
    for _ in range(MAX_ITERATIONS):
        times[active] = time_of(y[active])
        xy[active], depth[active] = project_at(times[active], active)
        g = xy[active, 1] - y[active]
        going = np.abs(g) >= TOLERANCE_PX  # NaN (no image position) counts as done
        if not going.any():
            return xy, depth, times
        ya, yp, gp = y[active], y_prev[active], g_prev[active]
        slope = g - gp
        with np.errstate(divide="ignore", invalid="ignore"):
            secant = ya - g * (ya - yp) / slope
        step = np.where(np.isfinite(secant) & (np.abs(slope) > 1e-15), secant, ya + g)
        y_prev[active], g_prev[active] = ya, g
        y[active] = np.where(going, step, ya)
        active = active[going]
    worst = float(np.nanmax(np.abs(g)))
    raise InputError(f"rolling_shutter_duration={duration!r}: no row-time fixed point found in "
                     f"{MAX_ITERATIONS} steps (last |Δy| {worst:.3g} px): a point's image "
                     "position jumps or moves too fast vertically for this readout time "
                     "(unique where duration/H · |vertical px/frame| < 1); allowed: a shorter "
                     "duration")


def posed_points(asset, local: np.ndarray, times: np.ndarray) -> np.ndarray:
    """World positions (n, 3) of points ``local`` (n, 3) in ``asset``'s unscaled local frame,
    each with the asset's pose at its own time (n,); ``asset`` None: the points are world
    points that never move."""
    local = np.asarray(local, np.float64)
    if asset is None:
        return local.copy()
    out = np.empty_like(local)
    uniq, inverse = np.unique(np.asarray(times, np.float64), return_inverse=True)
    for k, t in enumerate(uniq):
        sel = inverse == k
        with asset.at_frame(float(t)):
            m = asset.matrix_world
            scale = np.asarray(asset.scale, np.float64)
        out[sel] = (local[sel] * scale) @ m[:3, :3].T + m[:3, 3]
    return out


def project_at_times(camera, world: np.ndarray, times: np.ndarray, resolution):
    """(xy (n, 2), depth (n,)) of world points (n, 3), each projected with the camera posed at
    its own time (n,) (:func:`kubric.core.camera_geometry.project_to_pixels`)."""
    from kubric.core import camera_geometry as geo
    world = np.asarray(world, np.float64)
    xy, depth = np.empty((len(world), 2)), np.empty(len(world))
    uniq, inverse = np.unique(np.asarray(times, np.float64), return_inverse=True)
    for k, t in enumerate(uniq):
        sel = inverse == k
        xy[sel], depth[sel] = geo.project_to_pixels(camera, world[sel], frame=float(t),
                                                    resolution=resolution)
    return xy, depth


def rolling_projection(camera, groups, frame: float, resolution):
    """Rolling-shutter image positions of points on moving assets in ``frame``.

    ``groups``: (asset or None, local points (n_k, 3)) pairs (see :func:`posed_points`).
    Returns (xy (n, 2), depth (n,), time (n,)) over the groups' points in order
    (:func:`rolling_points`)."""
    local = (np.concatenate([np.asarray(p, np.float64).reshape(-1, 3) for _, p in groups])
             if groups else np.zeros((0, 3)))
    group_of = np.repeat(np.arange(len(groups)), [len(p) for _, p in groups])

    def world_at(times, idx):
        world = np.empty((len(idx), 3))
        for k in np.unique(group_of[idx]):
            sel = group_of[idx] == k
            world[sel] = posed_points(groups[k][0], local[idx[sel]], times[sel])
        return world

    return rolling_points(camera, world_at, len(local), frame, resolution)


def rolling_points(camera, world_at: Callable, count: int, frame: float, resolution):
    """Rolling-shutter image positions of ``count`` moving points in ``frame``: ``world_at(times,
    idx)`` gives the world positions (len(idx), 3) of points ``idx`` at their own times
    (len(idx),) (any motion: rigid poses, skinned or simulated meshes, keypoint regressors).
    Returns (xy (count, 2), depth (count,), time (count,)) at the fixed point (:func:`solve_rows`
    with the camera's ``rolling_shutter_duration``)."""
    w, h = resolution

    def project_at(times, idx):
        return project_at_times(camera, world_at(times, idx), times, (w, h))

    return solve_rows(project_at, float(frame), duration_of(camera), h, int(count))


def at_each_time(times, points_at: Callable) -> np.ndarray:
    """(n, 3) ``points_at(t, sel)`` (the points ``sel`` (indices into ``times``) at time ``t``)
    gathered over the unique values of ``times`` (n,): one evaluation of a deforming model per
    distinct time."""
    times = np.asarray(times, np.float64)
    out = np.empty((len(times), 3))
    uniq, inverse = np.unique(times, return_inverse=True)
    for k, t in enumerate(uniq):
        sel = np.flatnonzero(inverse == k)
        out[sel] = points_at(float(t), sel)
    return out
