"""Mesh collection → asset source (``kubric assets convert``).

Input: a folder of OBJ (+ MTL and textures), GLB/GLTF, PLY or STL files, searched recursively.
Each mesh becomes one asset whose id is its path relative to the folder without the suffix
(``a/b/b.obj`` collapses to ``a/b``). A sidecar ``<stem>.json`` may give ``category``,
``description``, ``license``, ``scale`` and ``color`` (fallback RGBA). OBJ/PLY/STL are taken
as z up unless ``up="y"``; glTF is y up by definition and is turned z up.

Per asset: load, keep the source's own appearance (see below), scale, make a watertight copy
where possible (trimesh: merge vertices, fill holes), convex decomposition (the mesh's own convex
parts when it consists of them, else PyBullet's V-HACD), mass properties with density 1 (from
the watertight mesh, else from the hulls), centre on the centre of mass, write
``visual_geometry.glb`` (appearance embedded), ``collision_geometry.obj``, ``object.urdf``,
``data.json`` into one archive.

Runs in parallel over processes with a progress bar. A mesh that fails is skipped and listed with
its reason in ``conversion_report.json``; its archive is never half-written (archives are written
to a temporary name and renamed). Re-running converts only what is missing or was written by an
older converter (``metadata["converter_version"]`` != :data:`CONVERTER_VERSION`).

Appearance of the visual GLB (recorded as ``metadata["appearance"]``; ``metadata["base_color"]``
holds the RGBA when one flat colour is used):

- ``"texture"``: the source's own texture image (MTL ``map_Kd`` / glTF base colour texture).
  As the MTL format defines, the material's ``Kd`` multiplies the texture (glTF
  ``baseColorFactor``).
- ``"mtl"``: untextured materials (MTL ``Kd``, glTF ``baseColorFactor``), per material. One
  colour becomes the material's ``baseColorFactor``; several distinct colours are baked into a
  small palette texture (4x4 pixels per colour, sRGB-encoded so that the imported linear value
  equals ``Kd``) with each part's UVs at the centre of its colour.
- ``"urdf_color"`` / ``"json_color"``: the mesh has no material of its own and its job carries a
  fallback ``color`` (the URDF ``<visual><material><color rgba>`` or the sidecar's ``color``).
- ``"vertex_color"``: per-vertex/face colours of the source (PLY, glTF), exported as they are.
- ``"none"``: nothing to keep; Blender shows its default material.

Colour values (``Kd``, URDF ``rgba``) are used as linear base colours, exactly as Blender's own
OBJ importer does; the GLB stores them with 8-bit precision (trimesh). Materials made from
OBJ/MTL or a fallback colour are dielectric (``metallicFactor`` 0; glTF's default would be 1).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import tarfile
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from kubric.asset_tools import gltf_pbr, physics
from kubric.asset_tools.mesh_load import as_rgba, split_parts
from kubric.asset_tools.physics import DECOMPOSITION_METHODS
from kubric.asset_tools.writer import Collision, dumps, package_object, write_manifest
from kubric.assets.gltf_refs import check_gltf
from kubric.core.color import linear_to_srgb
from kubric.core.imports import uninterrupted_import
from kubric.errors import InputError

MESH_SUFFIXES = (".obj", ".glb", ".gltf", ".ply", ".stl")
REPORT_NAME = "conversion_report.json"
#: version of what :func:`convert_one` writes; archives from another version are converted again.
CONVERTER_VERSION = 3
#: roughness of materials made from a fallback colour (no specular information in a URDF).
FALLBACK_ROUGHNESS = 0.5
_PALETTE_BLOCK = 4  # pixels per palette colour (side of the square block)


@dataclass
class ConvertJob:
    """One mesh to convert. ``scale``: a number or 3 per-axis factors applied to the raw mesh.

    ``color``: fallback RGBA (or RGB) in [0, 1] for a mesh without a material or texture of its
    own; ``color_from`` names where it came from (the ``metadata["appearance"]`` value).
    ``repair``: a module-level function ``mesh -> (mesh, counts)`` applied after loading (e.g.
    :func:`kubric.asset_tools.shapenet.repair_mesh`); ``counts`` is stored as ``metadata["repairs"]``.
    ``max_extent``: scale the loaded mesh so that its bounding box's largest side is this many
    metres (after ``scale``); the factor is stored as ``metadata["normalised_scale"]``.
    """

    asset_id: str
    mesh_path: str
    license: str
    scale: float | tuple = 1.0
    up: str = "z"
    metadata: dict = field(default_factory=dict)
    decomposition: str = "auto"
    color: tuple | None = None
    color_from: str = "urdf_color"
    repair: object = None
    max_extent: float | None = None


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
        if path.suffix.lower() in (".gltf", ".glb"):
            check_gltf(path, src, malformed_ok=True)  # URIs stay inside SRC (trimesh follows any)
        asset_id = _sanitize_id(path.relative_to(src))
        if asset_id in jobs:
            raise InputError(f"two meshes map to the asset id {asset_id!r}: "
                             f"{jobs[asset_id].mesh_path} and {path}")
        meta, lic, sc, color = {}, license, scale, None
        sidecar = path.with_suffix(".json")
        if sidecar.is_file():
            try:
                info = json.loads(sidecar.read_text())
            except (UnicodeDecodeError, json.JSONDecodeError) as err:
                raise InputError(f"sidecar {str(sidecar)!r} is not valid JSON: {err}") from None
            if not isinstance(info, dict):
                raise InputError(f"sidecar {str(sidecar)!r} must hold a JSON object, got "
                                 f"{type(info).__name__}")
            meta = {k: info[k] for k in ("category", "description") if k in info}
            lic = info.get("license", license)
            sc = info.get("scale", scale)
            if "color" in info:
                color = as_rgba(info["color"], f"'color' in {sidecar}")
        jobs[asset_id] = ConvertJob(asset_id, str(path), lic, sc, up, meta, decomposition,
                                    color, "json_color")
    return [jobs[k] for k in sorted(jobs)]


def load_visual(path: str, up: str = "z", scale=1.0, color=None,
                color_from: str = "urdf_color"):
    """Load a mesh file as one z-up trimesh that keeps the source's appearance.

    Returns ``(mesh, look)``: ``look`` is ``{"appearance": ...}`` plus ``"base_color"`` (RGBA)
    when one flat colour is used (see the module docstring). ``color``: fallback RGBA for parts
    without a material of their own.
    """
    import numpy as np
    trimesh = uninterrupted_import("trimesh")

    suffix = Path(path).suffix.lower()
    if suffix == ".obj":
        _check_obj_vertices(path)
    fallback = None if color is None else as_rgba(color, f"color of {path}")
    resolver = trimesh.resolvers.FilePathResolver(path, allow_anywhere=True)  # "../x.png" maps
    loaded = trimesh.load(path, process=True, resolver=resolver)
    mesh, look = _with_appearance(split_parts(loaded), fallback, color_from)
    if suffix in (".glb", ".gltf") or up == "y":
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    elif up != "z":
        raise InputError(f"up must be 'z' or 'y', got {up!r}")
    factors = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    if not np.all(factors > 0):
        raise InputError(f"scale must be positive, got {scale!r}")
    mesh.apply_transform(np.diag([*factors, 1.0]))
    if len(mesh.faces) == 0 or not np.all(np.isfinite(mesh.vertices)):
        raise InputError("empty mesh or non-finite vertex coordinates")
    if np.min(mesh.extents) <= 0:
        raise InputError(f"degenerate (flat) mesh with extents {mesh.extents.tolist()}")
    return mesh, look


def _check_obj_vertices(path: str) -> None:
    """Refuse an OBJ with non-finite vertex coordinates (trimesh would silently drop them)."""
    import math

    with open(path, errors="replace") as fh:
        count = 0
        for line in fh:
            if not line.startswith("v "):
                continue
            count += 1
            low = line.lower()
            if "nan" in low or "inf" in low:
                coords = line.split()[1:4]
                if not all(math.isfinite(float(c)) for c in coords):
                    raise InputError(f"non-finite vertex coordinates in vertex {count}: "
                                     f"{' '.join(coords)}")


def load_mesh(path: str, up: str = "z", scale=1.0, color=None):
    """Like :func:`load_visual` but returns only the mesh."""
    return load_visual(path, up, scale, color)[0]


def _part_look(part):
    """Classify one part: ``("texture", material)``, ``("color", (rgba, roughness))``,
    ``("vertex_color", None)`` or ``("none", None)``."""
    import numpy as np
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    vis = part.visual
    mat = getattr(vis, "material", None)
    if isinstance(vis, TextureVisuals) and mat is not None:
        pbr = mat if isinstance(mat, PBRMaterial) else mat.to_pbr()
        uv = vis.uv
        if pbr.baseColorTexture is not None and uv is not None and len(uv) == len(part.vertices):
            return "texture", mat
        factor = pbr.baseColorFactor
        rgba = (1.0, 1.0, 1.0, 1.0) if factor is None else \
            tuple(float(c) for c in np.asarray(factor, dtype=np.float64) / 255.0)
        rough = pbr.roughnessFactor
        return "color", (rgba, FALLBACK_ROUGHNESS if rough is None else float(rough))
    if vis.kind in ("vertex", "face"):
        return "vertex_color", None
    return "none", None


def _dielectric(mat):
    """An OBJ/MTL material as a glTF PBR material with metallic 0 (glTF PBR kept as it is)."""
    from trimesh.visual.material import PBRMaterial

    if isinstance(mat, PBRMaterial):
        return mat
    pbr = mat.to_pbr()
    pbr.metallicFactor = 0.0
    return pbr


def srgb_bytes(linear):
    """Linear values in [0, 1] → 8-bit sRGB-encoded values (the inverse of an image import)."""
    import numpy as np

    return np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)


def _pack_atlas(parts, looks, fallback):
    """Several materials, some textured → one mesh with one atlas texture (factor white).

    Each part's base colour is baked into an sRGB image first (a textured part: its texture
    times its factor, in linear space; an untextured part: a small image of its colour), then
    trimesh packs the images into one atlas and remaps the UVs.
    """
    import numpy as np
    trimesh = uninterrupted_import("trimesh")
    from PIL import Image
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    for part, (kind, info) in zip(parts, looks, strict=True):
        if kind == "texture":
            mat = _dielectric(info)
            pixels = np.asarray(mat.baseColorTexture.convert("RGBA"), dtype=np.float64)
            factor = np.ones(4) if mat.baseColorFactor is None else \
                np.asarray(mat.baseColorFactor, dtype=np.float64) / 255.0
            linear = srgb_to_linear(pixels[..., :3] / 255.0) * factor[:3]
            baked = np.empty(pixels.shape, dtype=np.uint8)
            baked[..., :3] = srgb_bytes(linear)
            baked[..., 3] = np.round(pixels[..., 3] * factor[3]).astype(np.uint8)
            texture, rough = Image.fromarray(baked, "RGBA"), mat.roughnessFactor
            uv = part.visual.uv
        else:
            rgba = info[0] if kind == "color" else (fallback or (1.0, 1.0, 1.0, 1.0))
            block = np.empty((_PALETTE_BLOCK, _PALETTE_BLOCK, 4), dtype=np.uint8)
            block[..., :3] = srgb_bytes(rgba[:3])
            block[..., 3] = int(round(rgba[3] * 255))
            texture = Image.fromarray(block, "RGBA")
            rough = info[1] if kind == "color" else FALLBACK_ROUGHNESS
            uv = np.full((len(part.vertices), 2), 0.5)
        part.visual = TextureVisuals(uv=uv, material=PBRMaterial(
            baseColorTexture=texture, metallicFactor=0.0, roughnessFactor=rough))
    mesh = trimesh.util.concatenate(parts)
    mat = mesh.visual.material
    if not isinstance(mat, PBRMaterial) or mat.baseColorTexture is None:
        raise InputError(f"packing {len(parts)} materials into one texture failed "
                         f"(got {type(mat).__name__})")
    mat.baseColorFactor = None
    mat.metallicFactor = 0.0
    return mesh


def srgb_to_linear(srgb):
    """sRGB-encoded values in [0, 1] → linear values (the decoding an image import applies)."""
    from kubric.core.color import srgb_to_linear as decode
    return decode(srgb)


def _with_appearance(parts, fallback, color_from: str):
    """Join ``parts`` into one trimesh whose visual keeps their appearance; see load_visual."""
    import numpy as np
    trimesh = uninterrupted_import("trimesh")
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    looks = [_part_look(p) for p in parts]
    kinds = {kind for kind, _ in looks}
    if "texture" in kinds:
        if len(parts) == 1:
            mesh = parts[0]
            mesh.visual.material = _dielectric(looks[0][1])
            return mesh, {"appearance": "texture"}
        return _pack_atlas(parts, looks, fallback), {"appearance": "texture"}
    if "vertex_color" in kinds or (kinds == {"none"} and fallback is None):
        mesh = parts[0] if len(parts) == 1 else trimesh.util.concatenate(parts)
        return mesh, {"appearance": "vertex_color" if "vertex_color" in kinds else "none"}
    colors, rough = [], []
    for kind, info in looks:
        if kind == "color":
            colors.append(info[0])
            rough.append(info[1])
        else:  # no material of its own: the fallback colour, else glTF's default white
            colors.append(fallback if fallback is not None else (1.0, 1.0, 1.0, 1.0))
            rough.append(FALLBACK_ROUGHNESS)
    appearance = "mtl" if "color" in kinds else color_from
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    vertices = np.concatenate([p.vertices for p in parts])
    faces = np.concatenate([p.faces + o for p, o in zip(parts, offsets[:-1], strict=True)])
    keys = [tuple(int(round(c * 255)) for c in rgba) for rgba in colors]
    unique = sorted(set(keys), key=keys.index)
    roughness = float(np.mean(rough))
    if len(unique) == 1:
        uvs = [getattr(p.visual, "uv", None) for p in parts]
        uv = np.concatenate(uvs) if all(u is not None and len(u) == len(p.vertices)
                                        for u, p in zip(uvs, parts, strict=True)) else None
        pbr = PBRMaterial(baseColorFactor=colors[0], metallicFactor=0.0,
                          roughnessFactor=roughness)
        mesh = trimesh.Trimesh(vertices, faces, process=False,
                               visual=TextureVisuals(uv=uv, material=pbr))
        return mesh, {"appearance": appearance, "base_color": list(colors[0])}
    block = _PALETTE_BLOCK
    image = np.zeros((block, block * len(unique), 4), dtype=np.uint8)
    rgba_of = dict(zip(keys, colors, strict=True))
    for k, key in enumerate(unique):
        rgba = np.asarray(rgba_of[key])
        image[:, k * block:(k + 1) * block, :3] = srgb_bytes(rgba[:3])
        image[:, k * block:(k + 1) * block, 3] = int(round(rgba[3] * 255))
    u_of = {key: (k + 0.5) / len(unique) for k, key in enumerate(unique)}
    uv = np.concatenate([np.tile([u_of[key], 0.5], (len(p.vertices), 1))
                         for key, p in zip(keys, parts, strict=True)])
    from PIL import Image

    pbr = PBRMaterial(baseColorTexture=Image.fromarray(image, "RGBA"),
                      baseColorFactor=(1.0, 1.0, 1.0, 1.0), metallicFactor=0.0,
                      roughnessFactor=roughness)
    mesh = trimesh.Trimesh(vertices, faces, process=False,
                           visual=TextureVisuals(uv=uv, material=pbr))
    return mesh, {"appearance": appearance, "palette": [list(rgba_of[k]) for k in unique]}


def convert_one(job: ConvertJob, out_dir: str | os.PathLike) -> dict:
    """Convert one mesh into ``out_dir``; returns the manifest entry (raises on failure)."""
    parts = None
    if gltf_pbr.is_gltf(job.mesh_path):  # glTF: each part keeps its own PBR material
        mesh, parts, look = gltf_pbr.load_gltf_parts(job.mesh_path, job.scale, job.color)
    else:
        mesh, look = load_visual(job.mesh_path, job.up, job.scale, job.color, job.color_from)
    if job.max_extent is not None:
        look["normalised_scale"] = gltf_pbr.normalise_extent(mesh, parts or [], job.max_extent)
    repairs = None
    if job.repair is not None:
        mesh, repairs = job.repair(mesh)  # a glTF's parts (the visual) keep their materials
    closed, watertight = physics.make_watertight(mesh)
    hulls, method = physics.decompose(closed if watertight else mesh, job.decomposition)
    metadata = dict(job.metadata)
    metadata.update(look)
    metadata.update({"source_file": Path(job.mesh_path).name, "watertight": watertight,
                     "mass_from": "watertight mesh" if watertight else "convex hulls",
                     "converter_version": CONVERTER_VERSION})
    if repairs is not None:
        metadata["repairs"] = repairs
    return package_object(job.asset_id, mesh, out_dir,
                          collision=Collision("hulls", hulls=hulls, method=method),
                          license=job.license, metadata=metadata,
                          physics_parts=[closed] if watertight else None, visual_format="glb",
                          visual_parts=parts)


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
                 progress: bool = True, skipped: list | None = None) -> dict:
    """Convert ``jobs`` into the source ``out_dir`` and write its manifest and report.

    Archives already there are reused when they hold this asset and were written by this
    :data:`CONVERTER_VERSION`; the others are converted again (each replaced atomically), and the
    manifest is written last. Returns the report: ``{"name", "total", "converted", "reused",
    "skipped": [{"id", "source", "reason"}]}`` (also written to ``conversion_report.json``).
    ``skipped``: failures found before conversion (e.g. an unsafe zip), added to the report.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries, todo = {}, []
    for job in jobs:
        entry = read_entry(out / f"{job.asset_id}.tar.gz")
        if entry is not None and entry.get("id") == job.asset_id and \
                entry.get("metadata", {}).get("converter_version") == CONVERTER_VERSION:
            entries[job.asset_id] = entry
        else:
            todo.append(job)
    reused = len(entries)
    skipped = list(skipped or [])
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
    report = {"name": name, "total": len(entries) + len(skipped),
              "converted": len(entries) - reused,
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
    if decomposition not in DECOMPOSITION_METHODS:
        raise InputError(f"decomposition must be one of {list(DECOMPOSITION_METHODS)}, "
                         f"got {decomposition!r}")
    if decomposition == "coacd":
        import importlib.util
        if importlib.util.find_spec("coacd") is None:
            raise ImportError("decomposition 'coacd' needs the optional package coacd "
                              "(pip install coacd)")
    jobs = discover_jobs(src_dir, license=license, up=up, scale=scale,
                         decomposition=decomposition)
    if not jobs:
        raise InputError(f"no {list(MESH_SUFFIXES)} files under {str(src_dir)!r}")
    return convert_jobs(jobs, out_dir, name, workers=workers, progress=progress)
