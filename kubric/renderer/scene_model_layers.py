"""Opt-in exact layers from the scene model, cast with Embree (the raycast backend's geometry), so
they are the same whichever backend renders RGB (the scene model is the one geometry both use).

* :func:`amodal_masks`: per instance and frame the full silhouette as if nothing occluded it:
  pixel (r, c) is in object k's mask iff the ray through its centre hits object k's posed mesh,
  the other objects ignored. Each object is cast alone, and only the rays inside the projection
  of its posed mesh's world box (a conservative bound for pinhole and orthographic cameras)
  are cast, so the cost grows with the objects' image area, not with their number × H × W.
* :func:`scene_flow`: per pixel the 3D displacement of the surface point seen at the pixel
  centre to the next / previous frame: the hit in its object's local frame, moved with the
  object's pose at frame t ± 1 (the keyframes the renderer and the flow layers use; held
  outside them). World frame: ``X(t ± 1) − X(t)``; camera frame: the point's position in the
  camera of frame t ± 1 minus its position in the camera of frame t (Blender camera axes), so
  projecting ``X_cam(t) + flow`` with frame t ± 1's intrinsics gives the optical flow's target.
  0 where nothing is hit. Static assets (the floor, the dome) move with their keyframes (none:
  0).

Skinned characters are not cast (the raycast backend has no skinning): a scene with one is
refused in one line.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core.characters import Character
from kubric.renderer.raycast import Raycast, _Geometry, _intersect, _PosedScene

#: the layers :func:`scene_flow` makes (world frame, then camera frame)
SCENE_FLOW_LAYERS = ("forward_scene_flow", "backward_scene_flow")
SCENE_FLOW_CAMERA_LAYERS = ("forward_scene_flow_camera", "backward_scene_flow_camera")


def _check(scene, who: str) -> None:
    if scene.camera is None:
        raise ValueError(f"{who}: the scene has no camera")
    people = [a.name for a in scene.assets if isinstance(a, Character)]
    if people:
        raise ValueError(f"{who}: skinned characters {people} are not supported (the raycast "
                         "geometry has no skinning); allowed: rigid objects (Cube, Sphere, "
                         "FileBasedObject, articulated links)")


def _frame_rays(camera, frame, w: int, h: int):
    """(origins, unit directions) (H·W, 3) of the pixel-centre rays of ``frame``."""
    return geo.pixel_rays(camera, geo.pixel_centres(h, w).reshape(-1, 2), frame=frame,
                          resolution=(w, h))


def _box_pixels(camera, triangles, frame, w: int, h: int) -> np.ndarray:
    """Flat indices of the pixels whose centres can see ``triangles`` (N, 3, 3) world: those in
    the bounding rectangle of the projected corners of their world box (every pixel when a
    corner is behind the camera)."""
    lo, hi = triangles.reshape(-1, 3).min(0), triangles.reshape(-1, 3).max(0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    in_front = _to_camera(camera, corners, frame)[:, 2] < 0
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


def amodal_masks(scene, assets: Sequence, frames: Sequence[int] | None = None) -> np.ndarray:
    """(T, N, H, W) bool: the amodal mask of each of ``assets`` (N) at each of ``frames``
    (default: the scene's frames); see module doc."""
    _check(scene, "amodal_masks")
    frames = list(scene.frames if frames is None else frames)
    camera, (w, h) = scene.camera, scene.resolution
    caster = Raycast(scene)
    geometries = [_Geometry([(k + 1, a, caster._mesh_of(a))]) for k, a in enumerate(assets)]
    out = np.zeros((len(frames), len(assets), h, w), bool)
    for t, frame in enumerate(frames):
        origins, dirs = _frame_rays(camera, frame, w, h)
        for k, geometry in enumerate(geometries):
            posed = _PosedScene(geometry, frame)
            if not len(posed.triangles):
                continue
            pixels = _box_pixels(camera, posed.triangles, frame, w, h)
            if len(pixels):
                hit = posed.first_hits(origins[pixels], dirs[pixels]) >= 0
                out[t, k].reshape(-1)[pixels[hit]] = True
    return out


def scene_flow(scene, frames: Sequence[int] | None = None, camera_frame: bool = True
               ) -> dict[str, np.ndarray]:
    """{layer: (T, H, W, 3) float32 metres} of :data:`SCENE_FLOW_LAYERS` (and, with
    ``camera_frame``, :data:`SCENE_FLOW_CAMERA_LAYERS`); see module doc."""
    _check(scene, "scene_flow")
    frames = list(scene.frames if frames is None else frames)
    camera, (w, h) = scene.camera, scene.resolution
    geometry = Raycast(scene).geometry()
    steps = {1: ("forward_scene_flow", "forward_scene_flow_camera"),
             -1: ("backward_scene_flow", "backward_scene_flow_camera")}
    names = SCENE_FLOW_LAYERS + (SCENE_FLOW_CAMERA_LAYERS if camera_frame else ())
    out = {name: np.zeros((len(frames), h * w, 3), np.float32) for name in names}
    for t, frame in enumerate(frames):
        origins, dirs = _frame_rays(camera, frame, w, h)
        posed = _PosedScene(geometry, frame)
        tri_id = posed.first_hits(origins, dirs)
        idx = np.flatnonzero(tri_id >= 0)
        tid = tri_id[idx]
        _, b1, b2 = _intersect(origins[idx], dirs[idx], posed.triangles[tid])
        owner = geometry.face_owner[tid]
        bary = np.stack([1 - b1 - b2, b1, b2], -1)
        local = np.einsum("nk,nkj->nj", bary, geometry.vertices[geometry.faces[tid]])
        here = geometry.to_world(local, owner, posed.poses)
        here_cam = _to_camera(camera, here, frame)
        for step, (world_name, cam_name) in steps.items():
            there = geometry.to_world(local, owner, geometry.poses(frame + step))
            out[world_name][t, idx] = there - here
            if camera_frame:
                out[cam_name][t, idx] = _to_camera(camera, there, frame + step) - here_cam
    return {name: value.reshape(len(frames), h, w, 3) for name, value in out.items()}


def _to_camera(camera, points, frame) -> np.ndarray:
    """World points (N, 3) → the camera frame of ``frame`` (Blender axes)."""
    m = geo.world_to_camera(camera, frame)
    return points @ m[:3, :3].T + m[:3, 3]
