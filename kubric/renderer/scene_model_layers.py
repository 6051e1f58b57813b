"""Opt-in exact layers from the scene model, cast with Embree (the raycast backend's geometry), so
they are the same whichever backend renders RGB (the scene model is the one geometry both use).

* :func:`amodal_masks`: per instance and frame the full silhouette as if nothing occluded it:
  pixel (r, c) is in object k's mask iff the ray through its centre hits object k's posed mesh,
  the other objects ignored. Each object is cast alone: its mesh is searchable in its own
  local frame (built once per scene, not per frame) and a frame's rays are moved into that
  frame; only the rays inside the projection of its posed box (a conservative bound for
  pinhole and orthographic cameras) are cast, so the cost grows with the objects' image area,
  not with their number × H × W.

A skinned character (:class:`kubric.core.characters.Character`) is cast as its mesh is skinned
at each frame (``Character.deformed_vertices``: the triangles the Blender backend renders).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import trimesh

from kubric.annotations.character_tracks import anchor_queries
from kubric.annotations.scene_flow import to_camera
from kubric.core import camera_geometry as geo
from kubric.core.deformables import DEFORMING
from kubric.renderer.raycast import Raycast, _Geometry, _intersect


def _check(scene, who: str) -> None:
    if scene.camera is None:
        raise ValueError(f"{who}: the scene has no camera")


def _frame_rays(camera, frame, w: int, h: int):
    """(origins, unit directions) (H·W, 3) of the pixel-centre rays of ``frame``."""
    return geo.pixel_rays(camera, geo.pixel_centres(h, w).reshape(-1, 2), frame=frame,
                          resolution=(w, h))


def _box_pixels(camera, corners, frame, w: int, h: int) -> np.ndarray:
    """Flat indices of the pixels whose centres can see inside the world box with ``corners``
    (8, 3): those in the bounding rectangle of the projected corners (every pixel when a corner
    is behind the camera)."""
    in_front = to_camera(camera, corners, frame)[:, 2] < 0
    xy, _ = geo.project_to_pixels(camera, corners, frame=frame, resolution=(w, h))
    if not (geo.is_orthographic(camera) or in_front.all()) or not np.isfinite(xy).all():
        return np.arange(w * h)
    c0, r0 = np.floor(xy.min(0) - 0.5).astype(int) - 1
    c1, r1 = np.ceil(xy.max(0) - 0.5).astype(int) + 1
    c0, r0, c1, r1 = max(c0, 0), max(r0, 0), min(c1, w - 1), min(r1, h - 1)
    if c0 > c1 or r0 > r1:
        return np.zeros(0, np.int64)
    rows, cols = np.meshgrid(np.arange(r0, r1 + 1), np.arange(c0, c1 + 1), indexing="ij")
    return (rows * w + cols).reshape(-1)


class _LocalCaster:
    """One rigid object's mesh searchable by Embree in its own unscaled local frame (built once):
    a frame's rays are moved into that frame instead of the mesh into the world."""

    def __init__(self, asset, mesh):
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        self.geometry = _Geometry([(1, asset, mesh)])
        self.faces = mesh.faces
        self.ray = RayMeshIntersector(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False))
        lo, hi = mesh.vertices.min(0), mesh.vertices.max(0)
        self.corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                 for z in (lo[2], hi[2])])

    def hits(self, camera, origins, dirs, frame, w: int, h: int) -> np.ndarray:
        """Flat indices of the pixels whose rays hit the object posed at ``frame``."""
        rot, trans, scale = (p[0] for p in self.geometry.poses(frame))
        if not np.all(scale != 0):
            return np.zeros(0, np.int64)
        corners = self.geometry.to_world(self.corners, np.zeros(8, int),
                                         tuple(p[None] for p in (rot, trans, scale)))
        pixels = _box_pixels(camera, corners, frame, w, h)
        if not len(pixels):
            return pixels
        local_o = (origins[pixels] - trans) @ rot / scale
        local_d = dirs[pixels] @ rot / scale
        return pixels[np.asarray(self.ray.intersects_first(local_o, local_d)) >= 0]


class _SkinnedCaster:
    """A skinned character: its mesh as skinned at each frame, searchable by Embree (built per
    frame: the surface deforms)."""

    def __init__(self, character):
        self.character = character
        self.faces = character.faces

    def hits(self, camera, origins, dirs, frame, w: int, h: int) -> np.ndarray:
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        verts = self.character.deformed_vertices(frame)
        used = verts[np.unique(self.faces)]
        lo, hi = used.min(0), used.max(0)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        pixels = _box_pixels(camera, corners, frame, w, h)
        if not len(pixels):
            return pixels
        ray = RayMeshIntersector(trimesh.Trimesh(verts, self.faces, process=False))
        return pixels[np.asarray(ray.intersects_first(origins[pixels], dirs[pixels])) >= 0]


def skinned_anchor(character, camera, frame, pixels_xy, world_points, resolution):
    """(triangle (n,), barycentric (n, 3)) of the surface points of ``character`` seen at
    ``pixels_xy`` (x, y) at ``frame``: :func:`kubric.annotations.character_tracks.anchor_queries`
    with Embree finding the triangles (one search structure per call, not a numpy loop per ray;
    the barycentric weights are recomputed in float64); rays that miss (a depth pixel at a
    silhouette the two renderers split differently) take ``anchor_queries``' own fallback."""
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    origins, dirs = geo.pixel_rays(camera, pixels_xy, frame=frame, resolution=resolution)
    verts = character.deformed_vertices(frame)
    ray = RayMeshIntersector(trimesh.Trimesh(verts, character.faces, process=False))
    tri = np.asarray(ray.intersects_first(origins, dirs), np.int64)
    bary = np.zeros((len(tri), 3))
    hit = np.flatnonzero(tri >= 0)
    _, b1, b2 = _intersect(origins[hit], dirs[hit], verts[character.faces[tri[hit]]])
    bary[hit] = np.stack([1 - b1 - b2, b1, b2], -1)
    miss = np.flatnonzero(tri < 0)
    if len(miss):
        tri[miss], bary[miss] = anchor_queries(character, camera, frame, pixels_xy[miss],
                                               world_points[miss], resolution)
    return tri, bary


def amodal_masks(scene, assets: Sequence, frames: Sequence[int] | None = None) -> np.ndarray:
    """(T, N, H, W) bool: the amodal mask of each of ``assets`` (N) at each of ``frames``
    (default: the scene's frames); see module doc."""
    _check(scene, "amodal_masks")
    frames = list(scene.frames if frames is None else frames)
    camera, (w, h) = scene.camera, scene.resolution
    meshes = Raycast(scene)
    casters = [_SkinnedCaster(a) if isinstance(a, DEFORMING) else
               _LocalCaster(a, meshes._mesh_of(a)) for a in assets]
    out = np.zeros((len(frames), len(assets), h * w), bool)
    for t, frame in enumerate(frames):
        origins, dirs = _frame_rays(camera, frame, w, h)
        for k, caster in enumerate(casters):
            if len(caster.faces):
                out[t, k, caster.hits(camera, origins, dirs, frame, w, h)] = True
    return out.reshape(len(frames), len(assets), h, w)
