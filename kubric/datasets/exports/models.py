"""Object models for the BOP export: meshes from asset sources, scaled and centred, written as PLY
in millimetres, their ``models_info.json`` entry, and silhouettes rasterised from them.

Mesh frame: an asset's ``render_filename`` in metres, times the object's scale, in the frame the
renderer imports it into: OBJ, PLY and STL without axis conversion (file x, y, z = the object's
local x, y, z); glTF / GLB from glTF's y-up axes as Blender's importer converts them (local
(x, y, z) = glTF (x, −z, y)). The
model's origin is moved to the centre of its 3D bounding box (BOP's convention); the export adds
that shift to ``cam_t_m2c`` so the pose still places the model where the object was.
"""

from __future__ import annotations

import dataclasses
import pathlib

import numpy as np

from kubric.core.imports import uninterrupted_import
from kubric.datasets.exports.scenes import ExportError

#: the renderer's default importer axes for these formats (= no conversion)
IDENTITY_AXES = {"forward_axis": "Y", "up_axis": "Z"}
MESH_FORMATS = (".obj", ".ply", ".stl", ".glb", ".gltf")
GLTF_FORMATS = (".glb", ".gltf")
#: glTF (y up) → our local frame (z up), as Blender's glTF importer converts
GLTF_TO_LOCAL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


@dataclasses.dataclass
class Model:
    vertices: np.ndarray   # (V, 3) float64 millimetres, origin at the bounding-box centre
    faces: np.ndarray      # (F, 3) int64
    normals: np.ndarray    # (V, 3) unit vertex normals
    centre: np.ndarray     # (3,) the removed offset, mm, in the scaled asset frame

    def info(self) -> dict:
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        size = hi - lo
        return {"diameter": diameter(self.vertices), "min_x": float(lo[0]),
                "min_y": float(lo[1]), "min_z": float(lo[2]), "size_x": float(size[0]),
                "size_y": float(size[1]), "size_z": float(size[2])}


def find_asset(sources, asset_id: str):
    for source in sources:
        if asset_id in source:
            return source
    names = ", ".join(s.name for s in sources) or "none"
    raise ExportError(f"asset {asset_id!r} is in none of the asset sources searched ({names}); "
                      "name the one the scenes used with --source")


def load_mesh(source, asset_id: str):
    """(vertices (V, 3) metres, faces (F, 3)) of the asset's render mesh, in its local frame."""
    trimesh = uninterrupted_import("trimesh")  # trimesh swallows a Ctrl-C in its import
    entry = source.db[asset_id]
    if entry.get("asset_type") != "FileBasedObject":
        raise ExportError(f"asset {asset_id!r} of {source.name!r} is not a mesh object")
    kwargs = source.get_asset_kwargs(asset_id)
    path = pathlib.Path(str(kwargs.get("render_filename") or ""))
    if path.suffix.lower() not in MESH_FORMATS:
        raise ExportError(f"asset {asset_id!r}: render mesh {path.name!r} is not one of "
                          f"{MESH_FORMATS} (the BOP export reads those)")
    axes = dict(kwargs.get("render_import_kwargs") or {})
    gltf = path.suffix.lower() in GLTF_FORMATS
    if (gltf and axes) or any(axes.get(k, v) != v for k, v in IDENTITY_AXES.items()) \
            or set(axes) - set(IDENTITY_AXES):
        raise ExportError(f"asset {asset_id!r}: render_import_kwargs {axes} change the "
                          "importer's axes; the BOP export reads meshes imported with the "
                          "defaults only")
    mesh = trimesh.load(path, force="mesh", process=False)
    if not len(mesh.faces):
        raise ExportError(f"asset {asset_id!r}: {path.name!r} holds no triangles")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if gltf:
        vertices = vertices @ GLTF_TO_LOCAL.T
    return vertices, np.asarray(mesh.faces, dtype=np.int64)


def make_model(vertices_m: np.ndarray, faces: np.ndarray, scale) -> Model:
    """The scaled mesh in millimetres, centred on its bounding box."""
    trimesh = uninterrupted_import("trimesh")  # trimesh swallows a Ctrl-C in its import
    v = np.asarray(vertices_m, dtype=np.float64) * np.asarray(scale, dtype=np.float64) * 1000.0
    centre = (v.min(axis=0) + v.max(axis=0)) / 2
    v = v - centre
    mesh = trimesh.Trimesh(v, faces, process=False)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    return Model(v, np.asarray(faces, dtype=np.int64), normals, centre)


def diameter(vertices: np.ndarray) -> float:
    """The largest distance between two vertices (attained on the convex hull's vertices)."""
    pts = np.asarray(vertices, dtype=np.float64)
    try:
        from scipy.spatial import ConvexHull
        pts = pts[ConvexHull(pts).vertices]
    except Exception:  # flat or degenerate point sets: all points (qhull needs a 3-D hull)
        pts = np.unique(pts, axis=0)
    best = 0.0
    for start in range(0, len(pts), 512):
        d = np.linalg.norm(pts[start:start + 512, None, :] - pts[None, :, :], axis=-1)
        best = max(best, float(d.max()))
    return best


def ply_bytes(model: Model) -> bytes:
    """Binary little-endian PLY: float x y z nx ny nz per vertex, uchar-counted int faces."""
    n, f = len(model.vertices), len(model.faces)
    header = ("ply\nformat binary_little_endian 1.0\ncomment kubric BOP export, millimetres\n"
              f"element vertex {n}\n" + "".join(f"property float {c}\n" for c in
                                                ("x", "y", "z", "nx", "ny", "nz"))
              + f"element face {f}\nproperty list uchar int vertex_indices\nend_header\n")
    verts = np.empty(n, dtype=[(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")])
    for k, c in enumerate("xyz"):
        verts[c] = model.vertices[:, k]
        verts["n" + c] = model.normals[:, k]
    faces = np.empty(f, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = model.faces
    return header.encode("ascii") + verts.tobytes() + faces.tobytes()


def _edge(p, q, px, py):
    """Twice the signed area of (p, q, pixel centre): its sign says which side of p→q it is."""
    return (q[:, 0] - p[:, 0]) * (py - p[:, 1]) - (q[:, 1] - p[:, 1]) * (px - p[:, 0])


def rasterise(points_px: np.ndarray, faces: np.ndarray, height: int, width: int,
              budget: int = 1 << 22) -> np.ndarray:
    """(H, W) bool: pixels whose centre lies inside a projected triangle (edges included).

    ``points_px``: (V, 2) image positions (x, y) with pixel (row r, col c) centred at (c, r).
    """
    tri = np.asarray(points_px, dtype=np.float64)[faces]            # (F, 3, 2)
    lo = np.ceil(tri.min(axis=1)).astype(np.int64)
    hi = np.floor(tri.max(axis=1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    keep = np.all(hi >= lo, axis=1)
    tri, lo, hi = tri[keep], lo[keep], hi[keep]
    bw = hi[:, 0] - lo[:, 0] + 1
    counts = bw * (hi[:, 1] - lo[:, 1] + 1)
    mask = np.zeros((height, width), dtype=bool)
    start = 0
    while start < len(tri):
        stop = start + max(1, int(np.searchsorted(np.cumsum(counts[start:]), budget)))
        idx = np.repeat(np.arange(start, stop), counts[start:stop])
        first = np.repeat(np.cumsum(counts[start:stop]) - counts[start:stop], counts[start:stop])
        offset = np.arange(len(idx)) - first
        px = lo[idx, 0] + offset % bw[idx]
        py = lo[idx, 1] + offset // bw[idx]
        a, b, c = tri[idx, 0], tri[idx, 1], tri[idx, 2]

        e0, e1, e2 = (_edge(a, b, px, py), _edge(b, c, px, py), _edge(c, a, px, py))
        inside = ((e0 >= 0) & (e1 >= 0) & (e2 >= 0)) | ((e0 <= 0) & (e1 <= 0) & (e2 <= 0))
        area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        inside &= area != 0
        mask[py[inside], px[inside]] = True
        start = stop
    return mask


__all__ = ["Model", "diameter", "find_asset", "load_mesh", "make_model", "ply_bytes",
           "rasterise"]
