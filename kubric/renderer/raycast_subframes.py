"""Exact layers at sub-frame times with the raycast backend (no bpy): what an exposure sees
between two frames (:mod:`kubric.annotations.exposure`, docs/conventions.md).

The scene model interpolates every keyframed property at fractional frames (linear vectors,
slerped quaternions; :mod:`kubric.core.assets`), so a ray cast at frame ``f + δ`` sees the
objects and the camera where they are at that instant. The raycast backend's ``render`` takes
whole frames only; this module casts the same pixel-centre rays at any finite time.
"""

from __future__ import annotations

import numpy as np

from kubric.annotations.exposure import shutter_offsets
from kubric.core import camera_geometry as geo
from kubric.renderer.raycast import Raycast


def subframe_layers(scene, frames, offsets, layers=("segmentation",)) -> dict[str, np.ndarray]:
    """{layer: (T, K, H, W, C)} of the exact ``layers`` at times ``frames[i] + offsets[k]``
    (frames, fractional allowed), each one pixel-centre ray cast per pixel as the raycast
    backend renders a frame (segmentation: the renderer's labels, before any relabelling)."""
    renderer = Raycast(scene)
    camera = scene.camera
    if camera is None:
        raise ValueError("subframe_layers: the scene has no camera")
    frames = [float(f) for f in frames]
    offsets = np.asarray(offsets, np.float64).reshape(-1)
    if not frames or not offsets.size or not np.all(np.isfinite(offsets)):
        raise ValueError(f"subframe_layers: need frames and finite offsets, got {frames!r}, "
                         f"{offsets.tolist()!r}")
    geometry = renderer.geometry()
    out: dict[str, np.ndarray] = {}
    for i, frame in enumerate(frames):
        for k, offset in enumerate(offsets):
            got = renderer.render_frame(camera, geometry, frame + float(offset), tuple(layers))
            for name, value in got.items():
                if name not in out:
                    out[name] = np.empty((len(frames), len(offsets)) + value.shape, value.dtype)
                out[name][i, k] = value
    return out


def shutter_segmentation(scene, frames, shutter: float, samples: int) -> np.ndarray:
    """(T, K, H, W) uint32 raw segmentation labels at the K = ``samples`` sub-frame times of a
    shutter of ``shutter`` frames centred on each of ``frames``
    (:func:`~kubric.annotations.exposure.shutter_offsets`)."""
    seg = subframe_layers(scene, frames, shutter_offsets(shutter, samples), ("segmentation",))
    return seg["segmentation"][..., 0]


def exposure_flow(scene, frames, shutter: float) -> np.ndarray:
    """(T, H, W, 2) float32 flow over the exposure, (Δrow, Δcol) in pixels: where the surface
    point seen through each pixel centre at frame f (the shutter's centre) is projected when the
    shutter closes (f + s/2) minus where it is when it opens (f − s/2), each with that instant's
    object pose and camera; 0 on background (as the flow layers)."""
    renderer = Raycast(scene)
    camera = scene.camera
    if camera is None:
        raise ValueError("exposure_flow: the scene has no camera")
    geometry = renderer.geometry()
    if geometry.deforming:
        raise ValueError(f"exposure_flow: deformables ({geometry.deforming[0][1].uid}) have no "
                         "sub-frame motion; allowed: rigid objects")
    if len(set(geometry.labels.tolist())) != len(geometry.labels):
        raise ValueError("exposure_flow: objects share a segmentation_id; every object needs "
                         "its own label")
    lut = np.full(int(geometry.labels.max(initial=0)) + 1, -1)
    lut[geometry.labels] = np.arange(len(geometry.labels))
    w, h = scene.resolution
    centres = geo.pixel_centres(h, w).reshape(-1, 2)
    out = np.zeros((len(frames), h * w, 2), np.float32)
    half = float(shutter) / 2.0
    for i, frame in enumerate(frames):
        got = renderer.render_frame(camera, geometry, frame, ("depth", "segmentation"))
        labels = got["segmentation"].reshape(-1)
        hit = np.flatnonzero(labels)
        owner = lut[labels[hit]]
        origins, dirs = geo.pixel_rays(camera, centres[hit], frame=frame, resolution=(w, h))
        world = origins + dirs * got["depth"].reshape(-1)[hit, None].astype(np.float64)
        rot, trans, scale = geometry.poses(frame)
        local = np.einsum("nji,nj->ni", rot[owner], world - trans[owner]) / scale[owner]
        ends = []
        for t in (frame - half, frame + half):
            moved = geometry.to_world(local, owner, geometry.poses(t))
            ends.append(geo.project_to_pixels(camera, moved, frame=t, resolution=(w, h))[0])
        out[i, hit] = (ends[1] - ends[0])[:, ::-1]
    return out.reshape(len(frames), h, w, 2)
