"""Rays against triangle meshes, in numpy: which triangle, which barycentric point, how far.

Used to name the surface point a pixel shows on a deforming mesh (a character): the point is
``(triangle, barycentric)`` on the mesh *as deformed at that frame*; the same coordinates on any
other frame's deformed mesh are the same material point (docs/characters.md).
"""

from __future__ import annotations

import numpy as np

#: rays × triangles tested per chunk (bounds memory at about 100 MB of float64 temporaries)
_CHUNK = 2_000_000


def ray_triangles(origins, directions, triangles, *, eps: float = 1e-12):
    """Nearest hit of each ray on the triangles (Möller–Trumbore, both faces).

    Args:
      origins, directions: (N, 3) rays (directions need not be unit length; ``distance`` is in
        units of the direction's length).
      triangles: (F, 3, 3) corner positions.

    Returns:
      (triangle (N,) int64, −1 where the ray misses; barycentric (N, 3) float64 weights of the
      three corners; distance (N,) float64, inf on a miss).
    """
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    tri = np.asarray(triangles, np.float64)
    p0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    n = len(o)
    best_t = np.full(n, np.inf)
    best_f = np.full(n, -1, np.int64)
    best_uv = np.zeros((n, 2))
    step = max(1, _CHUNK // max(1, len(tri)))
    for a in range(0, n, step):
        oo, dd = o[a:a + step, None, :], d[a:a + step, None, :]
        p = np.cross(dd, e2[None])
        det = np.einsum("nfi,fi->nf", p, e1)
        ok = np.abs(det) > eps
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = oo - p0[None]
        u = np.einsum("nfi,nfi->nf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("nfi,nfi->nf", np.broadcast_to(dd, q.shape), q) * inv
        t = np.einsum("nfi,fi->nf", q, e2) * inv
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t = np.where(hit, t, np.inf)
        f = np.argmin(t, axis=1)
        rows = np.arange(len(f))
        tt = t[rows, f]
        found = np.isfinite(tt)
        best_t[a:a + step] = tt
        best_f[a:a + step] = np.where(found, f, -1)
        best_uv[a:a + step] = np.stack([u[rows, f], v[rows, f]], -1) * found[:, None]
    bary = np.stack([1 - best_uv[:, 0] - best_uv[:, 1], best_uv[:, 0], best_uv[:, 1]], -1)
    bary[best_f < 0] = 0.0
    return best_f, bary, best_t
