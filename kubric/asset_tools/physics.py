"""Physical properties and collision geometry of meshes (trimesh; PyBullet's V-HACD).

Units: metres, density 1 (so mass = volume in m³ and inertia is in kg·m² with the same numbers).
All functions take and return ``trimesh.Trimesh`` objects in the object's local frame (z up).

Convex decomposition: a mesh whose connected components are all convex (e.g. a model that is
itself a set of hulls, like pybullet_data's ``random_urdfs``) is used as its own decomposition;
anything else goes through PyBullet's V-HACD, which runs in a **separate process** (it segfaults on
some inputs and prints megabytes of log to stdout), fed with an OBJ that trimesh has rewritten.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from kubric.errors import InputError

#: V-HACD settings used for every non-convex mesh (pybullet.vhacd keyword arguments); see
#: benchmarks/bench_assets.py for the speed / tightness trade-off that chose them.
VHACD_PARAMS = {"resolution": 200000, "depth": 16, "concavity": 0.001,
                "maxNumVerticesPerCH": 64}
#: CoACD concavity threshold (optional method). On the 12 non-convex test meshes `make bench`
#: measured Σ hull / mesh volume 1.02 (median) vs V-HACD's 1.23, at 0.5x-90x V-HACD's time
#: (median 6x; 127 s for pybullet_data's lego brick): V-HACD stays the default.
COACD_THRESHOLD = 0.05
DECOMPOSITION_METHODS = ("auto", "vhacd", "coacd")
#: a component counts as convex when its volume is within this fraction of its hull's.
CONVEX_TOLERANCE = 0.01
_VHACD_TIMEOUT_S = 300


def mass_properties(parts) -> dict:
    """Volume, centre of mass and inertia (about the centre of mass) of closed meshes, density 1.

    ``parts`` is one mesh or a list of closed meshes whose properties add up (e.g. convex hulls).
    Returns ``{"volume": float, "center_mass": (3,), "inertia": (3, 3)}``.
    """
    if not isinstance(parts, (list, tuple)):
        parts = [parts]
    vols, coms, inertias = [], [], []
    for part in parts:
        props = part.mass_properties
        vols.append(float(props["volume"]))
        coms.append(np.asarray(props["center_mass"], dtype=np.float64))
        inertias.append(np.asarray(props["inertia"], dtype=np.float64))
    total = float(sum(vols))
    if not total > 0.0:
        raise InputError(f"mesh volume must be positive, got {total!r} (open or inverted mesh)")
    com = sum(v * c for v, c in zip(vols, coms, strict=True)) / total
    inertia = np.zeros((3, 3))
    for v, c, i in zip(vols, coms, inertias, strict=True):
        d = c - com
        inertia += i + v * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return {"volume": total, "center_mass": com, "inertia": inertia}


def convex_parts_if_any(mesh):
    """The mesh's connected components if each is closed and convex, else ``None``."""
    parts = mesh.split(only_watertight=False)
    if not parts:
        return None
    for part in parts:
        if not part.is_watertight or part.volume <= 0:
            return None
        hull_volume = part.convex_hull.volume
        if hull_volume <= 0 or abs(part.volume - hull_volume) > CONVEX_TOLERANCE * hull_volume:
            return None
    return [p.convex_hull for p in parts]


def read_obj_parts(path: str | os.PathLike):
    """Read a multi-object OBJ (``o`` per hull, global 1-based indices) → list of hull meshes."""
    import trimesh

    verts, groups, current = [], [], None
    for line in Path(path).read_text().splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "o":
            current = []
            groups.append(current)
        elif tok[0] == "v":
            verts.append([float(x) for x in tok[1:4]])
        elif tok[0] == "f":
            if current is None:
                current = []
                groups.append(current)
            current.append([int(x.split("/")[0]) - 1 for x in tok[1:4]])
    verts = np.asarray(verts, dtype=np.float64)
    hulls = []
    for faces in groups:
        if not faces:
            continue
        idx = np.unique(np.asarray(faces).reshape(-1))
        pts = verts[idx]
        if len(pts) >= 4:
            try:
                hull = trimesh.Trimesh(pts).convex_hull
            except Exception:  # noqa: BLE001 - degenerate (flat) hull: skip it
                continue
            if hull.volume > 0:
                hulls.append(hull)
    return hulls


def vhacd(mesh, params: dict | None = None) -> list:
    """Approximate convex decomposition of ``mesh`` with PyBullet's V-HACD (in a subprocess).

    Returns a non-empty list of convex hull meshes; raises ``RuntimeError`` if V-HACD crashes,
    times out or produces nothing.
    """
    params = dict(VHACD_PARAMS if params is None else params)
    with tempfile.TemporaryDirectory(prefix="kubric_vhacd_") as tmp:
        src, out, log = (os.path.join(tmp, n) for n in ("in.obj", "out.obj", "log.txt"))
        mesh.export(src, file_type="obj", include_normals=False, include_texture=False)
        code = ("import sys, pybullet; pybullet.vhacd(sys.argv[1], sys.argv[2], sys.argv[3], "
                f"**{params!r})")
        try:
            proc = subprocess.run([sys.executable, "-P", "-c", code, src, out, log],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  timeout=_VHACD_TIMEOUT_S, check=False)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"V-HACD took longer than {_VHACD_TIMEOUT_S} s") from None
        if proc.returncode != 0 or not os.path.isfile(out):
            tail = proc.stderr.decode(errors="replace")[-300:]
            raise RuntimeError(f"V-HACD failed (exit code {proc.returncode}): {tail}")
        hulls = read_obj_parts(out)
    if not hulls:
        raise RuntimeError("V-HACD produced no convex hull with positive volume")
    return hulls


def coacd(mesh, threshold: float = COACD_THRESHOLD) -> list:
    """Convex decomposition with CoACD (optional package ``coacd``); returns hull meshes."""
    try:
        import coacd as coacd_lib
    except ImportError:
        raise ImportError("decomposition method 'coacd' needs the optional package coacd "
                          "(pip install coacd); the default method 'auto' uses PyBullet's "
                          "V-HACD") from None
    import trimesh

    coacd_lib.set_log_level("error")
    parts = coacd_lib.run_coacd(coacd_lib.Mesh(mesh.vertices, mesh.faces), threshold=threshold)
    hulls = [trimesh.Trimesh(v, f).convex_hull for v, f in parts]
    hulls = [h for h in hulls if h.volume > 0]
    if not hulls:
        raise RuntimeError("CoACD produced no convex hull with positive volume")
    return hulls


def decompose(mesh, method: str = "auto") -> tuple[list, str]:
    """(convex hulls, description of the method used).

    ``method``: ``"auto"`` (the mesh's own convex parts if it consists of them, else V-HACD),
    ``"vhacd"`` or ``"coacd"`` (always decompose with that tool).
    """
    if method not in DECOMPOSITION_METHODS:
        raise InputError(f"decomposition method must be one of {list(DECOMPOSITION_METHODS)}, "
                         f"got {method!r}")
    if method == "auto":
        parts = convex_parts_if_any(mesh)
        if parts is not None:
            return parts, "convex parts of the source mesh"
    if method == "coacd":
        return coacd(mesh), f"CoACD (threshold {COACD_THRESHOLD})"
    return vhacd(mesh), "V-HACD (pybullet.vhacd)"


def make_watertight(mesh):
    """(mesh, watertight?): merge duplicate vertices, fix normals, fill simple holes."""
    mesh = mesh.copy()
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.remove_unreferenced_vertices()
    if not mesh.is_watertight:
        mesh.fill_holes()
    if mesh.is_watertight:
        mesh.fix_normals()
        if mesh.volume < 0:
            mesh.invert()
    return mesh, bool(mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0)


def write_hulls_obj(hulls, path: str | os.PathLike) -> None:
    """Write convex hulls as one OBJ, one ``o hull_k`` object each (PyBullet: compound shape)."""
    lines, offset = [], 1
    for k, hull in enumerate(hulls):
        lines.append(f"o hull_{k:03d}")
        lines.extend("v " + " ".join(fmt(x) for x in v) for v in hull.vertices)
        lines.extend("f " + " ".join(str(int(i) + offset) for i in f) for f in hull.faces)
        offset += len(hull.vertices)
    Path(path).write_text("\n".join(lines) + "\n")


def fmt(x: float) -> str:
    """Fixed formatting of a coordinate: 9 significant digits, no '-0'."""
    s = f"{float(x):.9g}"
    return "0" if s in ("-0", "0") else s
