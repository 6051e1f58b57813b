"""Deformable objects (:class:`Deformable`): cloth sheets and soft solids whose simulated vertices
are the truth.

As for skinned characters (:mod:`kubric.core.characters`), the model holds the deforming mesh
itself and every view follows it: the simulator writes the vertex positions of every frame into
the model (the keyframable ``simulated_vertices``), the renderers draw the triangles between those
vertices, and flow and tracks follow material points of the mesh (a triangle and barycentric
weights) through them, so they are exact for the rendered surface. Conventions: docs/deformables.md.

Frames: the **rest mesh** (``vertices`` (V, 3), metres) is given in the object's unscaled model
frame; the object's pose (position, quaternion, scale) places it in the world before the
simulation (the rest state). ``simulated_vertices`` (V, 3) are **world** positions; unset (None),
the mesh is the rest mesh placed by the pose. Between keyed frames the vertices interpolate
linearly (what a renderer's shape keys do), outside the keyed range they hold the end values.
Object coordinates on a deformable are rest-state model-frame points (the material point, not
where the simulation moved it), as on characters.
"""

from __future__ import annotations

import numpy as np

from kubric.core import skinning as sk
from kubric.core import tet_meshes
from kubric.core import traits as kt
from kubric.core.characters import Character, _array, _integers
from kubric.core.objects import PhysicalObject
from kubric.errors import InputError

KINDS = ("cloth", "soft")


def cloth_grid(size=(1.0, 1.0), resolution=(16, 16)):
    """A flat rectangular sheet in the model's xy plane (z = 0), centred at the origin.

    Args:
      size: (width along x, depth along y) in metres, both > 0.
      resolution: (nx, ny) vertices along x and y, both ≥ 2.

    Returns:
      (vertices (nx·ny, 3) float64, faces (2·(nx−1)·(ny−1), 3) int32 counter-clockwise seen from
      +z (normal +z), uv (F, 3, 2) float32: u = (x − x0) / width, v = (y − y0) / depth).
      Vertex (i, j) (column i along x, row j along y) has index j·nx + i.
    """
    size = np.asarray(size, np.float64)
    if size.shape != (2,) or not np.all(np.isfinite(size)) or np.any(size <= 0):
        raise InputError(f"cloth_grid: size must be two positive numbers (m), got {size.tolist()}")
    if np.shape(resolution) != (2,) or any(isinstance(r, bool) or int(r) != r or r < 2
                                           for r in resolution):
        raise InputError(f"cloth_grid: resolution must be two integers ≥ 2, got {resolution!r}")
    nx, ny = (int(r) for r in resolution)
    u, v = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="xy")
    vertices = np.stack([(u.ravel() - 0.5) * size[0], (v.ravel() - 0.5) * size[1],
                         np.zeros(nx * ny)], -1)
    col, row = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing="xy")
    a = (row * nx + col).ravel()
    b, c, d = a + 1, a + nx + 1, a + nx
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)]).astype(np.int32)
    uv_vertex = np.stack([u.ravel(), v.ravel()], -1)
    return vertices, faces, uv_vertex[faces].astype(np.float32)


def checker_image(squares=(8, 8), pixels_per_square: int = 16, colors=None) -> np.ndarray:
    """(H, W, 3) uint8 sRGB checkerboard of ``squares`` (u, v) squares (a procedural cloth
    pattern whose motion is learnable); ``colors``: two (3,) sRGB colours in [0, 1]."""
    colors = np.asarray(((0.9, 0.9, 0.85), (0.15, 0.3, 0.7)) if colors is None else colors)
    if colors.shape != (2, 3) or np.any((colors < 0) | (colors > 1)):
        raise InputError(f"checker_image: colors must be two RGB triples in [0, 1], got "
                         f"{colors.tolist()}")
    nu, nv = (int(s) for s in squares)
    if nu < 1 or nv < 1 or pixels_per_square < 1:
        raise InputError(f"checker_image: squares and pixels_per_square must be ≥ 1, got "
                         f"{squares}, {pixels_per_square}")
    rows = np.arange(nv * pixels_per_square) // pixels_per_square
    cols = np.arange(nu * pixels_per_square) // pixels_per_square
    parity = (rows[:, None] + cols[None, :]) % 2
    return np.round(colors[parity] * 255).astype(np.uint8)


class Deformable(PhysicalObject):
    """A cloth sheet or a soft solid (module doc): a mesh whose vertices the simulator moves.

    Mesh (keyword arguments, fixed after construction): ``vertices`` (V, 3) rest positions in the
    model frame (m), ``faces`` (F, 3) the rendered triangles, ``uv`` (F, 3, 2) or None,
    ``tetrahedra`` (T, 4) for a soft solid (positive, :mod:`kubric.core.tet_meshes`; vertices no
    face uses are interior nodes, simulated and not rendered). ``kind``: ``"cloth"`` (a
    mass-spring sheet: stretch, shear and bending springs) or ``"soft"`` (a NeoHookean solid).
    Physics (properties): ``mass`` (kg, the whole object), ``friction``, ``collision_margin`` (m:
    the engine keeps the mesh this far from colliders); cloth: ``stiffness`` (spring elastic
    stiffness, N/m), ``damping`` (spring damping); soft: ``neo_hookean`` (μ, λ, damping).
    ``static`` is always False.
    """

    simulated_vertices = kt.Property(None, lambda v, o, n: o._convert_vertices(v),
                                     "(V, 3) world positions of the simulated mesh (m); None: "
                                     "the rest mesh placed by the pose", interpolation="linear")
    stiffness = kt.Float(60.0, low=0.0, doc="spring elastic stiffness (N/m)")
    damping = kt.Float(0.1, low=0.0, doc="spring damping stiffness")
    collision_margin = kt.Float(0.02, low=0.0, doc="contact margin of the mesh (m)")
    neo_hookean = kt.Property((180.0, 600.0, 0.01), kt.as_vector(3),
                              "soft solids: NeoHookean (mu, lambda, damping)")
    property_defaults = {"mass": 0.2}

    def __init__(self, *, vertices, faces, uv=None, kind: str = "cloth", tetrahedra=None,
                 **kwargs):
        where = f"Deformable {kwargs.get('name') or 'Deformable'!r}"
        if kind not in KINDS:
            raise InputError(f"{where}: kind {kind!r} is not one of {list(KINDS)}")
        v = _array(where, "vertices", vertices, np.float64, (None, 3))
        if len(v) < 3:
            raise InputError(f"{where}: vertices must hold at least 3 points, got {len(v)}")
        f = _integers(where, "faces", faces, (None, 3), 0, len(v))
        if not len(f):
            raise InputError(f"{where}: faces is empty (a deformable needs a triangle mesh)")
        degenerate = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
        if degenerate.any():
            raise InputError(f"{where}: face {int(np.flatnonzero(degenerate)[0])} repeats a "
                             f"vertex ({f[degenerate][0].tolist()}); faces need 3 distinct ones")
        if uv is not None:
            uv = _array(where, "uv", uv, np.float32, (len(f), 3, 2))
            uv.setflags(write=False)
        self.tetrahedra = self._check_tetrahedra(where, kind, tetrahedra, v)
        self.kind = kind
        self.vertices, self.faces, self.uv = v, f.astype(np.int32), uv
        self.rendered_vertices = np.unique(self.faces)
        for arr in (self.vertices, self.faces, self.rendered_vertices):
            arr.setflags(write=False)
        kwargs.setdefault("bounds", self.rest_bounds)
        super().__init__(**kwargs)
        self._check_static(self.static)

    @classmethod
    def cloth(cls, size=(1.0, 1.0), resolution=(16, 16), **kwargs) -> Deformable:
        """A :func:`cloth_grid` sheet; ``kwargs`` go to the constructor (pose, mass, ...)."""
        vertices, faces, uv = cloth_grid(size, resolution)
        return cls(vertices=vertices, faces=faces, uv=uv, kind="cloth", **kwargs)

    @classmethod
    def soft_box(cls, size=(0.4, 0.4, 0.4), resolution=(3, 3, 3), **kwargs) -> Deformable:
        """A soft solid box (:func:`kubric.core.tet_meshes.box`); ``kwargs`` go to the
        constructor."""
        vertices, tets, faces, uv = tet_meshes.box(size, resolution)
        return cls(vertices=vertices, faces=faces, uv=uv, tetrahedra=tets, kind="soft",
                   **kwargs)

    @classmethod
    def soft_mesh(cls, vertices, faces, uv=None, spacing=None, cells: int = 4,
                  **kwargs) -> Deformable:
        """A soft solid of a closed triangle mesh (model frame, m), tetrahedralised by
        :func:`kubric.core.tetrahedralize.tetrahedralize` (``spacing`` / ``cells``: its interior
        lattice); the mesh's faces (and ``uv`` (F, 3, 2)) are the rendered surface unchanged;
        ``kwargs`` go to the constructor."""
        from kubric.core.tetrahedralize import tetrahedralize
        nodes, tets = tetrahedralize(vertices, faces, spacing=spacing, cells=cells)
        return cls(vertices=nodes, faces=faces, uv=uv, tetrahedra=tets, kind="soft", **kwargs)

    @staticmethod
    def _check_tetrahedra(where, kind, tetrahedra, vertices):
        if kind == "cloth":
            if tetrahedra is not None:
                raise InputError(f"{where}: a cloth has no tetrahedra (give kind='soft')")
            return None
        if tetrahedra is None:
            raise InputError(f"{where}: a soft solid needs tetrahedra (T, 4)")
        t = _integers(where, "tetrahedra", tetrahedra, (None, 4), 0, len(vertices))
        vol = tet_meshes.signed_volumes(vertices, t) if len(t) else np.zeros(1)
        if not len(t) or np.any(vol <= 0):
            bad = int(np.flatnonzero(vol <= 0)[0]) if len(t) else 0
            raise InputError(f"{where}: tetrahedron {bad} is not positive (need "
                             "((b − a) × (c − a)) · (d − a) > 0 for every (a, b, c, d))")
        t = t.astype(np.int32)
        t.setflags(write=False)
        return t

    def _convert_vertices(self, value):
        if value is None:
            return None
        arr = _array(f"Deformable {self.name!r}", "simulated_vertices", value, np.float64,
                     (len(self.vertices), 3))
        arr.setflags(write=False)
        return arr

    def _check_static(self, value) -> None:
        if value:
            raise InputError(f"Deformable {self.name!r}: static must be False (a deformable is "
                             "moved by its simulation)")

    def _on_property_set(self, name, value):
        if name == "static":
            self._check_static(value)
        super()._on_property_set(name, value)

    # ------------------------------------------------------------------ geometry
    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    @property
    def rest_bounds(self) -> np.ndarray:
        """(2, 3) model-frame box of the rendered rest vertices."""
        v = self.vertices[self.rendered_vertices]
        return np.stack([v.min(axis=0), v.max(axis=0)])

    def rest_world_vertices(self, frame=None) -> np.ndarray:
        """(V, 3) the rest mesh placed by the object's pose at ``frame`` (the rest state)."""
        with self.at_frame(frame):
            return sk.to_world(self.vertices, self.position, self.quaternion, self.scale)

    def deformed_vertices(self, frame=None, indices=None, space: str = "world") -> np.ndarray:
        """(V, 3) world vertices at ``frame`` (None: the current values), or only ``indices``:
        the keyed ``simulated_vertices`` (linear between keys), else the placed rest mesh.
        ``space`` must be "world" (a simulated mesh has no model-frame pose)."""
        if space != "world":
            raise InputError(f"Deformable.deformed_vertices: space must be 'world', got {space!r}")
        sel = slice(None) if indices is None else np.asarray(indices)
        with self.at_frame(frame):
            sim = self.simulated_vertices
        if sim is None:
            return self.rest_world_vertices(frame)[sel]
        return np.asarray(sim, np.float64)[sel]

    def surface_points(self, triangles, barycentrics, frame=None, space: str = "world"):
        """(N, 3) points ``Σ bary_i · vertex(faces[tri, i])`` at ``frame`` (world), or on the
        rest mesh in the model frame with ``space="rest"``."""
        if space not in ("world", "rest"):
            raise InputError(f"space must be 'world' or 'rest', got {space!r}")
        tri = np.asarray(triangles, np.int64)
        bary = np.asarray(barycentrics, np.float64)
        if bary.shape != tri.shape + (3,):
            raise InputError(f"barycentrics must have shape {tri.shape + (3,)}, got {bary.shape}")
        if tri.size and (tri.min() < 0 or tri.max() >= len(self.faces)):
            raise InputError(f"triangles must be in [0, {len(self.faces) - 1}]")
        verts = self.vertices if space == "rest" else self.deformed_vertices(frame)
        return np.einsum("ni,nij->nj", bary, verts[self.faces[tri]])

    def aabb(self, frame=None) -> np.ndarray:
        """(2, 3) world box of the rendered vertices at ``frame``."""
        pts = self.deformed_vertices(frame, self.rendered_vertices)
        return np.stack([pts.min(axis=0), pts.max(axis=0)])

    @property
    def aabbox(self) -> np.ndarray:
        return self.aabb()

    @property
    def bbox_3d(self) -> np.ndarray:
        """(8, 3) corners of the world axis-aligned box of the current mesh (corner order as
        :attr:`PhysicalObject.bbox_3d`)."""
        import itertools
        b = self.aabb()
        return np.array(list(itertools.product(b[:, 0], b[:, 1], b[:, 2])))

    def centroid_motion(self, frames, frame_rate: float):
        """((T, 3) centroids, (T, 3) velocities) of the simulated nodes (the unweighted mean of
        all vertices, world, m) at ``frames``; velocity (m/s) is the central difference of the
        centroid over ±1 frame (one-sided at the ends of the keyed range, where the vertices
        hold), × ``frame_rate``. Unkeyed: the pose's placed rest mesh, velocity 0."""
        keys = sorted(self.keyframes.get("simulated_vertices", {}))
        lo, hi = (keys[0], keys[-1]) if keys else (0, 0)

        def centroid(frame):
            return self.deformed_vertices(frame).mean(axis=0)

        positions, velocities = [], []
        for f in frames:
            a, b = max(f - 1, lo), min(f + 1, hi)
            positions.append(centroid(f))
            velocities.append((centroid(b) - centroid(a)) * frame_rate / (b - a) if b > a
                              else np.zeros(3))
        return np.asarray(positions), np.asarray(velocities)

    def record(self, frame: int, vertices) -> None:
        """Set ``simulated_vertices`` to ``vertices`` (V, 3) world and key them at ``frame``."""
        self.simulated_vertices = vertices
        self.keyframe_insert("simulated_vertices", frame)


#: the assets whose surface deforms (a track on them follows a material point of the mesh)
DEFORMING = (Character, Deformable)
