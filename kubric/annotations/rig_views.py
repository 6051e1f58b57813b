"""Annotations of the further cameras of a rig (:mod:`kubric.core.rig`). Pure numpy.

* :func:`disparity`: the rectified stereo pair's disparity layer of the left image, defined by
  correspondence: the surface point seen through a left pixel centre (its exact depth, along the
  pixel's ray) is projected into the right camera, and disparity = x_left − x_right (pixels,
  image columns; 0 where the pixel sees nothing). For a rectified pair this is f·B / Z with Z the
  point's z-depth (the tests check that identity against the raycast oracle).
* :func:`view_tracks`: the reference camera's point tracks seen from another camera of the rig —
  the same surface points (``points_world``), projected with that camera and tested for
  occlusion against that camera's own depth and labels, with the rules and fields of
  :mod:`kubric.annotations.tracks` (``query_points`` stay the reference camera's queries).
* :func:`view_instances`: per instance, that camera's visible pixels, 2D boxes and image
  positions, stored in ``asset.metadata["cameras"][name]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kubric.annotations import tracks as tr
from kubric.annotations.segmentation import bounding_boxes, pixel_counts
from kubric.core import camera_geometry as geo


def check_rectified(rig) -> None:
    """ValueError (one line) unless ``rig`` is a pinhole stereo pair with a baseline along x."""
    mount = rig.mounts.get("right")
    if rig.kind != "stereo" or mount is None:
        raise ValueError(f"disparity needs a stereo rig (left, right), got a {rig.kind} rig "
                         f"with cameras {rig.names}")
    if geo.has_distortion(rig.reference):
        raise ValueError(f"disparity needs pinhole cameras (a rectified pair), got lens "
                         f"{geo.lens_of(rig.reference).name!r}")
    if not (np.allclose(mount[:3, :3], np.eye(3)) and np.allclose(mount[1:3, 3], 0)):
        raise ValueError("disparity needs the right camera translated along the left camera's "
                         "+x only (a rectified pair)")


def disparity(left, right, depth: np.ndarray, frames: Sequence[int]) -> np.ndarray:
    """(T, H, W, 1) float32 disparity in pixels of the left image (module doc) from the left
    camera's exact ``depth`` layer (T, H, W[, 1], metres along the ray)."""
    depth = np.asarray(depth, np.float64).reshape(len(frames), *np.shape(depth)[1:3])
    _, h, w = depth.shape
    centres = geo.pixel_centres(h, w)
    out = np.zeros(depth.shape + (1,), np.float32)
    for i, frame in enumerate(frames):
        hit = depth[i] < geo.BACKGROUND_DEPTH * 0.999
        points = geo.unproject_pixels(left, centres[hit], depth[i][hit], frame, (w, h))
        xy, _ = geo.project_to_pixels(right, points, frame, (w, h))
        out[i, hit, 0] = centres[hit][:, 0] - xy[:, 0]
    return out


def view_tracks(reference_tracks: dict, camera, frames: Sequence[int], depth, segmentation,
                reference_segmentation, depth_tolerance: float = tr.DEPTH_TOLERANCE) -> dict:
    """The reference camera's tracks (:func:`kubric.annotations.tracks.compute_tracks`' dict)
    seen from ``camera``, whose raw layers (labelled for ``scene.assets``, before relabelling)
    are ``depth`` and ``segmentation``; ``reference_segmentation`` (raw) gives each track's label
    at its query. Same fields; positions, depths, occlusion and visibility are ``camera``'s."""
    depth, labels, frames = tr.frame_layers(depth, segmentation, frames)
    ref_labels = tr.frame_layers(depth, reference_segmentation, frames)[1]
    h, w = depth.shape[1:]
    q = np.asarray(reference_tracks["query_points"], np.float64)
    qlabel = ref_labels[q[:, 0].astype(np.int64), np.floor(q[:, 1]).astype(np.int64),
                        np.floor(q[:, 2]).astype(np.int64)]
    world = np.asarray(reference_tracks["points_world"], np.float64)
    n, num_frames = world.shape[:2]
    xy = np.zeros((n, num_frames, 2))
    dist = np.zeros((n, num_frames))
    cam = np.zeros((n, num_frames, 3))
    for t, f in enumerate(frames):
        xy[:, t], dist[:, t] = geo.project_to_pixels(camera, world[:, t], f, (w, h))
        m = geo.world_to_camera(camera, f)
        cam[:, t] = world[:, t] @ m[:3, :3].T + m[:3, 3]
    slope = tr.depth_slope(depth, labels)
    reason = tr.occlusion_reasons(xy, cam[..., 2], dist, labels, depth, slope, qlabel,
                                  depth_tolerance)
    visible = tr.visible_fraction(xy, reason, dist, labels, depth, slope, qlabel,
                                  depth_tolerance)
    return {**reference_tracks, "target_points": xy.astype(np.float32),
            "occluded": reason != 0, "occlusion_reason": reason,
            "visible": np.clip(visible, 0.0, 1.0).astype(np.float32),
            "depth": dist.astype(np.float32), "points_camera": cam.astype(np.float32)}


def view_instances(name: str, camera, segmentation, instances: Sequence,
                   frames: Sequence[int], resolution) -> None:
    """Store camera ``name``'s ``visibility`` (T,) pixels, ``bboxes`` / ``bbox_frames`` (as the
    reference camera's) and ``image_positions`` (T, 2 normalised) in every instance's
    ``metadata["cameras"][name]``; ``segmentation`` is relabelled (label k = instances[k − 1])."""
    counts = pixel_counts(segmentation, np.arange(1, len(instances) + 1))
    seg = np.asarray(segmentation).reshape(np.shape(segmentation)[:3])
    for k, (asset, row) in enumerate(zip(instances, counts, strict=True), start=1):
        boxes, box_frames = bounding_boxes(seg, k)
        positions = asset.get_values_over_time("position", frames)
        image = np.array([geo.project_points(camera, p, f, resolution)[:2]
                          for f, p in zip(frames, positions, strict=True)], np.float32)
        views = dict(asset.metadata.get("cameras", {}))
        views[name] = {**views.get(name, {}), "visibility": row, "bboxes": boxes,
                       "bbox_frames": box_frames, "image_positions": image.reshape(-1, 2)}
        asset.metadata["cameras"] = views


__all__ = ["check_rectified", "disparity", "view_instances", "view_tracks"]
