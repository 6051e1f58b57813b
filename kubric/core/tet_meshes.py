"""Tetrahedral meshes for soft solids (:class:`kubric.core.deformables.Deformable`, kind "soft").
Plain numpy.

Orientation: a tetrahedron (a, b, c, d) is *positive* when ``((b − a) × (c − a)) · (d − a) > 0``;
PyBullet's NeoHookean bodies need every tetrahedron positive (measured: a mesh of negative ones
explodes on its first contact). Surface triangles are counter-clockwise seen from outside.
"""

from __future__ import annotations

import itertools

import numpy as np

from kubric.errors import InputError


def signed_volumes(vertices, tetrahedra) -> np.ndarray:
    """(T,) six times the signed volume of each tetrahedron (module doc's orientation)."""
    v = np.asarray(vertices, np.float64)
    t = np.asarray(tetrahedra, np.int64)
    a = v[t[:, 0]]
    return np.einsum("ij,ij->i", np.cross(v[t[:, 1]] - a, v[t[:, 2]] - a), v[t[:, 3]] - a)


def surface(vertices, tetrahedra) -> np.ndarray:
    """(F, 3) int32 boundary triangles (faces used by exactly one tetrahedron) of a mesh of
    positive tetrahedra, counter-clockwise seen from outside, in a fixed order."""
    t = np.asarray(tetrahedra, np.int64)
    # the faces of a positive (a, b, c, d) seen from outside
    tris = np.concatenate([t[:, [0, 2, 1]], t[:, [0, 1, 3]], t[:, [0, 3, 2]], t[:, [1, 2, 3]]])
    key = np.sort(tris, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return tris[np.sort(first[counts == 1])].astype(np.int32)


def box_uv(vertices, faces) -> np.ndarray:
    """(F, 3, 2) float32 box-mapped texture coordinates: each triangle is projected along the
    axis its normal is most aligned with, the other two coordinates normalised over the mesh's
    box (so every side of a box shows the whole texture)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    lo, hi = v.min(axis=0), v.max(axis=0)
    unit = (v - lo) / np.where(hi - lo > 0, hi - lo, 1.0)
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    axis = np.argmax(np.abs(normal), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[axis]                       # (F, 2)
    return np.take_along_axis(unit[f], keep[:, None, :], axis=2).astype(np.float32)


def box(size=(0.4, 0.4, 0.4), resolution=(3, 3, 3)):
    """A box of ``size`` (m, centred at the origin) split into ``resolution`` cells per axis,
    each cell into 6 positive tetrahedra (Kuhn's split along the cell's main diagonal, conforming
    between neighbours).

    Returns:
      (vertices ((nx+1)(ny+1)(nz+1), 3) float64, tetrahedra (6·nx·ny·nz, 4) int32, surface faces
      (F, 3) int32, uv (F, 3, 2) float32 box-mapped).
    """
    size = np.asarray(size, np.float64)
    if size.shape != (3,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise InputError(f"soft box: size must be three positive numbers (m), got "
                         f"{size.tolist()}")
    if np.shape(resolution) != (3,) or any(isinstance(r, bool) or int(r) != r or r < 1
                                           for r in resolution):
        raise InputError(f"soft box: resolution must be three integers ≥ 1, got {resolution!r}")
    n = [int(r) for r in resolution]
    axes = [np.linspace(-s / 2, s / 2, k + 1) for s, k in zip(size, n, strict=True)]
    vertices = np.array(list(itertools.product(*axes)))

    def index(i, j, k):
        return (i * (n[1] + 1) + j) * (n[2] + 1) + k

    tets = []
    for i, j, k in itertools.product(range(n[0]), range(n[1]), range(n[2])):
        for order in itertools.permutations(range(3)):
            corner = [i, j, k]
            tet = [index(*corner)]
            for ax in order:
                corner[ax] += 1
                tet.append(index(*corner))
            tets.append(tet)
    tets = np.array(tets, np.int64)
    flip = signed_volumes(vertices, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    faces = surface(vertices, tets)
    return vertices, tets.astype(np.int32), faces, box_uv(vertices, faces)
