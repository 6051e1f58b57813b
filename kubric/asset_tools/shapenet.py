"""ShapeNetCore v2 → asset source (``kubric assets shapenet``).

Input: ShapeNetCore v2 as distributed: ``taxonomy.json`` (a list of ``{"synsetId", "name",
"children", "numInstances"}``; ``name`` is a comma-separated list of WordNet synonyms, the first
is used as the category) and ``SYNSET/MODEL/models/model_normalized.obj`` with its
``model_normalized.mtl`` and textures (``../images/``). Asset ids are ``SYNSET/MODEL``; each
entry's metadata holds ``category`` (e.g. ``"airplane"``), ``synset_id`` and ``category_names``.
The meshes are y up (ShapeNet's canonical alignment) and are turned z up.

ShapeNet meshes render badly as they are (the paper, appendix "ShapeNetCore.v2"); before
conversion :func:`repair_mesh` applies, and counts per asset in ``metadata["repairs"]``:

- ``duplicate_faces_removed``: faces repeated with the same winding (one copy is kept) —
  together with trimesh's merging of duplicate vertices on load, the "remove doubles" step;
- ``double_sided_faces``: coincident faces with opposite windings (two-sided walls modelled as
  two triangles); each is moved by :data:`DISPLACEMENT` × the model's size along its own normal,
  the paper's "infinitesimally displacing the faces along the local normal", so Cycles no longer
  z-fights between them;
- ``flipped_faces``: faces whose winding disagreed with their neighbours' (inconsistent normals)
  or whose whole part faced inwards, turned around.

Auto-smoothing is not an issue here: the visual GLB carries no vertex normals, so Blender's glTF
importer shades flat, which is what disabling auto-smooth and splitting sharp edges gave upstream.
For collision, the converter makes a watertight copy where trimesh can close the holes and
otherwise decomposes the open mesh with V-HACD (which voxelises it, i.e. closes it), recorded
in ``metadata["watertight"]`` and ``metadata["collision_method"]``; ``conversion_report.json``
adds the totals of all of these under ``"repairs"``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from kubric.asset_tools.converter import REPORT_NAME, ConvertJob, convert_jobs
from kubric.asset_tools.gso import check_texture
from kubric.asset_tools.writer import dumps
from kubric.core.imports import uninterrupted_import
from kubric.errors import InputError

NAME = "ShapeNetCore.v2"
VERSION = "1.0"
LICENSE = ("ShapeNet terms of use: non-commercial research and educational use only "
           "(https://shapenet.org/terms)")
MODEL_FILE = Path("models") / "model_normalized.obj"
#: displacement of double-sided faces, as a fraction of the model's largest extent.
DISPLACEMENT = 1e-4
REPAIR_KEYS = ("duplicate_faces_removed", "double_sided_faces", "flipped_faces")


def read_taxonomy(path: str | os.PathLike) -> dict[str, list[str]]:
    """``{synset id: [names]}`` from ShapeNet's ``taxonomy.json``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise InputError(f"ShapeNet taxonomy {str(path)!r} is not readable JSON: {err}") from None
    if not isinstance(data, list) or not all(isinstance(d, dict) and "synsetId" in d and
                                             "name" in d for d in data):
        raise InputError(f"ShapeNet taxonomy {str(path)!r}: expected a list of objects with "
                         "'synsetId' and 'name'")
    return {str(d["synsetId"]): [n.strip() for n in str(d["name"]).split(",") if n.strip()]
            for d in data}


def _orientation(faces: np.ndarray) -> np.ndarray:
    """True where a face's corners are an even (cyclic) permutation of their sorted order."""
    order = np.argsort(faces, axis=1)
    return (order[:, 1] - order[:, 0]) % 3 == 1


def _position_ids(vertices: np.ndarray) -> np.ndarray:
    scale = max(float(np.ptp(vertices, axis=0).max()), 1e-12)
    keys = np.round(vertices / (scale * 1e-9)).astype(np.int64)
    return np.unique(keys, axis=0, return_inverse=True)[1].reshape(-1)


def _rebuilt(mesh, vertices, faces, corner_src):
    """A copy of ``mesh`` with new vertices; ``corner_src[i]`` is the old vertex whose
    per-vertex attributes (UV, colour) vertex ``i`` takes."""
    trimesh = uninterrupted_import("trimesh")
    from trimesh.visual.texture import TextureVisuals

    vis = mesh.visual
    if vis.kind == "vertex":
        visual = trimesh.visual.ColorVisuals(vertex_colors=vis.vertex_colors[corner_src])
    elif isinstance(vis, TextureVisuals):
        uv = vis.uv
        uv = uv[corner_src] if uv is not None and len(uv) == len(mesh.vertices) else None
        visual = TextureVisuals(uv=uv, material=vis.material)
    else:
        visual = None
    return trimesh.Trimesh(vertices, faces, visual=visual, process=False)


def repair_mesh(mesh):
    """Fix ShapeNet's rendering artefacts (see the module docstring); returns ``(mesh, counts)``."""
    trimesh = uninterrupted_import("trimesh")

    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64).copy()
    pos = _position_ids(verts)
    pf = pos[faces]
    valid = (pf[:, 0] != pf[:, 1]) & (pf[:, 1] != pf[:, 2]) & (pf[:, 0] != pf[:, 2])
    key = np.sort(pf, axis=1)
    even = _orientation(pf)
    group = np.unique(key, axis=0, return_inverse=True)[1].reshape(-1)
    # one face per (group, orientation); a group with both orientations is double-sided
    first = {}
    keep = np.ones(len(faces), dtype=bool)
    for i in np.nonzero(valid)[0]:
        k = (int(group[i]), bool(even[i]))
        if k in first:
            keep[i] = False
        else:
            first[k] = i
    both = {g for g, e in first if (g, not e) in first}
    double = np.array([valid[i] and keep[i] and int(group[i]) in both
                       for i in range(len(faces))], dtype=bool)
    counts = {"duplicate_faces_removed": int((~keep).sum()),
              "double_sided_faces": int(double.sum())}
    src = np.arange(len(verts))
    if double.any():
        tri = verts[faces[double]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)
        eps = DISPLACEMENT * max(float(np.ptp(verts, axis=0).max()), 1e-12)
        new = (tri + eps * normal[:, None, :]).reshape(-1, 3)
        src = np.concatenate([src, faces[double].reshape(-1)])
        faces[double] = len(verts) + np.arange(new.shape[0]).reshape(-1, 3)
        verts = np.concatenate([verts, new])
    faces = faces[keep]
    # consistent winding, then each connected part facing outwards
    pos = _position_ids(verts)
    unique = np.zeros((pos.max() + 1, 3))
    unique[pos] = verts
    merged = trimesh.Trimesh(unique, pos[faces], process=False)
    before = merged.faces.copy()
    trimesh.repair.fix_winding(merged)
    flip = _orientation(merged.faces) != _orientation(before)
    for part in trimesh.graph.connected_components(merged.face_adjacency,
                                                   nodes=np.arange(len(merged.faces))):
        tri = merged.vertices[merged.faces[part]]
        tri = tri - tri.reshape(-1, 3).mean(axis=0)
        signed = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
        if signed < 0:
            flip[part] = ~flip[part]
    faces[flip] = faces[flip][:, ::-1]
    counts["flipped_faces"] = int(flip.sum())
    return _rebuilt(mesh, verts, faces, src), counts


def find_models(src_dir: str | os.PathLike, synsets=None) -> list[tuple[str, str, Path]]:
    """``[(synset, model, obj path)]`` under ``src_dir`` (sorted), restricted to ``synsets``."""
    src = Path(src_dir)
    if not src.is_dir():
        raise FileNotFoundError(f"ShapeNet folder {str(src)!r} does not exist")
    wanted = set(synsets) if synsets else None
    found = []
    for synset_dir in sorted(p for p in src.iterdir() if p.is_dir()):
        if wanted is not None and synset_dir.name not in wanted:
            continue
        for model_dir in sorted(p for p in synset_dir.iterdir() if p.is_dir()):
            obj = model_dir / MODEL_FILE
            if obj.is_file():
                found.append((synset_dir.name, model_dir.name, obj))
    return found


def build_shapenet(src_dir: str | os.PathLike, out_dir: str | os.PathLike, synsets=None,
                   workers: int | None = None, limit_per_synset: int | None = None,
                   progress: bool = True, name: str = NAME) -> dict:
    """Convert ShapeNetCore v2 models under ``src_dir`` into the source ``out_dir``; returns the
    report (with the repair totals under ``"repairs"``)."""
    src = Path(src_dir)
    taxonomy_path = src / "taxonomy.json"
    if not taxonomy_path.is_file():
        raise FileNotFoundError(f"no taxonomy.json in ShapeNet folder {str(src)!r}")
    taxonomy = read_taxonomy(taxonomy_path)
    if synsets:
        unknown = sorted(set(synsets) - set(taxonomy))
        if unknown:
            raise InputError(f"unknown synset ids {unknown}; taxonomy.json has e.g. "
                             f"{sorted(taxonomy)[:5]}")
    models = find_models(src, synsets)
    jobs, per_synset, skipped = [], {}, []
    for synset, model, obj in models:
        per_synset[synset] = per_synset.get(synset, 0) + 1
        if limit_per_synset is not None and per_synset[synset] > limit_per_synset:
            continue
        try:
            check_texture(obj, copy_missing=False)
        except ValueError as err:  # missing or unreadable texture: reported, not converted
            skipped.append({"id": f"{synset}/{model}", "source": str(obj),
                            "reason": f"ValueError: {err}"})
            continue
        names = taxonomy.get(synset, [synset])
        meta = {"category": names[0], "category_names": names, "synset_id": synset,
                "model_id": model, "description": f"ShapeNet {names[0]} {model}"}
        jobs.append(ConvertJob(f"{synset}/{model}", str(obj), LICENSE, up="y", metadata=meta,
                               repair=repair_mesh))
    if not jobs and not skipped:
        raise InputError(f"no SYNSET/MODEL/{MODEL_FILE.as_posix()} under {str(src)!r}"
                         + (f" for synsets {sorted(synsets)}" if synsets else ""))
    report = convert_jobs(jobs, out_dir, name, VERSION, workers=workers, progress=progress,
                          skipped=skipped)
    manifest = json.loads((Path(out_dir) / "manifest.json").read_text())
    totals = dict.fromkeys(REPAIR_KEYS, 0)
    totals["assets_repaired"] = totals["not_watertight"] = 0
    for entry in manifest["assets"].values():
        reps = entry["metadata"].get("repairs", {})
        for k in REPAIR_KEYS:
            totals[k] += int(reps.get(k, 0))
        totals["assets_repaired"] += int(any(reps.get(k, 0) for k in REPAIR_KEYS))
        totals["not_watertight"] += int(not entry["metadata"].get("watertight", True))
    report["repairs"] = totals
    (Path(out_dir) / REPORT_NAME).write_text(dumps(report))
    return report
