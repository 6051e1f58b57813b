"""Tracks under a rolling shutter (:mod:`kubric.core.rolling_shutter`, docs/conventions.md).

In frame f a track's pixel is where its surface point is seen at the time its own row is read:
the fixed point ``y = proj_y(P(t), t)`` with ``t = f + d · (y / H − 1/2)`` (the point on its
object and the camera both posed at ``t``), solved by
:func:`kubric.core.rolling_shutter.rolling_projection`. The query's 3D point is unprojected at the
query row's time (:func:`kubric.annotations.tracks.compute_tracks`). Skinned characters are
refused in one line.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core.characters import Character
from kubric.core.rolling_shutter import duration_of, posed_points, rolling_projection
from kubric.errors import InputError


def rolling_positions(camera, frames, qassets, is_fg, points_object, resolution):
    """Per track and frame: (xy (N, T, 2), depth (N, T), camera-frame point (N, T, 3), world
    point (N, T, 3)) at each point's row time. ``points_object``: (N, 3) in the unscaled local
    frame of ``qassets[i]`` for foreground tracks (``is_fg``), world points for background ones."""
    for asset, fg in zip(qassets, is_fg, strict=True):
        if fg and isinstance(asset, Character):
            raise InputError(f"tracks on character {asset.name!r} under "
                             f"rolling_shutter_duration={duration_of(camera)!r}: not supported; "
                             "allowed: rigid objects and the background, or duration 0")
    n, num_frames = len(points_object), len(frames)
    keys = [(a.uid if fg else None) for a, fg in zip(qassets, is_fg, strict=True)]
    groups, members = [], []
    for key in dict.fromkeys(keys):
        sel = np.flatnonzero([k == key for k in keys])
        asset = None if key is None else qassets[int(sel[0])]
        groups.append((asset, points_object[sel]))
        members.append(sel)
    order = np.concatenate(members) if members else np.zeros(0, int)
    xy, dist = np.zeros((n, num_frames, 2)), np.zeros((n, num_frames))
    cam, world = np.zeros((n, num_frames, 3)), np.zeros((n, num_frames, 3))
    for t, f in enumerate(frames):
        g_xy, g_dist, g_time = rolling_projection(camera, groups, f, resolution)
        xy[order, t], dist[order, t] = g_xy, g_dist
        for (asset, points), sel, start in zip(groups, members, np.cumsum(
                [0] + [len(m) for m in members])[:-1], strict=True):
            times = g_time[start:start + len(sel)]
            world[sel, t] = posed_points(asset, points, times)
            for tt in np.unique(times):
                s = times == tt
                m = geo.world_to_camera(camera, float(tt))
                cam[sel[s], t] = world[sel[s], t] @ m[:3, :3].T + m[:3, 3]
    return xy, dist, cam, world
