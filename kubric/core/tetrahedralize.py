"""Tetrahedralising a closed triangle mesh for a soft solid (:meth:`kubric.Deformable.soft_mesh`).
Plain numpy and ``scipy.spatial`` (Delaunay, k-d tree).

Method (a Delaunay tetrahedralisation of surface and interior points): the nodes are the mesh's
own vertices (first, same indices, so its faces index the nodes unchanged and the rendered surface
*is* the input mesh) followed by the points of a cubic lattice of spacing ``spacing`` that lie
inside the mesh at least ``spacing / 2`` from its surface; the Delaunay tetrahedra of all nodes
whose centroid lies inside the mesh are kept, oriented positive
(:mod:`kubric.core.tet_meshes`), those of zero volume dropped. Inside = generalised winding number
> 1/2 (exact for a closed mesh). The solid's boundary (what the engine collides) is the
input surface where the surface triangles are Delaunay faces, and otherwise within about a lattice
spacing of it; its volume is checked against the mesh's (docs/deformables.md states the
tolerance, :data:`VOLUME_TOLERANCE`).
"""

from __future__ import annotations

import numpy as np

from kubric.core import tet_meshes
from kubric.errors import InputError

#: the tetrahedralisation's volume may differ from the mesh's enclosed volume by this fraction
#: at most (else one line: the mesh is too thin or too fine for the lattice)
VOLUME_TOLERANCE = 0.05
#: a tetrahedron whose volume is below this fraction of the mean is dropped (a flat tetrahedron
#: of coplanar points: a zero-stiffness element). Measured: dropping low-*quality* slivers
#: instead (6√2 · volume / rms edge³ < 0.003–0.05) leaves voids and makes PyBullet blow up on a
#: cube, so only flat ones go
SLIVER = 1e-9


def enclosed_volume(vertices, faces) -> float:
    """The volume (m³) a closed, outward-oriented triangle mesh encloses (divergence theorem)."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    return float(np.einsum("ij,ij->i", np.cross(tri[:, 1], tri[:, 2]), tri[:, 0]).sum() / 6)


def winding_numbers(vertices, faces, points) -> np.ndarray:
    """(N,) generalised winding numbers of ``points`` (N, 3) w.r.t. the triangle mesh: the
    solid angle the mesh subtends / 4π (Van Oosterom–Strackee); 1 inside a closed outward mesh,
    0 outside."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]      # (F, 3, 3)
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.empty(len(pts))
    chunk = max(1, 500_000 // len(tri))  # about 40 MB per array of the loop
    for s in range(0, len(pts), chunk):
        r = tri[None] - pts[s:s + chunk, None, None, :]                       # (n, F, 3, 3)
        a, b, c = r[..., 0, :], r[..., 1, :], r[..., 2, :]
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        det = np.einsum("nfi,nfi->nf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("nfi,nfi->nf", a, b) * lc
               + np.einsum("nfi,nfi->nf", b, c) * la + np.einsum("nfi,nfi->nf", c, a) * lb)
        out[s:s + chunk] = 2 * np.arctan2(det, den).sum(axis=1) / (4 * np.pi)
    return out


def check_closed(where: str, faces) -> None:
    """One line unless every directed edge of ``faces`` appears once and its reverse once (a
    closed, consistently oriented mesh)."""
    f = np.asarray(faces, np.int64)
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    keys, counts = np.unique(directed, axis=0, return_counts=True)
    if np.any(counts > 1):
        raise InputError(f"{where}: edge {keys[counts > 1][0].tolist()} is used twice in the same "
                         "direction; allowed: a closed, consistently oriented triangle mesh")
    back = set(map(tuple, keys[:, ::-1].tolist()))
    open_ = [e for e in keys.tolist() if tuple(e) not in back]
    if open_:
        raise InputError(f"{where}: edge {open_[0]} has no opposite face (the mesh is open); "
                         "allowed: a closed, consistently oriented triangle mesh")


def _surface_samples(vertices, faces, spacing: float) -> np.ndarray:
    """Points on every face about ``spacing`` / 4 apart (barycentric grid per face)."""
    tri = np.asarray(vertices, np.float64)[np.asarray(faces, np.int64)]
    longest = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max()
    n = int(np.clip(np.ceil(4 * longest / spacing), 1, 64))
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    bary = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], -1) / n        # (B, 3)
    return np.einsum("bk,fkj->fbj", bary, tri).reshape(-1, 3)


def tetrahedralize(vertices, faces, spacing: float | None = None, cells: int = 4):
    """Positive tetrahedra filling a closed triangle mesh (module doc).

    Args:
      vertices: (V, 3) mesh vertices (m); every vertex must be used by a face.
      faces: (F, 3) closed, consistently oriented, counter-clockwise seen from outside.
      spacing: the interior lattice's spacing (m); None: the box's longest side / ``cells``.
      cells: lattice cells along the longest side when ``spacing`` is None (≥ 1).

    Returns:
      (nodes (V + I, 3) float64: the mesh's vertices then I interior points, tetrahedra (T, 4)
      int32 positive). Every node is used by a tetrahedron.
    """
    from scipy.spatial import Delaunay, cKDTree
    where = "tetrahedralize"
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.all(np.isfinite(v)) or len(v) < 4:
        raise InputError(f"{where}: vertices must be (V ≥ 4, 3) finite, got shape {v.shape}")
    if f.ndim != 2 or f.shape[1] != 3 or f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{where}: faces must be (F, 3) indices in [0, {len(v) - 1}]")
    unused = np.setdiff1d(np.arange(len(v)), f)
    if len(unused):
        raise InputError(f"{where}: vertex {int(unused[0])} is used by no face; allowed: "
                         "a mesh whose vertices are all on its surface")
    check_closed(where, f)
    volume = enclosed_volume(v, f)
    if volume <= 0:
        raise InputError(f"{where}: the mesh encloses volume {volume:.3g} m³ (faces point "
                         "inwards?); allowed: outward faces, counter-clockwise seen from outside")
    lo, hi = v.min(axis=0), v.max(axis=0)
    if spacing is None:
        if isinstance(cells, bool) or int(cells) != cells or cells < 1:
            raise InputError(f"{where}: cells must be an integer ≥ 1, got {cells!r}")
        spacing = float((hi - lo).max()) / int(cells)
    if not np.isfinite(spacing) or spacing <= 0:
        raise InputError(f"{where}: spacing must be a positive number (m), got {spacing!r}")
    axes = [np.arange(a + spacing / 2, b, spacing) for a, b in zip(lo, hi, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    # a fixed jitter of 1 % of the spacing: a regular lattice is co-spherical in groups of 8,
    # where the Delaunay split is ambiguous and Qhull emits flat tetrahedra
    grid += np.random.RandomState(0).uniform(-0.01, 0.01, grid.shape) * spacing
    if len(grid):
        far = cKDTree(_surface_samples(v, f, spacing)).query(grid)[0] >= spacing / 2
        grid = grid[far]
        grid = grid[winding_numbers(v, f, grid) > 0.5]
    nodes = np.concatenate([v, grid])
    tets = Delaunay(nodes).simplices.astype(np.int64)
    tets = tets[winding_numbers(v, f, nodes[tets].mean(axis=1)) > 0.5]
    vol = tet_meshes.signed_volumes(nodes, tets)
    flip = vol < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    tets = tets[np.abs(vol) > SLIVER * np.abs(vol).mean()]
    loose = np.setdiff1d(np.arange(len(nodes)), tets)
    if np.any(loose < len(v)):
        raise InputError(f"{where}: surface vertex {int(loose[0])} is in no tetrahedron; allowed: "
                         "a mesh without parts thinner than its triangles")
    if len(loose):  # an interior point left out of every kept tetrahedron: drop it
        keep = np.setdiff1d(np.arange(len(nodes)), loose)
        remap = np.full(len(nodes), -1)
        remap[keep] = np.arange(len(keep))
        nodes, tets = nodes[keep], remap[tets]
    filled = tet_meshes.signed_volumes(nodes, tets).sum() / 6
    if abs(filled - volume) > VOLUME_TOLERANCE * volume:
        raise InputError(f"{where}: the tetrahedra fill {filled:.4g} m³ of the mesh's "
                         f"{volume:.4g} m³ (allowed: within {VOLUME_TOLERANCE:.0%}); use a finer "
                         "spacing or a mesh without thin parts")
    return nodes, tets.astype(np.int32)
