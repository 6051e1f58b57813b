"""Mesh collection → asset source (``kubric assets convert``).

Input: a folder of OBJ (+ MTL and textures), GLB/GLTF, PLY or STL files, searched recursively.
Each mesh becomes one asset whose id is its path relative to the folder without the suffix
(``a/b/b.obj`` collapses to ``a/b``). A sidecar ``<stem>.json`` may give ``category``,
``description``, ``license`` and ``scale``. OBJ/PLY/STL are taken as z up unless ``up="y"``;
glTF is y up by definition and is turned z up.

Per asset: load (textures kept), scale, make a watertight copy where possible (trimesh: merge
vertices, fill holes), convex decomposition (the mesh's own convex parts when it consists of
them, else PyBullet's V-HACD), mass properties with density 1 (from the watertight mesh, else
from the hulls), centre on the centre of mass, write ``visual_geometry.glb`` (textures embedded),
``collision_geometry.obj``, ``object.urdf``, ``data.json`` into one archive.

Runs in parallel over processes with a progress bar. A mesh that fails is skipped and listed with
its reason in ``conversion_report.json``; its archive is never half-written (archives are written
to a temporary name and renamed). Re-running converts only what is missing.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import tarfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl")
REPORT_NAME = "conversion_report.json"


@dataclass
class ConvertJob:
    """One mesh to convert. ``scale``: a number or 3 per-axis factors applied to the raw mesh."""

    asset_id: str
    mesh_path: str
    license: str
    scale: float | tuple = 1.0
    up: str = "z"
    metadata: dict = field(default_factory=dict)
    decomposition: str = "auto"


def _sanitize_id(rel: Path) -> str:
    parts = list(rel.with_suffix("").parts)
    if len(parts) >= 2 and parts[-1] == parts[-2]:
        parts = parts[:-1]
    return "/".join("".join(c if c.isalnum() or c in "-_." else "_" for c in p) for p in parts)


def discover_jobs(src_dir: str | os.PathLike, license: str, up: str = "z",
                  scale: float = 1.0, decomposition: str = "auto") -> list[ConvertJob]:
    """One :class:`ConvertJob` per mesh file under ``src_dir`` (sorted by id)."""
    src = Path(src_dir)
    if not src.is_dir():
        raise FileNotFoundError(f"mesh collection folder {str(src)!r} does not exist")
    jobs: dict[str, ConvertJob] = {}
    for path in sorted(src.rglob("*")):
        if path.suffix.lower() not in MESH_SUFFIXES or not path.is_file():
            continue
        asset_id = _sanitize_id(path.relative_to(src))
        if asset_id in jobs:
            raise ValueError(f"two meshes map to the asset id {asset_id!r}: "
                             f"{jobs[asset_id].mesh_path} and {path}")
        meta, lic, sc = {}, license, scale
        sidecar = path.with_suffix(".json")
        if sidecar.is_file():
            info = json.loads(sidecar.read_text())
            meta = {k: info[k] for k in ("category", "description") if k in info}
            lic = info.get("license", license)
            sc = info.get("scale", scale)
        jobs[asset_id] = ConvertJob(asset_id, str(path), lic, sc, up, meta, decomposition)
    return [jobs[k] for k in sorted(jobs)]


def load_mesh(path: str, up: str = "z", scale=1.0):
    """Load a mesh file as one z-up trimesh (scene graphs flattened, textures kept)."""
    import numpy as np
    import trimesh

    suffix = Path(path).suffix.lower()
    loaded = trimesh.load(path, process=True)
    if isinstance(loaded, trimesh.Scene):
        if not loaded.geometry:
            raise ValueError("the file holds no geometry")
        loaded = loaded.to_geometry() if hasattr(loaded, "to_geometry") else \
            loaded.dump(concatenate=True)
    if not isinstance(loaded, trimesh.Trimesh):
        raise ValueError(f"not a triangle mesh (got {type(loaded).__name__}, e.g. a point cloud)")
    mesh = loaded
    if suffix in (".glb", ".gltf") or up == "y":
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    elif up != "z":
        raise ValueError(f"up must be 'z' or 'y', got {up!r}")
    factors = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    if not np.all(factors > 0):
        raise ValueError(f"scale must be positive, got {scale!r}")
    mesh.apply_transform(np.diag([*factors, 1.0]))
    if len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)):
        raise ValueError("empty mesh or non-finite vertex coordinates")
    if np.min(mesh.extents) <= 0:
        raise ValueError(f"degenerate (flat) mesh with extents {mesh.extents.tolist()}")
    return mesh


def convert_one(job: ConvertJob, out_dir: str | os.PathLike) -> dict:
    """Convert one mesh into ``out_dir``; returns the manifest entry (raises on failure)."""
    from kubric.assets import physics
    from kubric.assets.writer import Collision, package_object

    mesh = load_mesh(job.mesh_path, job.up, job.scale)
    closed, watertight = physics.make_watertight(mesh)
    hulls, method = physics.decompose(closed if watertight else mesh, job.decomposition)
    metadata = dict(job.metadata)
    metadata.update({"source_file": Path(job.mesh_path).name, "watertight": watertight,
                     "mass_from": "watertight mesh" if watertight else "convex hulls"})
    return package_object(job.asset_id, mesh, out_dir,
                          collision=Collision("hulls", hulls=hulls, method=method),
                          license=job.license, metadata=metadata,
                          physics_parts=[closed] if watertight else None, visual_format="glb")


def read_entry(archive: Path) -> dict | None:
    """The ``data.json`` entry stored in an existing archive, or None if unreadable."""
    try:
        with tarfile.open(archive, "r:gz") as tar:
            member = tar.extractfile("data.json")
            return json.loads(member.read()) if member else None
    except (OSError, tarfile.TarError, KeyError, EOFError, json.JSONDecodeError):
        return None


def _job_worker(args):
    job, out_dir = args
    try:
        return job.asset_id, convert_one(job, out_dir), None
    except Exception as err:  # noqa: BLE001 - every failure becomes a report line
        return job.asset_id, None, f"{type(err).__name__}: {err}"


def convert_jobs(jobs: list[ConvertJob], out_dir: str | os.PathLike, name: str,
                 version: str = "1.0", workers: int | None = None,
                 progress: bool = True) -> dict:
    """Convert ``jobs`` into the source ``out_dir`` and write its manifest and report.

    Returns the report: ``{"name", "total", "converted", "reused", "skipped": [{"id", "source",
    "reason"}]}`` (also written to ``conversion_report.json``).
    """
    from kubric.assets.writer import dumps, write_manifest

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries, todo = {}, []
    for job in jobs:
        entry = read_entry(out / f"{job.asset_id}.tar.gz")
        if entry is not None and entry.get("id") == job.asset_id:
            entries[job.asset_id] = entry
        else:
            todo.append(job)
    reused = len(entries)
    skipped = []
    by_id = {j.asset_id: j for j in jobs}
    workers = max(1, workers or os.cpu_count() or 1)
    args = [(job, str(out)) for job in todo]
    pool = None
    if workers > 1 and len(todo) > 1:
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
        results = pool.map(_job_worker, args, chunksize=1)
    else:
        results = map(_job_worker, args)
    if progress:
        from tqdm import tqdm
        results = tqdm(results, total=len(args), desc=f"converting {name}", unit="mesh")
    try:
        for asset_id, entry, error in results:
            if error is None:
                entries[asset_id] = entry
            else:
                skipped.append({"id": asset_id, "source": by_id[asset_id].mesh_path,
                                "reason": error})
    finally:
        if pool is not None:
            pool.shutdown()
    write_manifest(out / "manifest.json", name, version, entries)
    report = {"name": name, "total": len(jobs), "converted": len(entries) - reused,
              "reused": reused, "skipped": sorted(skipped, key=lambda s: s["id"])}
    (out / REPORT_NAME).write_text(dumps(report))
    return report


def convert_collection(src_dir: str | os.PathLike, out_dir: str | os.PathLike, name: str,
                       license: str, workers: int | None = None, up: str = "z",
                       scale: float = 1.0, progress: bool = True,
                       decomposition: str = "auto") -> dict:
    """Convert every mesh under ``src_dir`` (see the module docstring); returns the report.

    ``decomposition``: ``"auto"`` (default; own convex parts, else V-HACD), ``"vhacd"`` or
    ``"coacd"`` (optional package).
    """
    from kubric.assets.physics import DECOMPOSITION_METHODS

    if decomposition not in DECOMPOSITION_METHODS:
        raise ValueError(f"decomposition must be one of {list(DECOMPOSITION_METHODS)}, "
                         f"got {decomposition!r}")
    if decomposition == "coacd":
        import importlib.util
        if importlib.util.find_spec("coacd") is None:
            raise ImportError("decomposition 'coacd' needs the optional package coacd "
                              "(pip install coacd)")
    jobs = discover_jobs(src_dir, license=license, up=up, scale=scale,
                         decomposition=decomposition)
    if not jobs:
        raise ValueError(f"no {list(MESH_SUFFIXES)} files under {str(src_dir)!r}")
    return convert_jobs(jobs, out_dir, name, workers=workers, progress=progress)
