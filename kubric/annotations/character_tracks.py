"""Point tracks on deforming surfaces (characters). Pure numpy.

A query on a :class:`~kubric.core.characters.Character` is turned into a **material point** of its
mesh: the ray through the query's pixel position, from the camera at the query frame, is cast
against the character's mesh as skinned at that frame (:func:`kubric.annotations.surfaces.
ray_triangles`); the nearest hit gives ``(triangle, barycentric)``. The track is then that point
on every frame's skinned mesh (``Character.surface_points``): exact for the rendered surface,
because the renderer draws the same triangles between the same skinned vertices. A query ray that
misses the mesh (possible only for a query off a pixel centre at a silhouette, where the depth was
interpolated) snaps to the mesh vertex nearest the unprojected query point. ``points_object`` of a
character track is the rest-pose point in the model frame (the meaning of object coordinates on
characters, docs/characters.md).
"""

from __future__ import annotations

import numpy as np

from kubric.annotations.surfaces import ray_triangles
from kubric.core import camera_geometry as geo


def anchor_queries(character, camera, frame, pixels_xy, world_points, resolution):
    """(triangle (n,), barycentric (n, 3)) of the surface points seen at ``pixels_xy`` (x, y) at
    ``frame`` (module doc); ``world_points`` (n, 3) are the unprojected queries (for a miss)."""
    o, d = geo.pixel_rays(camera, pixels_xy, frame=frame, resolution=resolution)
    verts = character.deformed_vertices(frame)
    tri, bary = _cast(o, d, verts, character.faces, camera, frame, resolution, pixels_xy)
    miss = np.flatnonzero(tri < 0)
    if len(miss):
        used = character.rendered_vertices
        dist = np.linalg.norm(verts[used][None] - world_points[miss][:, None], axis=-1)
        nearest = used[np.argmin(dist, axis=1)]
        for i, v in zip(miss, nearest, strict=True):
            f = int(np.flatnonzero((character.faces == v).any(axis=1))[0])
            tri[i] = f
            bary[i] = (character.faces[f] == v).astype(np.float64)
    return tri, bary


def _cast(o, d, verts, faces, camera, frame, resolution, pixels_xy, chunk: int = 64):
    """:func:`ray_triangles` against only the triangles whose image-space box contains the
    query pixel (a triangle partly behind the camera is always a candidate): the same nearest
    hit, without testing every ray against every triangle."""
    xy, _ = geo.project_to_pixels(camera, verts, frame=frame, resolution=resolution)
    m = geo.world_to_camera(camera, frame)
    behind = (verts @ m[:3, :3].T + m[:3, 3])[:, 2] >= 0
    corners = xy[faces]                                              # (F, 3, 2)
    lo, hi = corners.min(axis=1) - 1e-3, corners.max(axis=1) + 1e-3
    always = behind[faces].any(axis=1) | ~np.isfinite(corners).all(axis=(1, 2))
    tris = verts[faces]
    n = len(o)
    tri = np.full(n, -1, np.int64)
    bary = np.zeros((n, 3))
    p = np.asarray(pixels_xy, np.float64)
    for a in range(0, n, chunk):
        pc = p[a:a + chunk]
        inside = ((pc[:, None, 0] >= lo[None, :, 0]) & (pc[:, None, 0] <= hi[None, :, 0])
                  & (pc[:, None, 1] >= lo[None, :, 1]) & (pc[:, None, 1] <= hi[None, :, 1]))
        inside |= always[None]
        for i, row in enumerate(inside):
            cand = np.flatnonzero(row)
            if not len(cand):
                continue
            f, b, _ = ray_triangles(o[a + i:a + i + 1], d[a + i:a + i + 1], tris[cand])
            if f[0] >= 0:
                tri[a + i], bary[a + i] = cand[f[0]], b[0]
    return tri, bary


def follow_character(character, camera, frames, query_times, pixels_xy, world_points,
                     resolution):
    """(points_object (n, 3) rest-pose model-frame points, points_world (n, T, 3), triangle (n,),
    barycentric (n, 3)) for queries on ``character`` (a Character or Deformable) anchored at
    ``query_times`` (n,): each query's frame, or under a rolling shutter the time its row is read
    (camera and mesh both at that time)."""
    query_times = np.asarray(query_times, np.float64)
    n = len(query_times)
    tri = np.zeros(n, np.int64)
    bary = np.zeros((n, 3))
    for t in np.unique(query_times):
        sel = query_times == t
        tri[sel], bary[sel] = anchor_queries(character, camera, float(t), pixels_xy[sel],
                                             world_points[sel], resolution)
    rest = character.surface_points(tri, bary, space="rest")
    world = np.stack([character.surface_points(tri, bary, f) for f in frames], axis=1)
    return rest, world, tri, bary
