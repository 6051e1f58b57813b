"""The meshes the raycast backend casts rays into, each in its object's unscaled local frame.

``Cube`` and ``Sphere`` are rebuilt exactly as the Blender backend builds them (cube:
±1, Blender's cube UVs, flat; sphere: 128 × 64 UV sphere, smooth, Blender's UVs); a
``FileBasedObject``'s ``render_filename`` is read with trimesh (OBJ, PLY, STL as they are; glTF /
GLB converted from y-up to z-up as Blender's importer does); files without vertex normals (OBJ
``vn``, PLY ``nx ny nz``, glTF ``NORMAL``) are flat shaded, with them smooth with the file's
normals (Blender's importers' rule; STL is always flat).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from kubric.core.color import srgb_to_linear
from kubric.core.imports import uninterrupted_import

trimesh = uninterrupted_import("trimesh")  # trimesh swallows a Ctrl-C in its import

_SPHERE_SEGMENTS, _SPHERE_RINGS = 128, 64  # as kubric.renderer.blender_objects
#: glTF's y-up → Blender's z-up: (x, y, z) → (x, −z, y)
_GLTF_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
MESH_FORMATS = (".obj", ".glb", ".gltf", ".ply", ".stl")
GREY = (0.8, 0.8, 0.8)  # base colour of a mesh whose file gives none


@dataclass
class Mesh:
    """One object's geometry in its unscaled local frame (triangles)."""
    vertices: np.ndarray            # (V, 3) float64
    faces: np.ndarray               # (F, 3) int64
    normals: np.ndarray | None      # (V, 3) vertex normals of a smooth mesh; None = flat
    corner_uv: np.ndarray | None    # (F, 3, 2) texture coordinates per triangle corner
    texture: np.ndarray | None = None  # (h, w, 3) linear base-colour image (file materials)
    color: tuple = GREY             # linear base colour when there is no texture


# ---------------------------------------------------------------------------------- geometry
def _quads_to_triangles(quads):
    """Blender's fixed quad split: corners (0, 1, 2) and (0, 2, 3)."""
    q = np.asarray(quads)
    return np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])


def cube_mesh() -> Mesh:
    """The Blender backend's cube: vertices ±1, Blender's default cube UVs, flat."""
    corners = [(-1, -1, -1), (-1, -1, 1), (-1, 1, 1), (-1, 1, -1), (1, 1, -1), (1, 1, 1),
               (1, -1, 1), (1, -1, -1)]
    quads = [(0, 1, 2, 3), (3, 2, 5, 4), (4, 5, 6, 7), (7, 6, 1, 0), (3, 4, 7, 0), (5, 2, 1, 6)]
    uvs = [[(.375, 0), (.625, 0), (.625, .25), (.375, .25)],
           [(.375, .25), (.625, .25), (.625, .5), (.375, .5)],
           [(.375, .5), (.625, .5), (.625, .75), (.375, .75)],
           [(.375, .75), (.625, .75), (.625, 1), (.375, 1)],
           [(.125, .5), (.375, .5), (.375, .75), (.125, .75)],
           [(.625, .5), (.875, .5), (.875, .75), (.625, .75)]]
    corner_ids = np.arange(24).reshape(6, 4)
    tri = _quads_to_triangles(corner_ids)
    quad_vertices = np.asarray(quads).reshape(-1)
    return Mesh(np.asarray(corners, np.float64), quad_vertices[tri], None,
                np.asarray(uvs, np.float64).reshape(24, 2)[tri])


def sphere_mesh(segments: int = _SPHERE_SEGMENTS, rings: int = _SPHERE_RINGS) -> Mesh:
    """The Blender backend's UV sphere (radius 1): ring i at polar angle π·i/rings, segment j at
    azimuth 2π·j/segments − π; UV u = j / segments, v = 1 − i / rings (pole corners at the
    segment's middle u); smooth, with angle-weighted vertex normals."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments - np.pi
    ring = np.stack([np.sin(theta)[:, None] * np.cos(phi), np.sin(theta)[:, None] * np.sin(phi),
                     np.broadcast_to(np.cos(theta)[:, None], (rings - 1, segments))], axis=-1)
    vertices = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    bottom = len(vertices) - 1

    def vid(i, j):  # ring i in 1 .. rings−1, segment j (wraps)
        return 1 + (i - 1) * segments + j % segments

    faces, uvs = [], []
    j = np.arange(segments)
    u0, u1, um = j / segments, (j + 1) / segments, (j + 0.5) / segments
    for i in range(rings):
        v0, v1 = 1 - i / rings, 1 - (i + 1) / rings
        if i == 0:
            faces.append(np.stack([np.zeros_like(j), vid(1, j), vid(1, j + 1)], -1))
            uvs.append(np.stack([np.stack([um, np.full_like(um, v0)], -1),
                                 np.stack([u0, np.full_like(u0, v1)], -1),
                                 np.stack([u1, np.full_like(u1, v1)], -1)], 1))
        elif i == rings - 1:
            faces.append(np.stack([vid(i, j), np.full_like(j, bottom), vid(i, j + 1)], -1))
            uvs.append(np.stack([np.stack([u0, np.full_like(u0, v0)], -1),
                                 np.stack([um, np.full_like(um, v1)], -1),
                                 np.stack([u1, np.full_like(u1, v0)], -1)], 1))
        else:
            quads = np.stack([vid(i, j), vid(i + 1, j), vid(i + 1, j + 1), vid(i, j + 1)], -1)
            quv = np.stack([np.stack([u0, np.full_like(u0, v0)], -1),
                            np.stack([u0, np.full_like(u0, v1)], -1),
                            np.stack([u1, np.full_like(u1, v1)], -1),
                            np.stack([u1, np.full_like(u1, v0)], -1)], 1)
            faces.append(_quads_to_triangles(quads))
            uvs.append(np.concatenate([quv[:, [0, 1, 2]], quv[:, [0, 2, 3]]]))
    faces = np.concatenate(faces)
    uv = np.concatenate(uvs)
    tri = vertices[faces]
    outward = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]),
                        tri.mean(axis=1)) > 0
    faces = np.where(outward[:, None], faces, faces[:, ::-1])
    uv = np.where(outward[:, None, None], uv, uv[:, ::-1])
    normals = trimesh.Trimesh(vertices, faces, process=False).vertex_normals
    return Mesh(vertices, faces, np.asarray(normals, np.float64), uv)


def _file_has_normals(path: str, ext: str, loaded) -> bool:
    if ext == ".obj":
        with open(path, encoding="utf-8", errors="replace") as f:
            return any(line.startswith("vn ") for line in f)
    # glTF NORMAL / PLY nx ny nz: trimesh's loaders hand the file's normals to the mesh, which
    # caches them; without them (and for STL) Blender's importers shade flat
    return ext != ".stl" and "vertex_normals" in loaded._cache


def _axis(name: str) -> np.ndarray:
    vec = np.zeros(3)
    vec["XYZ".index(name[-1])] = -1.0 if name.startswith("NEGATIVE_") else 1.0
    return vec


def _import_axes(asset, ext) -> np.ndarray:
    """(3, 3) file → local frame rotation: glTF's y-up → z-up; OBJ / PLY / STL by their
    ``render_import_kwargs`` ``forward_axis`` / ``up_axis`` (Blender's importer options: the
    file's forward axis becomes +y, its up axis +z; default Y / Z, unchanged)."""
    kwargs = dict(asset.render_import_kwargs)
    allowed = {"forward_axis", "up_axis"} if ext in (".obj", ".ply", ".stl") else set()
    names = ("X", "Y", "Z", "NEGATIVE_X", "NEGATIVE_Y", "NEGATIVE_Z")
    bad = sorted(set(kwargs) - allowed)
    if bad or any(v not in names for v in kwargs.values()):
        raise ValueError(f"{asset.uid}: the raycast renderer reads render_import_kwargs "
                         f"{sorted(allowed) or 'none'} for {ext} files (values {list(names)}), "
                         f"got {kwargs}")
    if ext in (".glb", ".gltf"):
        return _GLTF_TO_Z_UP
    forward, up = _axis(kwargs.get("forward_axis", "Y")), _axis(kwargs.get("up_axis", "Z"))
    if abs(forward @ up) > 0:
        raise ValueError(f"{asset.uid}: render_import_kwargs forward_axis and up_axis must be "
                         f"different axes, got {kwargs}")
    return np.stack([np.cross(forward, up), forward, up])


def file_mesh(asset) -> Mesh:
    """The geometry of a FileBasedObject's ``render_filename`` (see module doc)."""
    path = asset.render_filename
    if not path:
        raise ValueError(f"{asset.uid}: FileBasedObject.render_filename is not set; the raycast "
                         f"renderer needs a mesh file ({', '.join(MESH_FORMATS)})")
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_FORMATS:
        raise ValueError(f"{asset.uid}: the raycast renderer cannot read render_filename {path!r}: "
                         f"extension {ext!r} is not one of {list(MESH_FORMATS)}")
    axes = _import_axes(asset, ext)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{asset.uid}: render_filename {path!r} does not exist")
    loaded = trimesh.load(path, force="mesh", process=False)
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError(f"{asset.uid}: {path!r} contains no triangle mesh")
    vertices = np.asarray(loaded.vertices, np.float64)
    normals = np.asarray(loaded.vertex_normals, np.float64) \
        if _file_has_normals(path, ext, loaded) else None
    vertices = vertices @ axes.T
    normals = None if normals is None else normals @ axes.T
    faces = np.asarray(loaded.faces, np.int64)
    visual = loaded.visual
    uv = getattr(visual, "uv", None)
    corner_uv = np.asarray(uv, np.float64)[faces] if uv is not None and len(uv) == len(
        vertices) else None
    texture, color = _file_appearance(visual)
    return Mesh(vertices, faces, normals, corner_uv, texture if corner_uv is not None else None,
                color)


def _file_appearance(visual):
    """(linear texture image × base colour factor or None, linear base colour) of a trimesh
    visual."""
    material = getattr(visual, "material", None)
    image = getattr(material, "baseColorTexture", None) or getattr(material, "image", None)
    factor = getattr(material, "baseColorFactor", None)
    color = GREY if factor is None else tuple(srgb_to_linear(np.asarray(factor[:3]) / 255.0))
    if image is not None:  # the factor multiplies the texture, as in glTF and Blender
        pixels = np.asarray(image.convert("RGB"), np.float64) / 255.0
        return srgb_to_linear(pixels) * (1.0 if factor is None else np.asarray(color)), color
    return None, color
