"""Tracks and keypoints under a rolling shutter (:mod:`kubric.core.rolling_shutter`,
docs/conventions.md).

In frame f a track's pixel is where its surface point is seen at the time its own row is read:
the fixed point ``y = proj_y(P(t), t)`` with ``t = f + d · (y / H − 1/2)`` (the point on its
object and the camera both posed at ``t``), solved by
:func:`kubric.core.rolling_shutter.rolling_points`. The query's 3D point is unprojected at the
query row's time (:func:`kubric.annotations.tracks.compute_tracks`). A point on a rigid object
moves with the object's pose; one on a deforming surface (a skinned character or a simulated
Deformable) is its material point (triangle, barycentric) on the mesh deformed at ``t``; a
character's keypoint is its regressor on the mesh skinned at ``t`` (:func:`rolling_keypoints`).
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core.rolling_shutter import at_each_time, posed_points, rolling_points


def _camera_points(camera, world, times) -> np.ndarray:
    """(n, 3) world points (n, 3) in the camera frame of their own times (n,)."""
    def at(t, sel):
        m = geo.world_to_camera(camera, t)
        return world[sel] @ m[:3, :3].T + m[:3, 3]
    return at_each_time(times, at)


def rolling_positions(camera, frames, qassets, is_fg, points_object, resolution, anchors=None):
    """Per track and frame: (xy (N, T, 2), depth (N, T), camera-frame point (N, T, 3), world
    point (N, T, 3)) at each point's row time. ``points_object``: (N, 3) in the unscaled local
    frame of ``qassets[i]`` for foreground tracks (``is_fg``), world points for background ones;
    ``anchors``: {track index: (triangle, barycentric (3,))} of the tracks on deforming surfaces
    (:func:`kubric.annotations.character_tracks.follow_character`)."""
    anchors = anchors or {}
    n, num_frames = len(points_object), len(frames)
    deforming = np.array([i in anchors for i in range(n)], bool)
    tri = np.array([anchors[i][0] if i in anchors else 0 for i in range(n)], np.int64)
    bary = np.array([anchors[i][1] if i in anchors else np.zeros(3) for i in range(n)]
                    ).reshape(n, 3)
    keys = [(a.uid if fg else None) for a, fg in zip(qassets, is_fg, strict=True)]
    groups = list(dict.fromkeys(keys))
    group = np.array([groups.index(key) for key in keys], np.int64)
    first = [keys.index(key) for key in groups]
    assets = [qassets[i] if key is not None else None for key, i in zip(groups, first,
                                                                        strict=True)]

    def world_at(times, idx):
        out = np.empty((len(idx), 3))
        for g in np.unique(group[idx]):
            sel = np.flatnonzero(group[idx] == g)
            tracks = idx[sel]
            if deforming[first[g]]:
                out[sel] = at_each_time(times[sel], lambda t, s, a=assets[g], k=tracks:
                                        a.surface_points(tri[k[s]], bary[k[s]], t))
            else:
                out[sel] = posed_points(assets[g], points_object[tracks], times[sel])
        return out

    xy, dist = np.zeros((n, num_frames, 2)), np.zeros((n, num_frames))
    cam, world = np.zeros((n, num_frames, 3)), np.zeros((n, num_frames, 3))
    every = np.arange(n)
    for t, f in enumerate(frames):
        xy[:, t], dist[:, t], times = rolling_points(camera, world_at, n, f, resolution)
        world[:, t] = world_at(times, every)
        cam[:, t] = _camera_points(camera, world[:, t], times)
    return xy, dist, cam, world


def rolling_keypoints(camera, frames, character, pick, resolution):
    """Keypoints ``pick`` (indices into ``character.keypoint_names``) of ``character`` under the
    camera's rolling shutter: per frame, each keypoint where its regressor on the mesh skinned at
    its row's time projects with the camera at that time (the fixed point of the module doc).
    Returns (world (T, K, 3), xy (T, K, 2), depth (T, K), camera-frame (T, K, 3), time (T, K))."""
    pick = np.asarray(pick, np.int64)
    k = len(pick)

    def world_at(times, idx):
        return at_each_time(times, lambda t, s: character.keypoints(t)[pick[idx[s]]])

    shape = (len(frames), k)
    world, xy, cam = np.zeros(shape + (3,)), np.zeros(shape + (2,)), np.zeros(shape + (3,))
    dist, time = np.zeros(shape), np.zeros(shape)
    every = np.arange(k)
    for t, f in enumerate(frames):
        xy[t], dist[t], time[t] = rolling_points(camera, world_at, k, f, resolution)
        world[t] = world_at(time[t], every)
        cam[t] = _camera_points(camera, world[t], time[t])
    return world, xy, dist, cam, time
