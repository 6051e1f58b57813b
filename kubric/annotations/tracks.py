"""Exact point tracks (TAP-Vid-Kubric style) from the scene model and the exact layers. Pure numpy.

A track follows one surface point through every rendered frame. Its query ``(t, y, x)`` names a
frame index ``t`` (0 = the first rendered frame) and a pixel position ``(y, x)`` in that frame.

How a track is made (:func:`compute_tracks`):

1. **The query's 3D point** comes from the exact annotation layers of the query frame: the
   segmentation at the query's pixel says which object the point lies on, and the point is
   ``camera centre + depth · ray(x, y)`` (:func:`kubric.core.camera_geometry.unproject_pixels`
   with the camera of the query frame). At a pixel centre the depth is that pixel's value, which
   the annotation pass renders with one ray through the pixel centre, so the point is the surface
   point seen there (to float32 depth precision). Off a pixel centre the depth is interpolated
   bilinearly over the neighbouring pixel centres showing the same object (second-order error;
   the track still passes exactly through the query position at the query frame).
   On a skinned character the point is instead the mesh's surface point hit by the query's
   pixel ray at the query frame, as (triangle, barycentric), followed through every frame's
   skinned mesh (:mod:`kubric.annotations.character_tracks`; ``points_object`` is then its
   rest-pose position in the model frame).
2. The point is expressed **in its object's own frame** (the unscaled local frame of the mesh,
   using the object's position, quaternion and scale at the query frame). Points on the
   background (floor / dome: assets with ``background=True``) stay in world coordinates: the
   background never moves.
3. Each frame moves the point with the object's pose at that frame (``Asset.at_frame``: the
   keyframes the renderer also used) and projects it with that frame's camera
   (:func:`kubric.core.camera_geometry.project_to_pixels`). **Pixel convention: pixel centres at
   +0.5** — the centre of pixel (row r, column c) is ``(x, y) = (c + 0.5, r + 0.5)``, the image
   spans ``[0, W] × [0, H]``; this is TAP-Vid's "raster" convention too.
4. **Rolling shutter** (the camera's ``rolling_shutter_duration`` > 0): step 1 unprojects at
   the query row's time and step 3 puts each point where it is seen when the row it lands on
   is read (:mod:`kubric.annotations.rolling_tracks`).

Occlusion of track n at frame t (``occluded[n, t]``, with the reasons in ``occlusion_reason``
bits): the point is **behind the camera** (1), **outside the image** (2: x ∉ [0, W) or
y ∉ [0, H)), or at the pixel that contains it the rendered segmentation shows **another
instance** (4), or the rendered depth there is **closer than the point** by more than the
tolerance (8: self-occlusion, e.g. the far side of the object)::

    tolerance = depth_tolerance · depth(point) + reach · g

where ``g`` is the largest depth step from that pixel to a 4-neighbour showing the same instance
(the local depth slope: the pixel centre is up to 0.71 px from the point) and ``reach`` = 1 px.
``depth_tolerance`` defaults to :data:`DEPTH_TOLERANCE` (relative).

``visible[n, t]`` is the sub-pixel visible fraction: the bilinear weights of the four pixel
centres around the point summed over those where the point passes the same instance and depth
tests (``reach`` = 1.5 px; neighbours outside the image count as hidden). It is 1 deep inside a
visible surface, 0 when hidden, in between at silhouettes.

Query sampling (:func:`sample_queries`) follows TAP-Vid: a grid of stride ``stride`` over
(t, y, x) with a random offset per axis; the grid points are grouped by instance (the background
is one group, pixels that hit nothing are never sampled); groups are served from the smallest up,
each asked for an equal share of what is still needed and capped at ``max_fraction`` of its grid
points; if the caps leave the total short, the shortfall is taken from the groups with the most
grid points left (so a scene always yields exactly ``num_tracks``); points are drawn without
replacement and the result is shuffled. Every random number comes from the ``rng`` argument.

The result of :func:`compute_tracks` (see ``TRACK_FIELDS``; ``N`` tracks, ``T`` frames):

==================  ============  =========  ==================================================
key                 shape         dtype      meaning
==================  ============  =========  ==================================================
query_points        (N, 3)        float32    (t, y, x): frame index, pixel row / column position
target_points       (N, T, 2)     float32    (x, y) pixel position per frame (centres at +0.5)
occluded            (N, T)        bool       see above
occlusion_reason    (N, T)        uint8      bits: 1 behind camera, 2 outside image, 4 another
                                             instance at the pixel, 8 rendered depth closer
visible             (N, T)        float32    sub-pixel visible fraction in [0, 1]
depth               (N, T)        float32    Euclidean distance to the camera centre (metres)
points_world        (N, T, 3)     float32    world position per frame (metres, z up)
points_camera       (N, T, 3)     float32    camera-frame position (Blender: x right, y up,
                                             looking down −z)
points_object       (N, 3)        float64    the point in its object's unscaled local frame
                                             (world frame for the background)
instance_id         (N,)          int32      0 = background, k = metadata["instances"][k-1]
                                             (= the scene directory's segmentation label)
is_foreground       (N,)          bool       instance_id > 0
frames              (T,)          int32      the rendered frame numbers
resolution          (2,)          int32      (width, height)
pixel_offset        ()            float32    0.5 (pixel centres at +0.5)
depth_tolerance     ()            float32    the relative tolerance used
==================  ============  =========  ==================================================
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kubric.annotations.character_tracks import follow_character
from kubric.annotations.rolling_tracks import rolling_positions
from kubric.annotations.segmentation import instance_labels
from kubric.core import camera_geometry as geo
from kubric.core.deformables import DEFORMING
from kubric.core.rolling_shutter import duration_of, row_offset
from kubric.errors import InputError

#: Relative depth tolerance of the self-occlusion test (see module doc).
DEPTH_TOLERANCE = 1e-3
#: Occlusion reason bits.
BEHIND_CAMERA, OUTSIDE_IMAGE, OTHER_INSTANCE, DEPTH_CLOSER = 1, 2, 4, 8
PIXEL_OFFSET = 0.5
TRACK_FIELDS = ("query_points", "target_points", "occluded", "occlusion_reason", "visible",
                "depth", "points_world", "points_camera", "points_object", "instance_id",
                "is_foreground", "frames", "resolution", "pixel_offset", "depth_tolerance")
#: the fields a packed dataset carries (the ``<recipe>_tracks`` schemas derive their features
#: from this table): (key, dtype, shape with P tracks and T frames, unit, doc)
PACKED_TRACK_FIELDS = (
    ("query_points", "float32", ("P", 3), "",
     "(t, y, x): query frame index and pixel position (pixel centres at +0.5)"),
    ("target_points", "float32", ("P", "T", 2), "px",
     "(x, y) pixel position per frame (pixel centres at +0.5)"),
    ("occluded", "bool", ("P", "T"), "",
     "behind the camera, outside the image, or hidden by another surface"),
    ("occlusion_reason", "uint8", ("P", "T"), "",
     "bits: 1 behind camera, 2 outside image, 4 another instance, 8 depth closer"),
    ("visible", "float32", ("P", "T"), "", "sub-pixel visible fraction in [0, 1]"),
    ("depth", "float32", ("P", "T"), "m", "distance of the point to the camera centre"),
    ("points_world", "float32", ("P", "T", 3), "m", "3D position per frame, world frame"),
    ("instance_id", "int32", ("P",), "", "0 = background, k = instances[k − 1]"),
    ("is_foreground", "bool", ("P",), "", "the point lies on an instance"),
)


def _image_stack(array, name: str) -> np.ndarray:
    arr = np.asarray(array)
    if arr.ndim == 4 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim != 3:
        raise ValueError(f"{name} must have shape (T, H, W) or (T, H, W, 1), got {arr.shape}")
    return arr


# ---------------------------------------------------------------------------------- sampling
def grid_points_available(num_frames: int, height: int, width: int, stride: int) -> int:
    """Fewest grid points any random offset gives (an upper bound on ``num_tracks`` known
    before rendering)."""
    def fewest(n):
        return min(len(range(o, n, stride)) for o in range(min(stride, n)))
    return fewest(num_frames) * fewest(height) * fewest(width)


def allocate(counts: Sequence[int], num_tracks: int, max_fraction: float) -> np.ndarray:
    """Tracks per group (TAP-Vid's balanced allocation plus a shortfall fill; module doc)."""
    counts = np.asarray(counts, dtype=np.int64)
    if num_tracks > counts.sum():
        raise InputError(f"num_tracks={num_tracks} is more than the {int(counts.sum())} "
                         "trackable grid points of this scene")
    take = np.zeros_like(counts)
    remaining = int(num_tracks)
    order = np.argsort(counts, kind="stable")
    for i, g in enumerate(order):
        want = int(round(remaining / (len(order) - i)))
        cap = int(round(counts[g] * max_fraction))
        take[g] = min(want, cap, counts[g])
        remaining -= take[g]
    while remaining > 0:
        spare = counts - take
        g = int(np.argmax(spare))
        extra = min(int(spare[g]), remaining)
        take[g] += extra
        remaining -= extra
    return take


def sample_queries(groups, num_tracks: int, rng, *, stride: int = 4,
                   max_fraction: float = 0.1) -> np.ndarray:
    """Sample ``num_tracks`` query pixels (module doc).

    Args:
      groups: (T, H, W) int group of every pixel (e.g. instance id, 0 = background); negative =
        not trackable (the ray hits nothing).
      rng: a ``numpy.random.RandomState`` / ``Generator``.

    Returns:
      (num_tracks, 3) float32 queries (t, y, x) at pixel centres (y = row + 0.5, x = col + 0.5).
    """
    groups = _image_stack(groups, "groups")
    if num_tracks < 0:
        raise ValueError(f"num_tracks={num_tracks} must be ≥ 0")
    if stride < 1:
        raise ValueError(f"stride={stride} must be ≥ 1")
    start = [int(rng.randint(0, min(stride, n))) for n in groups.shape]
    grid = groups[start[0]::stride, start[1]::stride, start[2]::stride]
    t, r, c = np.meshgrid(*[np.arange(s, n, stride) for s, n in zip(start, groups.shape, strict=False)],
                          indexing="ij")
    coords = np.stack([t.ravel(), r.ravel(), c.ravel()], axis=-1)
    flat = grid.ravel()
    ids = np.unique(flat[flat >= 0])
    members = [np.flatnonzero(flat == g) for g in ids]
    take = allocate([len(m) for m in members], num_tracks, max_fraction)
    chosen = [m[rng.choice(len(m), size=k, replace=False)] for m, k in zip(members, take, strict=False) if k]
    picked = np.concatenate(chosen) if chosen else np.zeros(0, dtype=np.int64)
    picked = picked[rng.permutation(len(picked))]
    out = coords[picked].astype(np.float32)
    out[:, 1:] += PIXEL_OFFSET
    return out


def check_queries(queries, num_frames: int, width: int, height: int) -> np.ndarray:
    """(N, 3) float64 queries (t, y, x), or ValueError (one line) naming the first bad one:
    t must be an integer frame index in [0, num_frames), y in [0, height), x in [0, width)."""
    q = np.asarray(queries, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"queries must have shape (N, 3) rows (t, y, x), got {q.shape}")
    bad = ~np.isfinite(q).all(axis=1)
    bad |= (q[:, 0] != np.round(q[:, 0])) | (q[:, 0] < 0) | (q[:, 0] >= num_frames)
    bad |= (q[:, 1] < 0) | (q[:, 1] >= height) | (q[:, 2] < 0) | (q[:, 2] >= width)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"query {i} (t, y, x)={tuple(float(v) for v in q[i])} is outside the "
                         f"clip: t must be an integer in [0, {num_frames}), y in [0, {height}), "
                         f"x in [0, {width})")
    return q


# ---------------------------------------------------------------------------------- geometry
def _poses(asset, frames) -> tuple[np.ndarray, np.ndarray]:
    """(T, 4, 4) local → world matrices and (T, 3) scales of ``asset`` at ``frames``."""
    mats, scales = [], []
    for f in frames:
        with asset.at_frame(f):
            mats.append(asset.matrix_world)
            scales.append(np.asarray(asset.scale, dtype=np.float64))
    return np.stack(mats), np.stack(scales)


def depth_slope(depth: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(T, H, W) largest |depth step| to a 4-neighbour with the same label (0 if none)."""
    d = depth.astype(np.float64)
    out = np.zeros(d.shape)
    for axis in (1, 2):
        step = np.abs(np.diff(d, axis=axis))
        same = np.diff(labels, axis=axis) == 0
        step = np.where(same, step, 0.0)
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        out[tuple(lo)] = np.maximum(out[tuple(lo)], step)
        out[tuple(hi)] = np.maximum(out[tuple(hi)], step)
    return out


def _query_depth(depth, labels, t, y, x, label) -> float:
    """Depth along the ray through (x, y) (module doc, step 1)."""
    h, w = depth.shape[1:]
    fy = np.clip(np.nan_to_num(y, nan=-2.0), -2.0, h + 2.0) - PIXEL_OFFSET
    fx = np.clip(np.nan_to_num(x, nan=-2.0), -2.0, w + 2.0) - PIXEL_OFFSET
    r0, c0 = int(np.floor(fy)), int(np.floor(fx))
    if fy == r0 and fx == c0:
        return float(depth[t, r0, c0])
    total, weight = 0.0, 0.0
    for dr, dc in ((0, 0), (0, 1), (1, 0), (1, 1)):
        r, c = r0 + dr, c0 + dc
        if 0 <= r < h and 0 <= c < w and labels[t, r, c] == label:
            wgt = (1 - abs(fy - r)) * (1 - abs(fx - c))
            total += wgt * float(depth[t, r, c])
            weight += wgt
    if weight == 0.0:
        return float(depth[t, int(y), int(x)])
    return total / weight


def _visible_at(rows, cols, labels, depth, slope, want_label, point_depth, reach, tol, h, w):
    """(inside, same, not_closer) boolean (N, T) arrays for pixel (row, col): inside the image,
    shows ``want_label``, rendered depth no closer than the point − tolerance (module doc).
    ``rows`` / ``cols`` / ``point_depth`` are (N, T); ``labels`` / ``depth`` / ``slope`` (T, H, W)."""
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    rr, cc = np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)
    tt = np.broadcast_to(np.arange(rows.shape[1]), rows.shape)
    same = labels[tt, rr, cc] == want_label[:, None]
    limit = point_depth * (1.0 - tol) - reach * slope[tt, rr, cc]
    not_closer = depth[tt, rr, cc] >= limit
    return inside, same, not_closer


def frame_layers(depth, segmentation, frames) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(depth (T, H, W) float32, labels (T, H, W) int64, frames as ints), checked to agree."""
    depth = _image_stack(depth, "depth").astype(np.float32)
    labels = _image_stack(segmentation, "segmentation").astype(np.int64)
    frames = [int(f) for f in frames]
    if len(frames) != depth.shape[0] or labels.shape != depth.shape:
        raise ValueError(f"frames ({len(frames)}), depth {depth.shape} and segmentation "
                         f"{labels.shape} must agree")
    return depth, labels, frames


def occlusion_reasons(xy, cam_z, point_depth, labels, depth, slope, want_label,
                      depth_tolerance: float) -> np.ndarray:
    """(N, T) uint8 occlusion bits (module doc) of points at pixel positions ``xy`` (N, T, 2)
    with camera-frame z ``cam_z`` (N, T) and distances ``point_depth`` (N, T), which should lie
    on instance label ``want_label`` (N,)."""
    h, w = depth.shape[1:]
    reason = np.zeros(cam_z.shape, dtype=np.uint8)
    reason[cam_z >= 0] |= BEHIND_CAMERA
    x, y = xy[..., 0], xy[..., 1]
    with np.errstate(invalid="ignore"):
        outside = ~((x >= 0) & (x < w) & (y >= 0) & (y < h))
    reason[outside] |= OUTSIDE_IMAGE
    rows = np.floor(np.clip(np.nan_to_num(y, nan=-1.0), -1.0, h + 1.0)).astype(np.int64)
    cols = np.floor(np.clip(np.nan_to_num(x, nan=-1.0), -1.0, w + 1.0)).astype(np.int64)
    inside, same, not_closer = _visible_at(rows, cols, labels, depth, slope, want_label,
                                           point_depth, 1.0, depth_tolerance, h, w)
    inside &= (reason & BEHIND_CAMERA) == 0  # the pixel tests mean nothing behind the camera
    reason[inside & ~same] |= OTHER_INSTANCE
    reason[inside & same & ~not_closer] |= DEPTH_CLOSER
    return reason


def visible_fraction(xy, reason, point_depth, labels, depth, slope, want_label,
                     depth_tolerance: float) -> np.ndarray:
    """(N, T) sub-pixel visible fraction (module doc) of points at ``xy`` (N, T, 2) with
    occlusion bits ``reason`` and distances ``point_depth``, which should lie on label
    ``want_label`` (N,), against the layers ``labels`` / ``depth`` (T, H, W) and their slope."""
    h, w = depth.shape[1:]
    x, y = xy[..., 0], xy[..., 1]
    visible = np.zeros(reason.shape)
    fy = np.clip(np.nan_to_num(y, nan=-2.0), -2.0, h + 2.0) - PIXEL_OFFSET
    fx = np.clip(np.nan_to_num(x, nan=-2.0), -2.0, w + 2.0) - PIXEL_OFFSET
    r0, c0 = np.floor(fy), np.floor(fx)
    for dr in (0, 1):
        for dc in (0, 1):
            wgt = (1 - np.abs(fy - (r0 + dr))) * (1 - np.abs(fx - (c0 + dc)))
            ins, sm, nc = _visible_at((r0 + dr).astype(np.int64), (c0 + dc).astype(np.int64),
                                      labels, depth, slope, want_label, point_depth, 1.5,
                                      depth_tolerance, h, w)
            visible += np.where(ins & sm & nc, wgt, 0.0)
    visible[(reason & BEHIND_CAMERA) != 0] = 0.0
    return visible


def compute_tracks(camera, frames: Sequence[int], depth, segmentation, assets: Sequence,
                   queries, *, instances: Sequence | None = None,
                   depth_tolerance: float = DEPTH_TOLERANCE) -> dict[str, np.ndarray]:
    """Tracks for ``queries`` (module doc).

    Args:
      camera: the scene's camera (keyframed per frame).
      frames: the T rendered frame numbers; layer index t is frame ``frames[t]``.
      depth: (T, H, W[, 1]) Euclidean depth layer (BACKGROUND_DEPTH where nothing is hit).
      segmentation: (T, H, W[, 1]) labels as rendered for ``assets`` (label k = ``assets[k-1]``
        or its ``segmentation_id``; 0 = nothing).
      assets: the asset list the segmentation was made for (usually ``scene.assets``).
      queries: (N, 3) (t, y, x) (see :func:`check_queries`).
      instances: the foreground instances in output order (``instance_id`` k =
        ``instances[k-1]``); default: the foreground assets hit by a query, in ``assets`` order.
        Assets with ``background=True`` are the background (instance 0).
    """
    depth, labels, frames = frame_layers(depth, segmentation, frames)
    num_frames, h, w = depth.shape
    q = check_queries(queries, num_frames, w, h)
    by_label = dict(zip(instance_labels(assets).tolist(), assets, strict=False))
    n = len(q)
    tq = q[:, 0].astype(np.int64)
    rq, cq = np.floor(q[:, 1]).astype(np.int64), np.floor(q[:, 2]).astype(np.int64)
    qlabel = labels[tq, rq, cq]
    missing = (qlabel == 0) | (depth[tq, rq, cq] >= geo.BACKGROUND_DEPTH * 0.999)
    if missing.any():
        i = int(np.flatnonzero(missing)[0])
        raise InputError(f"query {i} (t, y, x)={tuple(float(v) for v in q[i])} hits no surface "
                         "(the pixel shows the empty background): nothing to track there")
    qassets = [by_label[int(lab)] for lab in qlabel]
    is_fg = np.array([not a.background for a in qassets], dtype=bool)
    if instances is None:
        hit = {a.uid for a, fg in zip(qassets, is_fg, strict=False) if fg}
        instances = [a for a in assets if a.uid in hit]
    ids = {a.uid: k for k, a in enumerate(instances, start=1)}
    instance_id = np.array([ids[a.uid] if fg else 0 for a, fg in zip(qassets, is_fg, strict=False)],
                           dtype=np.int32)
    if np.any(is_fg & (instance_id == 0)):
        i = int(np.flatnonzero(is_fg & (instance_id == 0))[0])
        raise InputError(f"query {i} lies on {qassets[i].uid}, which is not in `instances`")

    # 1.–2. query points in world, then in their object's frame
    qdepth = np.array([_query_depth(depth, labels, tq[i], q[i, 1], q[i, 2], qlabel[i])
                       for i in range(n)])
    world_q = np.zeros((n, 3))
    # the query's time: its frame, or under a rolling shutter the time its row is read
    qtime = np.asarray(frames, np.float64)[tq] + row_offset(duration_of(camera), q[:, 1], h)
    for t in np.unique(qtime):
        sel = qtime == t
        world_q[sel] = geo.unproject_pixels(camera, q[sel][:, [2, 1]], qdepth[sel],
                                            frame=float(t), resolution=(w, h))
    points_object = world_q.copy()
    points_world = np.repeat(world_q[:, None, :], num_frames, axis=1)
    anchors = {}  # track index → (triangle, barycentric) of tracks on deforming surfaces
    for uid in {a.uid for a, fg in zip(qassets, is_fg, strict=False) if fg}:
        sel = np.array([a.uid == uid for a in qassets]) & is_fg
        asset = qassets[int(np.flatnonzero(sel)[0])]
        if isinstance(asset, DEFORMING):  # a deforming surface: kubric.annotations.character_tracks
            points_object[sel], points_world[sel], tri, bary = follow_character(
                asset, camera, frames, qtime[sel], q[sel][:, [2, 1]], world_q[sel], (w, h))
            anchors.update(zip(np.flatnonzero(sel).tolist(), zip(tri.tolist(), bary, strict=True),
                               strict=True))
            continue
        mats, scales = _poses(asset, frames)
        for t in np.unique(qtime[sel]):
            s = sel & (qtime == t)
            (qmat,), (qscale,) = _poses(asset, [float(t)])
            points_object[s] = (world_q[s] - qmat[:3, 3]) @ qmat[:3, :3] / qscale
        local = points_object[sel][:, None, :] * scales[None]          # (n, T, 3)
        points_world[sel] = np.einsum("tij,ntj->nti", mats[:, :3, :3], local) + mats[:, :3, 3]

    # 3. project with every frame's camera
    xy = np.zeros((n, num_frames, 2))
    dist = np.zeros((n, num_frames))
    cam = np.zeros((n, num_frames, 3))
    for t, f in enumerate(frames):
        xy[:, t], dist[:, t] = geo.project_to_pixels(camera, points_world[:, t], frame=f,
                                                     resolution=(w, h))
        m = geo.world_to_camera(camera, f)
        cam[:, t] = points_world[:, t] @ m[:3, :3].T + m[:3, 3]
    if duration_of(camera) > 0:  # each point at the time of the row it lands on
        xy, dist, cam, points_world = rolling_positions(camera, frames, qassets, is_fg,
                                                        points_object, (w, h), anchors)

    # occlusion
    slope = depth_slope(depth, labels)
    reason = occlusion_reasons(xy, cam[..., 2], dist, labels, depth, slope, qlabel,
                               depth_tolerance)
    occluded = reason != 0
    visible = visible_fraction(xy, reason, dist, labels, depth, slope, qlabel, depth_tolerance)

    return {
        "query_points": q.astype(np.float32),
        "target_points": xy.astype(np.float32),
        "occluded": occluded,
        "occlusion_reason": reason,
        "visible": np.clip(visible, 0.0, 1.0).astype(np.float32),
        "depth": dist.astype(np.float32),
        "points_world": points_world.astype(np.float32),
        "points_camera": cam.astype(np.float32),
        "points_object": points_object,
        "instance_id": instance_id,
        "is_foreground": is_fg,
        "frames": np.asarray(frames, dtype=np.int32),
        "resolution": np.array([w, h], dtype=np.int32),
        "pixel_offset": np.float32(PIXEL_OFFSET),
        "depth_tolerance": np.float32(depth_tolerance),
    }


def trackable_groups(segmentation, depth, assets: Sequence, instances: Sequence) -> np.ndarray:
    """(T, H, W) int32 sampling groups for :func:`sample_queries`: the instance id (0 for the
    background), −1 where the ray hits nothing or an asset not in ``instances`` and not
    background."""
    labels = _image_stack(segmentation, "segmentation").astype(np.int64)
    depth = _image_stack(depth, "depth")
    ids = {a.uid: k for k, a in enumerate(instances, start=1)}
    lut = np.full(int(max(labels.max(), instance_labels(assets).max(initial=0))) + 1, -1,
                  dtype=np.int32)
    for label, asset in zip(instance_labels(assets).tolist(), assets, strict=False):
        lut[label] = 0 if asset.background else ids.get(asset.uid, -1)
    out = lut[labels]
    out[depth >= geo.BACKGROUND_DEPTH * 0.999] = -1
    return out


def load_queries(path) -> np.ndarray:
    """Queries from a file: ``.npy`` (N, 3), ``.json`` (a list of [t, y, x] rows) or text (one
    row per line, numbers separated by spaces and / or commas). ValueError (one line) when unreadable."""
    import io
    import json
    import pathlib
    path = pathlib.Path(path)
    try:
        if path.suffix == ".npy":
            q = np.load(path, allow_pickle=False)
        elif path.suffix == ".json":
            q = np.asarray(json.loads(path.read_text()), dtype=np.float64)
        else:
            q = np.loadtxt(io.StringIO(path.read_text().replace(",", " ")), ndmin=2)
        q = np.asarray(q, dtype=np.float64)
    except (OSError, ValueError, TypeError) as err:  # TypeError: a JSON object, not rows
        raise InputError(f"cannot read queries from {str(path)!r}: expected rows (t, y, x) "
                         f"({' '.join(str(err).split())[:200]})") from None
    if q.ndim != 2 or q.shape[1] != 3 or not len(q):
        raise InputError(f"queries file {str(path)!r} must hold rows (t, y, x), got shape "
                         f"{q.shape}")
    return q


def scene_tracks(scene, layers: dict, instances: Sequence, rng, *, num_tracks: int = 0,
                 queries=None, stride: int = 4, max_fraction: float = 0.1,
                 depth_tolerance: float = DEPTH_TOLERANCE) -> dict[str, np.ndarray]:
    """Tracks of a rendered scene: ``queries`` if given, else ``num_tracks`` sampled with
    ``rng``. ``layers`` are the renderer's (segmentation labels made for ``scene.assets``, i.e.
    before relabelling); ``instances`` give the instance ids (the metadata's instance list)."""
    frames = list(range(scene.frame_start, scene.frame_end + 1))
    if queries is None:
        groups = trackable_groups(layers["segmentation"], layers["depth"], scene.assets,
                                  instances)
        queries = sample_queries(groups, num_tracks, rng, stride=stride,
                                 max_fraction=max_fraction)
    return compute_tracks(scene.camera, frames, layers["depth"], layers["segmentation"],
                          scene.assets, queries, instances=instances,
                          depth_tolerance=depth_tolerance)
