"""Keypoints of characters per frame: 2D, 3D and visibility. Pure numpy.

For each :class:`~kubric.core.characters.Character` with a keypoint regressor and each rendered
frame, for the keypoints asked for (default: the 17 COCO person keypoints, which the humans
source's and the procedural person's regressors provide):

* ``keypoints_3d`` (T, K, 3): world position, metres (the regressor on the skinned mesh);
* ``keypoints_camera`` (T, K, 3): camera frame (Blender axes: x right, y up, looking down −z);
* ``keypoints_2d`` (T, K, 2): pixel position (x, y), pixel centres at +0.5 (docs/conventions.md);
  under a rolling shutter (the camera's ``rolling_shutter_duration`` > 0) each keypoint is where
  it is seen when the row it lands on is read, and the 3D / camera fields are at that time
  (:func:`kubric.annotations.rolling_tracks.rolling_keypoints`);
* ``keypoints_depth`` (T, K): distance to the camera centre, metres;
* ``keypoint_occlusion_reason`` (T, K) uint8 bits, the point tracks' rule (docs/tracks.md):
  1 behind the camera, 2 outside the image, 4 the pixel shows another instance, 8 the rendered
  depth there is closer than the keypoint by more than the tolerance. Most keypoints lie *inside*
  the body (a joint centre), so the depth test compares the rendered depth with the keypoint's
  depth minus its **skin depth** (``keypoint_skin_depth``, (K,) metres: the keypoint's distance to
  the nearest rendered rest vertex, times the character's largest scale);
* ``keypoints_visibility`` (T, K) uint8, COCO's flag: 0 outside the image or behind the camera,
  1 in the image but occluded, 2 visible;
* ``keypoint_names`` (K,) and ``keypoint_skeleton`` (COCO's 1-based pairs, when the names are
  COCO's).

:func:`annotate_keypoints` stores these in each character's ``metadata``, so
``get_instance_info`` writes them with the instance into ``metadata.json`` (docs/scene-format.md).
:func:`coco_keypoints` turns one frame of them into COCO's annotation form (for a COCO export).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kubric.annotations.rolling_tracks import rolling_keypoints
from kubric.annotations.segmentation import instance_labels
from kubric.annotations.tracks import (
    BEHIND_CAMERA,
    DEPTH_TOLERANCE,
    OUTSIDE_IMAGE,
    depth_slope,
    frame_layers,
    occlusion_reasons,
)
from kubric.core import camera_geometry as geo
from kubric.core.characters import COCO_KEYPOINTS, COCO_SKELETON, Character
from kubric.core.rolling_shutter import duration_of
from kubric.errors import InputError

KEYPOINT_FIELDS = ("keypoint_names", "keypoint_skeleton", "keypoint_skin_depth", "keypoints_3d",
                   "keypoints_camera", "keypoints_2d", "keypoints_depth",
                   "keypoint_occlusion_reason", "keypoints_visibility")


def skin_depth(character) -> np.ndarray:
    """(K,) each rest keypoint's distance to the nearest rendered rest vertex (model units)."""
    reg = character.keypoint_regressor
    rest = np.stack([w @ character.vertices[i] for i, w in reg.values()])
    verts = character.vertices[character.rendered_vertices]
    return np.array([np.linalg.norm(verts - p, axis=1).min() for p in rest])


def character_keypoints(camera, frames: Sequence[int], depth, segmentation, assets: Sequence,
                        character, *, names: Sequence[str] = COCO_KEYPOINTS,
                        depth_tolerance: float = DEPTH_TOLERANCE, slope=None) -> dict:
    """Keypoint fields (module doc) of ``character`` over ``frames`` for the keypoints ``names``
    (default: the 17 COCO ones, in COCO's order; a regressor's other points, e.g. MakeHuman's
    foot points, are left out); ``depth`` / ``segmentation`` (T, H, W[, 1]) are the rendered
    layers labelled for ``assets`` (usually ``scene.assets``); ``slope``: their
    :func:`~kubric.annotations.tracks.depth_slope` when already computed."""
    if not isinstance(character, Character) or character.keypoint_regressor is None:
        raise InputError(f"{getattr(character, 'uid', character)!r} is not a Character with a "
                         "keypoint_regressor")
    missing = [n for n in names if n not in character.keypoint_names]
    if missing:
        raise InputError(f"{character.uid}: its keypoint regressor lacks {missing}; it has "
                         f"{list(character.keypoint_names)}")
    pick = [character.keypoint_names.index(n) for n in names]
    depth, labels, frames = frame_layers(depth, segmentation, frames)
    _, h, w = depth.shape
    label = int(instance_labels(assets)[list(assets).index(character)])
    if duration_of(camera) > 0:  # each keypoint at the time of the row it lands on
        world, xy, dist, cam, _ = rolling_keypoints(camera, frames, character, pick, (w, h))
    else:
        world = np.stack([character.keypoints(f)[pick] for f in frames])     # (T, K, 3)
        xy = np.zeros(world.shape[:2] + (2,))
        dist = np.zeros(world.shape[:2])
        cam = np.zeros(world.shape)
        for t, f in enumerate(frames):
            xy[t], dist[t] = geo.project_to_pixels(camera, world[t], frame=f, resolution=(w, h))
            m = geo.world_to_camera(camera, f)
            cam[t] = world[t] @ m[:3, :3].T + m[:3, 3]
    k = world.shape[1]
    skin = skin_depth(character)[pick] * float(np.max(character.scale))
    reason = occlusion_reasons(xy.transpose(1, 0, 2), cam[..., 2].T, dist.T - skin[:, None],
                               labels, depth, depth_slope(depth, labels) if slope is None
                               else slope, np.full(k, label),
                               depth_tolerance).T
    vis = np.where((reason & (BEHIND_CAMERA | OUTSIDE_IMAGE)) != 0, 0,
                   np.where(reason != 0, 1, 2)).astype(np.uint8)
    names = list(names)
    return {
        "keypoint_names": names,
        "keypoint_skeleton": [list(p) for p in COCO_SKELETON] if tuple(names) == COCO_KEYPOINTS
        else [],
        "keypoint_skin_depth": skin.astype(np.float32),
        "keypoints_3d": world.astype(np.float32),
        "keypoints_camera": cam.astype(np.float32),
        "keypoints_2d": xy.astype(np.float32),
        "keypoints_depth": dist.astype(np.float32),
        "keypoint_occlusion_reason": reason,
        "keypoints_visibility": vis,
    }


def annotate_keypoints(scene, layers: dict, characters: Sequence | None = None, *,
                       names: Sequence[str] = COCO_KEYPOINTS,
                       depth_tolerance: float = DEPTH_TOLERANCE) -> list:
    """Store :func:`character_keypoints` of every character with a regressor (default: all in
    the scene) in its ``metadata``; ``layers`` are the renderer's (labelled for
    ``scene.assets``, i.e. before relabelling). Returns the characters annotated."""
    if characters is None:
        characters = [a for a in scene.assets if isinstance(a, Character)
                      and a.keypoint_regressor is not None]
    frames = list(range(scene.frame_start, scene.frame_end + 1))
    if not characters:
        return []
    depth, labels, frames = frame_layers(layers["depth"], layers["segmentation"], frames)
    slope = depth_slope(depth, labels)  # once for every character
    for c in characters:
        c.metadata.update(character_keypoints(scene.camera, frames, depth, labels, scene.assets,
                                              c, names=names, depth_tolerance=depth_tolerance,
                                              slope=slope))
    return list(characters)


def coco_keypoints(keypoints_2d, visibility) -> tuple[list[float], int]:
    """One frame of a person's keypoints in COCO's annotation form: (``keypoints`` = [x1, y1, v1,
    x2, y2, v2, ...], ``num_keypoints`` = how many have v > 0).

    COCO's keypoint coordinates are pixel indices (the centre of the top-left pixel is (0, 0)),
    ours put pixel centres at +0.5, so x, y = ours − 0.5; v is our ``keypoints_visibility`` (0:
    outside the image, written as x = y = v = 0 as COCO's unlabelled points; 1 occluded; 2 visible).
    """
    xy = np.asarray(keypoints_2d, np.float64)
    vis = np.asarray(visibility).astype(np.int64)
    if xy.ndim != 2 or xy.shape[1] != 2 or vis.shape != xy.shape[:1]:
        raise InputError(f"coco_keypoints needs (K, 2) positions and (K,) flags, got {xy.shape} "
                         f"and {vis.shape}")
    out = []
    for (x, y), v in zip(xy - 0.5, vis, strict=True):
        out += [0.0, 0.0, 0] if v == 0 else [round(float(x), 3), round(float(y), 3), int(v)]
    return out, int(np.sum(vis > 0))
