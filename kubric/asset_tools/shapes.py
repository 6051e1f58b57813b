"""Procedural meshes of the KuBasic shapes at their design size (trimesh, z up, cube bounds ±1).

The KuBasic source is unit-sized: :func:`kubric.asset_tools.kubasic.build_shape` scales these meshes by
``SHAPE_SCALE`` = 0.5, so every built shape fits a 1 m cube. The dome is built at its own size.

Every function returns a ``trimesh.Trimesh`` built by our own code from formulas (or, for
``suzanne``, Blender's built-in monkey; for ``teapot``, Newell's Bezier patches; for ``spot``, the
Stanford bunny that ships with ``pybullet_data``). Meshes are not yet centred on their centre of
mass; :func:`kubric.asset_tools.writer.package_object` does that.
"""

from __future__ import annotations

import math

import numpy as np

from kubric.asset_tools.teapot_data import PATCHES, POINTS


def _trimesh():
    import trimesh
    return trimesh


def cube():
    """Edge 2 (bounds ±1)."""
    return _trimesh().creation.box(extents=(2.0, 2.0, 2.0))


def sphere():
    """Radius 1, icosphere with 1280 faces."""
    return _trimesh().creation.icosphere(subdivisions=3, radius=1.0)


def cylinder():
    """Radius 1, height 2, axis z, 64 sections."""
    return _trimesh().creation.cylinder(radius=1.0, height=2.0, sections=64)


def cone():
    """Base radius 1 at z = -1, apex at z = +1, 64 sections."""
    mesh = _trimesh().creation.cone(radius=1.0, height=2.0, sections=64)
    mesh.apply_translation((0.0, 0.0, -1.0))
    return mesh


def torus():
    """Ring radius 0.7, tube radius 0.3 (bounds ±1 in x, y; ±0.3 in z)."""
    return tube_along(lambda t: np.stack([0.7 * np.cos(t), 0.7 * np.sin(t),
                                          np.zeros_like(t)], axis=-1),
                      radius=0.3, n_path=96, n_ring=32)


def torus_knot(p: int = 2, q: int = 3):
    """A (p, q) torus knot tube, scaled to fit in ±1."""
    def curve(t):
        r = 0.6 + 0.3 * np.cos(q * t)
        return np.stack([r * np.cos(p * t), r * np.sin(p * t), 0.3 * np.sin(q * t)], axis=-1)
    mesh = tube_along(curve, radius=0.12, n_path=256, n_ring=16)
    mesh.apply_scale(1.0 / np.abs(mesh.vertices).max())
    return mesh


def tube_along(curve, radius: float, n_path: int, n_ring: int):
    """Closed tube of ``radius`` around the closed curve ``curve(t)``, t ∈ [0, 2π) (watertight).

    Frames are parallel-transported along the curve and the leftover twist is spread evenly, so
    the tube closes without a seam.
    """
    trimesh = _trimesh()
    t = np.linspace(0.0, 2.0 * np.pi, n_path, endpoint=False)
    pts = curve(t)
    tangents = np.roll(pts, -1, axis=0) - np.roll(pts, 1, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normals = np.zeros_like(pts)
    ref = np.array([0.0, 0.0, 1.0]) if abs(tangents[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    n = np.cross(tangents[0], ref)
    n /= np.linalg.norm(n)
    for i in range(n_path):
        n = n - np.dot(n, tangents[i]) * tangents[i]
        n /= np.linalg.norm(n)
        normals[i] = n
    # twist needed to close the loop: angle between the transported and the initial normal
    n_end = normals[-1] - np.dot(normals[-1], tangents[0]) * tangents[0]
    n_end /= np.linalg.norm(n_end)
    twist = math.atan2(np.dot(np.cross(n_end, normals[0]), tangents[0]),
                       np.dot(n_end, normals[0]))
    verts = []
    for i in range(n_path):
        b = np.cross(tangents[i], normals[i])
        a0 = twist * i / n_path
        ang = a0 + np.linspace(0.0, 2.0 * np.pi, n_ring, endpoint=False)
        ring = (np.cos(ang)[:, None] * normals[i] + np.sin(ang)[:, None] * b) * radius
        verts.append(pts[i] + ring)
    verts = np.concatenate(verts)
    faces = []
    for i in range(n_path):
        i2 = (i + 1) % n_path
        for j in range(n_ring):
            j2 = (j + 1) % n_ring
            a, b_, c, d = i * n_ring + j, i * n_ring + j2, i2 * n_ring + j2, i2 * n_ring + j
            faces += [(a, d, c), (a, c, b_)]
    mesh = trimesh.Trimesh(verts, np.array(faces), process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def gear(teeth: int = 12, r_tip: float = 1.0, r_root: float = 0.8, r_hole: float = 0.3,
         thickness: float = 0.4):
    """Spur gear with trapezoidal teeth and a round hole along z (watertight)."""
    trimesh = _trimesh()
    per_tooth = 8
    n = teeth * per_tooth
    ang = np.arange(n) * 2.0 * np.pi / n
    # radius profile over one tooth: root, rising flank, tip, falling flank
    prof = np.array([r_root, r_root, r_root + 0.5 * (r_tip - r_root), r_tip, r_tip,
                     r_root + 0.5 * (r_tip - r_root), r_root, r_root])
    r_out = np.tile(prof, teeth)
    outer = np.stack([r_out * np.cos(ang), r_out * np.sin(ang)], axis=1)
    inner = np.stack([r_hole * np.cos(ang), r_hole * np.sin(ang)], axis=1)
    h = thickness / 2.0
    # vertex blocks: outer top, outer bottom, inner top, inner bottom
    v = np.concatenate([np.c_[outer, np.full(n, h)], np.c_[outer, np.full(n, -h)],
                        np.c_[inner, np.full(n, h)], np.c_[inner, np.full(n, -h)]])
    ot, ob, it, ib = 0, n, 2 * n, 3 * n
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(ot + i, ot + j, it + j), (ot + i, it + j, it + i)]   # top annulus (+z)
        faces += [(ob + i, ib + j, ob + j), (ob + i, ib + i, ib + j)]   # bottom annulus (-z)
        faces += [(ob + i, ob + j, ot + j), (ob + i, ot + j, ot + i)]   # outer wall
        faces += [(ib + i, it + j, ib + j), (ib + i, it + i, it + j)]   # hole wall
    mesh = trimesh.Trimesh(v, np.array(faces), process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def sponge(level: int = 2):
    """Menger sponge of ``level`` (edge 2, bounds ±1): the boundary faces of its voxel grid."""
    trimesh = _trimesh()
    size = 3 ** level
    idx = np.indices((size, size, size)).reshape(3, -1).T
    filled = np.ones(len(idx), dtype=bool)
    for k in range(level):
        digits = (idx // 3 ** k) % 3
        filled &= (digits == 1).sum(axis=1) < 2
    occ = filled.reshape(size, size, size)
    padded = np.pad(occ, 1)
    faces, verts, vindex = [], [], {}

    def vid(p):
        key = tuple(int(c) for c in p)
        if key not in vindex:
            vindex[key] = len(verts)
            verts.append(key)
        return vindex[key]

    for axis in range(3):
        for sign in (-1, 1):
            shift = np.roll(padded, -sign, axis=axis)[1:-1, 1:-1, 1:-1]
            exposed = occ & ~shift
            u, w = [a for a in range(3) if a != axis]
            for cell in np.argwhere(exposed):
                base = cell.copy()
                if sign > 0:
                    base[axis] += 1
                corners = []
                for du, dw in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    c = base.copy()
                    c[u] += du
                    c[w] += dw
                    corners.append(vid(c))
                a, b, c, d = corners
                # (u, w) counter-clockwise gives +axis for x and z and -axis for y (u < w)
                if sign * (1 if axis != 1 else -1) > 0:
                    faces += [(a, b, c), (a, c, d)]
                else:
                    faces += [(a, c, b), (a, d, c)]
    v = np.asarray(verts, dtype=np.float64) * (2.0 / size) - 1.0
    return trimesh.Trimesh(v, np.array(faces), process=True)


def teapot(n: int = 10):
    """Newell's Utah teapot: 32 Bezier patches at n×n quads each, scaled to max |coordinate| 1."""
    trimesh = _trimesh()
    pts = np.asarray(POINTS, dtype=np.float64)
    s = np.linspace(0.0, 1.0, n + 1)
    bern = np.stack([(1 - s) ** 3, 3 * s * (1 - s) ** 2, 3 * s ** 2 * (1 - s), s ** 3], axis=1)
    verts, faces = [], []
    for patch in PATCHES:
        ctrl = pts[np.asarray(patch) - 1].reshape(4, 4, 3)
        grid = np.einsum("ui,vj,ijc->uvc", bern, bern, ctrl).reshape(-1, 3)
        off = len(verts) * (n + 1) ** 2
        verts.append(grid)
        for i in range(n):
            for j in range(n):
                a = off + i * (n + 1) + j
                b, c, d = a + 1, a + n + 2, a + n + 1
                faces += [(a, d, c), (a, c, b)]
    mesh = trimesh.Trimesh(np.concatenate(verts), np.array(faces), process=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    mesh.fix_normals()
    if mesh.volume < 0:  # open surface: make the (approximate) signed volume positive = outward
        mesh.invert()
    mesh.apply_translation(-(mesh.bounds[0] + mesh.bounds[1]) / 2.0)
    mesh.apply_scale(1.0 / np.abs(mesh.vertices).max())
    return mesh


_SUZANNE_SCRIPT = """
import json
import bpy  # first: it puts Blender's modules (bmesh) on the path
import bmesh
bm = bmesh.new()
bmesh.ops.create_monkey(bm)
bmesh.ops.triangulate(bm, faces=bm.faces[:])
print(json.dumps({"v": [list(v.co) for v in bm.verts],
                  "f": [[v.index for v in f.verts] for f in bm.faces]}))
"""


def suzanne():
    """Blender's monkey (``bmesh.ops.create_monkey``; faces −y as in Blender), max |coordinate| 1.

    Generated by bpy in a fresh subprocess: a process that has already imported bpy (or a
    worker spawned from one) would otherwise see Blender's internal ``bpy`` package first.
    """
    import json
    import subprocess
    import sys

    trimesh = _trimesh()
    proc = subprocess.run([sys.executable, "-P", "-c", _SUZANNE_SCRIPT], capture_output=True,
                          text=True, check=False, timeout=300)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"generating suzanne with bpy failed (exit {proc.returncode}): "
                           f"{proc.stderr[-500:]}")
    data = json.loads(lines[-1])
    v = np.asarray(data["v"], dtype=np.float64)
    v /= np.abs(v).max()
    return trimesh.Trimesh(v, np.asarray(data["f"], dtype=np.int64), process=True)


def spot():
    """Stand-in for upstream's cow: the Stanford bunny from ``pybullet_data``, max extent 2, z up."""
    import pybullet_data
    trimesh = _trimesh()
    mesh = trimesh.load(f"{pybullet_data.getDataPath()}/bunny.obj", force="mesh", process=True)
    # the scan is y up: rotate +90° about x so that it stands on the xy plane
    mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    mesh.apply_translation(-(mesh.bounds[0] + mesh.bounds[1]) / 2.0)
    mesh.apply_scale(2.0 / (mesh.bounds[1] - mesh.bounds[0]).max())
    return mesh


SPOT_LICENSE = ("Stanford Bunny, Stanford 3D Scanning Repository (Stanford Computer Graphics "
                "Laboratory), as redistributed in pybullet_data (package licence zlib); free to use "
                "and redistribute with acknowledgement. Stand-in for upstream's 'spot' cow.")


def dome(floor_radius: float = 25.0, fillet: float = 15.0, height: float = 40.0,
         n_around: int = 64, n_fillet: int = 12):
    """Floor + backdrop bowl: a flat disc that bends up (quarter circle) into a vertical wall.

    Radius ``floor_radius + fillet`` (40 m), ``height`` tall, open at the top; normals face inward
    (up on the floor). UVs: u = angle / 2π, v = arc length / total profile length.
    """
    trimesh = _trimesh()
    prof = [(0.0, 0.0)]
    prof += [(floor_radius * k / 8.0, 0.0) for k in range(1, 9)]
    for k in range(1, n_fillet + 1):
        a = 0.5 * np.pi * k / n_fillet
        prof.append((floor_radius + fillet * np.sin(a), fillet * (1.0 - np.cos(a))))
    top = floor_radius + fillet
    prof += [(top, fillet + (height - fillet) * k / 4.0) for k in range(1, 5)]
    prof = np.asarray(prof)
    seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(prof, axis=0), axis=1))]
    v_coord = seg / seg[-1]
    verts, uvs, faces = [], [], []
    cols = n_around + 1  # duplicate seam column for continuous UVs
    for i, (r, z) in enumerate(prof):
        for j in range(cols):
            a = 2.0 * np.pi * j / n_around
            verts.append((r * np.cos(a), r * np.sin(a), z))
            uvs.append((j / n_around, v_coord[i]))
    for i in range(len(prof) - 1):
        for j in range(n_around):
            a, b = i * cols + j, i * cols + j + 1
            c, d = a + cols, b + cols
            faces += [(a, d, b), (a, c, d)]  # normals up / inward
    visual = trimesh.visual.TextureVisuals(uv=np.asarray(uvs))
    mesh = trimesh.Trimesh(np.asarray(verts), np.asarray(faces), visual=visual, process=False)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    return mesh
