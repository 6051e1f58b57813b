"""Scene flow from the exact layers and the scene model's poses. Pure numpy.

Per pixel, the 3D displacement (metres) of the surface point seen at the pixel centre to the next
(forward) and previous (backward) frame: the point ``X = camera centre + depth · ray`` of frame t
(:func:`kubric.core.camera_geometry.unproject_pixels`) belongs to the asset its renderer label
names; it is carried into that asset's unscaled local frame with the asset's pose at frame t and
back out with its pose at frame t ± 1 (position, quaternion, scale: the keyframes the renderer
and the optical flow use, held outside them), exactly as the flow layers move it.

* world frame: ``X(t ± 1) − X(t)``;
* camera frame: the point's position in the camera of frame t ± 1 minus its position in the
  camera of frame t (Blender camera axes): the motion the camera sees, so ``X_cam(t) + flow``
  projected with frame t ± 1's intrinsics is where the optical flow points.

0 where nothing is hit. Rigid assets (primitives, mesh files, the links of an articulated
object, each its own asset) move with their pose; on a skinned character the pixel's surface
point is the material point of the skinned mesh its ray hits (as the point tracks anchor it,
:mod:`kubric.annotations.character_tracks`), followed onto the mesh skinned at frame t ± 1.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kubric.annotations.character_tracks import anchor_queries
from kubric.annotations.segmentation import instance_labels
from kubric.core import camera_geometry as geo
from kubric.core.deformables import DEFORMING

#: the layers :func:`scene_flow` makes: world frame, then camera frame
WORLD_LAYERS = ("forward_scene_flow", "backward_scene_flow")
CAMERA_LAYERS = ("forward_scene_flow_camera", "backward_scene_flow_camera")


def _pose(asset, frame):
    """(rotation (3, 3), translation (3,), scale (3,)) of ``asset`` at ``frame``."""
    with asset.at_frame(frame):
        m = asset.matrix_world
        return m[:3, :3], m[:3, 3], np.broadcast_to(np.asarray(asset.scale, np.float64), (3,))


def to_camera(camera, points, frame) -> np.ndarray:
    """World points (..., 3) → the camera frame of ``frame`` (Blender axes)."""
    m = geo.world_to_camera(camera, frame)
    return points @ m[:3, :3].T + m[:3, 3]


def _rigid_moves(asset, camera, frame, pixels, points, resolution):
    """(step, direction index, the points at frame + step) of a rigid asset's surface points."""
    rot, trans, scale = _pose(asset, frame)
    local = (points - trans) @ rot / scale
    for step, k in ((1, 0), (-1, 1)):
        rot2, trans2, scale2 = _pose(asset, frame + step)
        yield step, k, (local * scale2) @ rot2.T + trans2


def _character_moves(character, camera, frame, pixels, points, resolution,
                     anchor=anchor_queries):
    """The same for a skinned character: each pixel's surface point is the material point
    (triangle, barycentric) its ray hits on the mesh skinned at ``frame`` (the anchor of the
    point tracks, :func:`kubric.annotations.character_tracks.anchor_queries`), followed onto the
    mesh skinned at frame ± 1 and moved by the difference of the two (so the step starts at the
    depth layer's point)."""
    tri, bary = anchor(character, camera, frame, pixels, points, resolution)
    here = character.surface_points(tri, bary, frame)
    for step, k in ((1, 0), (-1, 1)):
        yield step, k, points + character.surface_points(tri, bary, frame + step) - here


def scene_flow(scene, depth, segmentation, frames: Sequence[int] | None = None,
               camera_frame: bool = True, anchor=anchor_queries) -> dict[str, np.ndarray]:
    """{layer: (T, H, W, 3) float32 m} of :data:`WORLD_LAYERS` (and with ``camera_frame``
    :data:`CAMERA_LAYERS`) from (T, H, W[, 1]) depth and the renderer's labels for
    ``scene.assets`` (module doc). ``anchor``: how a character's pixels find their material
    points (``anchor_queries``' signature; the recipes pass Embree's,
    :func:`kubric.renderer.scene_model_layers.skinned_anchor`)."""
    d = np.asarray(depth, np.float64)
    lab = np.asarray(segmentation)
    d, lab = (a[..., 0] if a.ndim == 4 else a for a in (d, lab))
    frames = list(scene.frames if frames is None else frames)
    if d.shape != lab.shape or d.ndim != 3 or d.shape[0] != len(frames):
        raise ValueError(f"scene_flow: depth {d.shape} and segmentation {lab.shape} must be "
                         f"(T={len(frames)}, H, W[, 1])")
    camera = scene.camera
    t_, h, w = d.shape
    by_label = dict(zip(instance_labels(scene.assets).tolist(), scene.assets, strict=True))
    names = WORLD_LAYERS + (CAMERA_LAYERS if camera_frame else ())
    out = {name: np.zeros((t_, h, w, 3), np.float32) for name in names}
    centres = geo.pixel_centres(h, w)
    for t, frame in enumerate(frames):
        hit = d[t] < geo.BACKGROUND_DEPTH
        points = geo.unproject_pixels(camera, centres, np.where(hit, d[t], 0.0), frame)
        cam_here = to_camera(camera, points, frame) if camera_frame else None
        for label in np.unique(lab[t][hit]):
            asset = by_label.get(int(label))
            if asset is None:
                raise ValueError(f"scene_flow: label {int(label)} names no asset of the scene "
                                 f"(labels {sorted(by_label)})")
            sel = hit & (lab[t] == label)
            args = (asset, camera, frame, centres[sel], points[sel], (w, h))
            moves = _character_moves(*args, anchor=anchor) if isinstance(asset, DEFORMING) \
                else _rigid_moves(*args)
            for step, k, there in moves:
                out[WORLD_LAYERS[k]][t][sel] = there - points[sel]
                if camera_frame:
                    out[CAMERA_LAYERS[k]][t][sel] = to_camera(camera, there, frame + step) - \
                        cam_here[sel]
    return out
