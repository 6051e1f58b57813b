"""A real third-party collection on every machine: the objects shipped in ``pybullet_data``.

``random_urdfs/NNN`` (1000 procedurally generated blobs, each a set of convex parts) and a list
of textured models (duck, teddy, domino, ...), converted with :mod:`kubric.assets.converter` at
the size their own URDF gives them (the URDF's mesh ``scale``). Ids: ``"random_urdfs/023"``,
``"duck"``, ...; categories ``"random_urdfs"`` and ``"textured_models"``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

NAME = "PybulletObjects"
VERSION = "1.0"
ZLIB = "zlib (pybullet_data, Bullet Physics / Erwin Coumans)"

#: id → (mesh, URDF giving its scale or None, licence, description)
TEXTURED_MODELS = {
    "duck": ("duck.obj", "duck_vhacd.urdf", "COLLADA sample model 'duck' (Sony Computer "
             "Entertainment, SCEA Shared Source License 1.0), via pybullet_data", "rubber duck"),
    "teddy": ("teddy2_VHACD_CHs.obj", "teddy_vhacd.urdf", ZLIB, "teddy bear"),
    "domino": ("domino/domino.obj", "domino/domino.urdf", ZLIB, "domino tile"),
    "soccerball": ("soccerball.obj", "soccerball.urdf", ZLIB, "soccer ball"),
    "mug": ("objects/mug.obj", "objects/mug.urdf", ZLIB, "mug"),
    "lego": ("lego/lego.obj", "lego/lego.urdf", ZLIB, "lego brick"),
    "jenga": ("jenga/jenga.obj", "jenga/jenga.urdf", ZLIB, "jenga block"),
    "textured_sphere": ("textured_sphere_smooth.obj", "sphere2.urdf", ZLIB, "textured sphere"),
    "textured_cube": ("cube.obj", "cube.urdf", ZLIB, "textured cube"),
    "textured_torus": ("torus/torus_textured.obj", None, ZLIB, "textured torus"),
    "concave_box": ("toys/concave_box.obj", "toys/concave_box.urdf", ZLIB, "open box"),
    "shape_sorter": ("toys/shape_sorter.obj", None, ZLIB, "shape sorter toy"),
}

_SCALE_RE = re.compile(r'<mesh[^>]*filename="([^"]+)"[^>]*?(?:scale="([^"]+)")?\s*/?>')


def urdf_mesh_scale(urdf: Path) -> tuple[float, float, float]:
    """The ``scale`` of the first visual ``<mesh>`` in a URDF (1 if none is given)."""
    text = urdf.read_text()
    visual = text.split("<visual", 1)[1] if "<visual" in text else text
    match = _SCALE_RE.search(visual)
    if not match or not match.group(2):
        return (1.0, 1.0, 1.0)
    vals = [float(v) for v in match.group(2).split()]
    return tuple(vals * 3)[:3] if len(vals) == 1 else tuple(vals[:3])


def pybullet_jobs(limit: int | None = None, textured: bool = True):
    """Conversion jobs: the first ``limit`` random_urdfs (all if None) + the textured models."""
    import pybullet_data

    from kubric.assets.converter import ConvertJob

    root = Path(pybullet_data.getDataPath())
    jobs = []
    dirs = sorted(p for p in (root / "random_urdfs").iterdir() if p.is_dir())
    for d in dirs[:limit] if limit is not None else dirs:
        mesh, urdf = d / f"{d.name}.obj", d / f"{d.name}.urdf"
        if not mesh.is_file():
            continue
        scale = urdf_mesh_scale(urdf) if urdf.is_file() else (1.0, 1.0, 1.0)
        jobs.append(ConvertJob(f"random_urdfs/{d.name}", str(mesh), ZLIB, scale, "z",
                               {"category": "random_urdfs",
                                "description": f"random object {d.name} from pybullet_data"}))
    if textured:
        for asset_id, (mesh, urdf, lic, desc) in sorted(TEXTURED_MODELS.items()):
            scale = urdf_mesh_scale(root / urdf) if urdf else (1.0, 1.0, 1.0)
            jobs.append(ConvertJob(asset_id, str(root / mesh), lic, scale, "z",
                                   {"category": "textured_models", "description": desc}))
    return jobs


def build_pybullet_collection(out_dir: str | os.PathLike, limit: int | None = None,
                              workers: int | None = None, progress: bool = True,
                              only: list[str] | None = None) -> dict:
    """Convert the pybullet_data objects into ``out_dir``; returns the conversion report.

    ``only``: restrict to these ids (e.g. a test subset).
    """
    from kubric.assets.converter import convert_jobs

    jobs = pybullet_jobs(limit=limit)
    if only is not None:
        wanted = set(only)
        jobs = [j for j in jobs if j.asset_id in wanted]
        missing = wanted - {j.asset_id for j in jobs}
        if missing:
            raise KeyError(f"no pybullet_data object(s) {sorted(missing)}")
    return convert_jobs(jobs, out_dir, NAME, VERSION, workers=workers, progress=progress)


def ensure_pybullet_collection(limit: int | None = None, cache=None, workers=None):
    """The pybullet_data objects as an :class:`AssetSource` in ``<cache>/PybulletObjects``.

    Converts what is missing (re-running reuses existing archives); ``limit`` bounds the number
    of random_urdfs (default: all 1000, several minutes per core).
    """
    from kubric.assets.asset_source import AssetSource, cache_dir

    root = Path(cache) if cache is not None else cache_dir()
    target = root / NAME
    if limit is not None:
        target = root / f"{NAME}-{int(limit)}"
    if not (target / "manifest.json").is_file():
        build_pybullet_collection(target, limit=limit, workers=workers, progress=True)
    return AssetSource(target)
