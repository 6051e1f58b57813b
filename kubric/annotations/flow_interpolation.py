"""Images between rendered frames, warped along the exact optical flow with its occlusions: a
cheap source of sub-frame intensity for event streams (:mod:`kubric.annotations.event_camera`;
docs/conventions.md, "Event streams"). Pure numpy.

Between frames t and t + 1, the image at t + s (0 < s < 1) is made by **forward splatting**
both frames to where their surface points are at t + s, assuming each point moves on a straight
line in the image over the frame interval:

* frame t's pixel p (its centre) goes to p + s · forward_flow_t(p), at depth
  (1 − s) · depth_t(p) + s · depth at t + 1 (the depth it has there is not known per pixel: the
  forward flow's target is sampled in depth_{t+1}, nearest pixel);
* frame t + 1's pixel q goes to q + (1 − s) · backward_flow_{t+1}(q) likewise;
* each splat spreads bilinearly over the four pixel centres around its target; per target pixel
  only splats within ``depth_tolerance`` (relative) of the surface there count: the nearest of
  the splats that land mostly on it (bilinear weight ≥ ¼), else the nearest of all (a z-buffer
  with soft edges: an occluded surface does not bleed through, and the corner of a splat that
  grazes a pixel does not hide the surface that covers it);
* a pixel reached from both frames takes (1 − s) · frame t's splats + s · frame t + 1's
  (normalised by their weights); from one frame only (a surface being uncovered or covered):
  that frame's; from neither (background, or a hole where the flow stretches): the linear blend
  (1 − s) · I_t + s · I_{t+1} of the two frames at that pixel.

Background pixels (depth ≥ the background depth) carry flow 0 and splat at their own place
behind everything. The result equals the rendered frames at s = 0 and s = 1.
"""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo


def _splat(image, flow, depth, target_depth, s: float, tol: float):
    """(sum of weighted values (H, W, C), sum of weights (H, W)) of ``image`` splatted to
    p + s · flow at depth interpolated towards ``target_depth``; module doc."""
    h, w = depth.shape
    rows, cols = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64),
                             indexing="ij")
    r, c = rows + s * flow[..., 0], cols + s * flow[..., 1]
    tr = np.clip(np.rint(rows + flow[..., 0]), 0, h - 1).astype(np.int64)
    tc = np.clip(np.rint(cols + flow[..., 1]), 0, w - 1).astype(np.int64)
    z = (1 - s) * depth + s * target_depth[tr, tc]
    z = np.where(depth >= geo.BACKGROUND_DEPTH, geo.BACKGROUND_DEPTH, z)
    r0, c0 = np.floor(r).astype(np.int64), np.floor(c).astype(np.int64)
    fr, fc = r - r0, c - c0
    targets, weights = [], []
    for dr, dc, wgt in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc),
                        (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
        rr, cc = r0 + dr, c0 + dc
        ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w) & (wgt > 1e-6)
        targets.append(np.where(ok, rr * w + cc, -1).ravel())
        weights.append(np.where(ok, wgt, 0.0).ravel())
    target, weight = np.concatenate(targets), np.concatenate(weights)
    zs, values = np.tile(z.ravel(), 4), np.tile(image.reshape(h * w, -1), (4, 1))
    keep = target >= 0
    target, weight, zs, values = target[keep], weight[keep], zs[keep], values[keep]
    nearest = np.full(h * w, np.inf)  # of the splats that mostly land there (weight ≥ ¼)
    strong = weight >= 0.25
    np.minimum.at(nearest, target[strong], zs[strong])
    weak = np.full(h * w, np.inf)  # a pixel only grazed by splats: the nearest of those
    np.minimum.at(weak, target, zs)
    nearest = np.where(np.isfinite(nearest), nearest, weak)
    front = np.abs(zs - nearest[target]) <= nearest[target] * tol
    acc = np.zeros((h * w, values.shape[1]))
    np.add.at(acc, target[front], values[front] * weight[front, None])
    total = np.zeros(h * w)
    np.add.at(total, target[front], weight[front])
    return acc.reshape(h, w, -1), total.reshape(h, w), nearest.reshape(h, w)


def interpolate(image0, image1, forward_flow0, backward_flow1, depth0, depth1, s: float,
                depth_tolerance: float = 0.02) -> np.ndarray:
    """(H, W, C) float64 image at t + ``s`` between ``image0`` (frame t) and ``image1`` (t + 1),
    each (H, W, C); flows (H, W, 2) (Δrow, Δcol) px, depths (H, W[, 1]) m (module doc)."""
    if not 0.0 <= s <= 1.0:
        raise ValueError(f"interpolate: s must be in [0, 1], got {s!r}")
    a = np.asarray(image0, np.float64)
    b = np.asarray(image1, np.float64)
    d0, d1 = (np.asarray(d, np.float64).reshape(a.shape[:2]) for d in (depth0, depth1))
    if s == 0.0 or s == 1.0:
        return (a if s == 0.0 else b).copy()
    f0, b1 = np.asarray(forward_flow0, np.float64), np.asarray(backward_flow1, np.float64)
    acc0, w0, z0 = _splat(a, f0, d0, d1, s, depth_tolerance)
    acc1, w1, z1 = _splat(b, b1, d1, d0, 1.0 - s, depth_tolerance)
    # the two frames' splats of one surface agree in depth; where one frame's nearest splat is
    # clearly in front, the other frame's splat there is an occluded surface: drop it
    use0 = (w0 > 1e-9) & ~(z1 * (1 + depth_tolerance) < z0)
    use1 = (w1 > 1e-9) & ~(z0 * (1 + depth_tolerance) < z1)
    v0 = acc0 / np.maximum(w0, 1e-12)[..., None]
    v1 = acc1 / np.maximum(w1, 1e-12)[..., None]
    blend = (1 - s) * a + s * b
    both = use0 & use1
    out = np.where(both[..., None], (1 - s) * v0 + s * v1, blend)
    out = np.where((use0 & ~use1)[..., None], v0, out)
    return np.where((use1 & ~use0)[..., None], v1, out)


def interpolate_sequence(images, forward_flow, backward_flow, depth, k: int,
                         depth_tolerance: float = 0.02) -> np.ndarray:
    """(1 + (T − 1) · k, H, W, C) float64: the T frames ``images`` (T, H, W, C) with k − 1
    interpolated images between each two (times frame + j / k), from the (T, H, W, 2) flows and
    (T, H, W[, 1]) depth of the same frames."""
    images = np.asarray(images)
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"interpolate_sequence: k must be a whole number ≥ 1, got {k!r}")
    t_ = len(images)
    out = []
    for t in range(t_ - 1):
        for j in range(k):
            out.append(interpolate(images[t], images[t + 1], forward_flow[t],
                                   backward_flow[t + 1], depth[t], depth[t + 1], j / k,
                                   depth_tolerance))
    out.append(np.asarray(images[-1], np.float64))
    return np.stack(out)
