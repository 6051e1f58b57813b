"""Occlusion boundaries from the exact layers (docs/conventions.md#occlusion-boundaries). Pure numpy.

A boundary lies on the edge between two 4-neighbour pixels p, q (their centres one pixel apart)
when, with ``l`` the renderer's segmentation label (0 = nothing hit) and ``d`` the depth
(distance to the camera centre) at the pixel centres:

* **object boundary**: ``l_p ≠ l_q`` (two assets, or an asset and the empty background), or
* **depth discontinuity** on one asset (``l_p = l_q ≠ 0``, e.g. a handle in front of its mug):
  ``|d_p − d_q| > DEPTH_JUMP · min(d_p, d_q)`` and ``|d_p − d_q| > SLOPE_FACTOR · s``, where
  ``s`` is the larger of the two steps continuing the line p → q on the same asset (from p's
  other neighbour to p, from q to q's other neighbour; 0 where there is none): a smooth surface
  seen at a grazing angle (the far floor) has steps that grow gradually, a jump does not.

The **occluding side** of a boundary edge is the pixel with the smaller depth (the nearer
surface; nothing hit is 10000 m away); equal depths: neither.

The layer (``occlusion_boundaries``, uint8, kind ``edge_bits``): bit 0 / 1 / 2 / 3 = a boundary
on the edge to the pixel above / below / left / right; bit 4 + the same index = this pixel is the
occluding side of that edge. A pixel lies on a boundary iff ``value & 15``.
"""

from __future__ import annotations

import numpy as np

#: relative depth step of a discontinuity on one asset
DEPTH_JUMP = 0.02
#: how much larger than the continuing steps a depth step must be
SLOPE_FACTOR = 2.0
#: edge bits: (direction, (Δrow, Δcol)) in bit order
DIRECTIONS = (("up", (-1, 0)), ("down", (1, 0)), ("left", (0, -1)), ("right", (0, 1)))
OCCLUDES = 4  # bit offset of the occluding-side flags


def _edges_along(labels: np.ndarray, depth: np.ndarray):
    """Boundary and occluder flags of the edges between element i and i + 1 along the last axis
    of (..., L) arrays: (boundary (..., L − 1), first_is_nearer, second_is_nearer)."""
    lp, lq = labels[..., :-1], labels[..., 1:]
    dp, dq = depth[..., :-1], depth[..., 1:]
    step = np.abs(dq - dp)
    same = lp == lq
    # continuing steps on the same label: before p (p−1 → p) and after q (q → q+1)
    before = np.zeros_like(step)
    before[..., 1:] = np.where(same[..., :-1], step[..., :-1], 0.0)
    after = np.zeros_like(step)
    after[..., :-1] = np.where(same[..., 1:], step[..., 1:], 0.0)
    jump = (step > DEPTH_JUMP * np.minimum(dp, dq)) & \
        (step > SLOPE_FACTOR * np.maximum(before, after))
    boundary = ~same | (same & (lp != 0) & jump)
    return boundary, boundary & (dp < dq), boundary & (dq < dp)


def occlusion_boundaries(depth, segmentation) -> np.ndarray:
    """(T, H, W, 1) uint8 edge bits (module doc) of (T, H, W[, 1]) depth and renderer labels."""
    d = np.asarray(depth, np.float64)
    lab = np.asarray(segmentation)
    d = d[..., 0] if d.ndim == 4 else d
    lab = lab[..., 0] if lab.ndim == 4 else lab
    if d.shape != lab.shape or d.ndim != 3:
        raise ValueError(f"occlusion_boundaries: depth {d.shape} and segmentation {lab.shape} "
                         "must both be (T, H, W[, 1])")
    out = np.zeros(d.shape, np.uint8)
    for axis, (first_bit, second_bit) in ((1, (1, 0)), (2, (3, 2))):
        # along rows (axis 1: p above q → p's "down" edge, q's "up" edge), then columns
        dm, lm = np.moveaxis(d, axis, -1), np.moveaxis(lab, axis, -1)
        boundary, p_near, q_near = _edges_along(lm, dm)
        view = np.moveaxis(out, axis, -1)
        view[..., :-1] |= (boundary.astype(np.uint8) << first_bit) | \
            (p_near.astype(np.uint8) << (first_bit + OCCLUDES))
        view[..., 1:] |= (boundary.astype(np.uint8) << second_bit) | \
            (q_near.astype(np.uint8) << (second_bit + OCCLUDES))
    return out[..., None]
