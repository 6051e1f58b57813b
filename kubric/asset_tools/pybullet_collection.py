"""A real third-party collection on every machine: the objects shipped in ``pybullet_data``.

``random_urdfs/NNN`` (1000 procedurally generated blobs, each a set of convex parts) and a list
of textured models (duck, teddy, domino, ...), converted with :mod:`kubric.asset_tools.converter` at
the size their own URDF gives them (the URDF's mesh ``scale``). Ids: ``"random_urdfs/023"``,
``"duck"``, ...; categories ``"random_urdfs"`` and ``"textured_models"``.

Appearance: a mesh's own texture or MTL colours are kept; a mesh without either gets its URDF's
visual material colour (``<visual><material><color rgba>``), see :mod:`kubric.asset_tools.converter`.
:data:`VERSION` is the manifest version; a cached collection whose manifest carries another
version is converted again (see :func:`ensure_pybullet_collection`).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from kubric.asset_tools.converter import ConvertJob, as_rgba, convert_jobs
from kubric.assets.asset_source import AssetSource, build_lock, cache_dir
from kubric.errors import InputError

NAME = "PybulletObjects"
#: 2.0: visual GLBs carry the source's appearance (texture, MTL colour or URDF colour)
VERSION = "2.1"  # 2.1: each archive's sha256 in the manifest
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


def urdf_visual_color(urdf: Path) -> tuple[float, float, float, float] | None:
    """RGBA of the first link visual's ``<material>`` in a URDF (None if it gives no colour).

    The material may hold the ``<color>`` itself or name a robot-level ``<material>`` that does.
    """
    import xml.etree.ElementTree as ET

    try:
        robot = ET.parse(urdf).getroot()
    except ET.ParseError as err:
        raise InputError(f"URDF {urdf} is not valid XML: {err}") from err
    named = {m.get("name"): m for m in robot.findall("material")}
    material = robot.find("./link/visual/material")
    if material is None:
        return None
    color = material.find("color")
    if color is None and material.get("name") in named:
        color = named[material.get("name")].find("color")
    if color is None or color.get("rgba") is None:
        return None
    try:
        values = [float(v) for v in color.get("rgba").split()]
    except ValueError as err:
        raise InputError(f"URDF {urdf}: color rgba must be numbers, got "
                         f"{color.get('rgba')!r}") from err
    return as_rgba(values, f"URDF {urdf} color rgba")


def pybullet_jobs(limit: int | None = None, textured: bool = True):
    """Conversion jobs: the first ``limit`` random_urdfs (all if None) + the textured models."""
    import pybullet_data

    root = Path(pybullet_data.getDataPath())
    jobs = []
    dirs = sorted(p for p in (root / "random_urdfs").iterdir() if p.is_dir())
    for d in dirs[:limit] if limit is not None else dirs:
        mesh, urdf = d / f"{d.name}.obj", d / f"{d.name}.urdf"
        if not mesh.is_file():
            continue
        has_urdf = urdf.is_file()
        scale = urdf_mesh_scale(urdf) if has_urdf else (1.0, 1.0, 1.0)
        jobs.append(ConvertJob(f"random_urdfs/{d.name}", str(mesh), ZLIB, scale, "z",
                               {"category": "random_urdfs",
                                "description": f"random object {d.name} from pybullet_data"},
                               color=urdf_visual_color(urdf) if has_urdf else None))
    if textured:
        for asset_id, (mesh, urdf, lic, desc) in sorted(TEXTURED_MODELS.items()):
            scale = urdf_mesh_scale(root / urdf) if urdf else (1.0, 1.0, 1.0)
            jobs.append(ConvertJob(asset_id, str(root / mesh), lic, scale, "z",
                                   {"category": "textured_models", "description": desc},
                                   color=urdf_visual_color(root / urdf) if urdf else None))
    return jobs


def build_pybullet_collection(out_dir: str | os.PathLike, limit: int | None = None,
                              workers: int | None = None, progress: bool = True,
                              only: list[str] | None = None) -> dict:
    """Convert the pybullet_data objects into ``out_dir``; returns the conversion report.

    ``only``: restrict to these ids (e.g. a test subset).
    """
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
    of random_urdfs (default: all 1000, several minutes per core). The cache counts as complete
    when its ``manifest.json`` exists and carries :data:`VERSION`; otherwise the collection is
    (re)built: archives from an older converter are converted again, each replaced atomically,
    and the new manifest is written (atomically) last, so an interrupted rebuild is redone.
    """
    root = Path(cache) if cache is not None else cache_dir()
    target = root / NAME
    if limit is not None:
        target = root / f"{NAME}-{int(limit)}"
    if manifest_version(target / "manifest.json") != VERSION:
        with build_lock(target):  # concurrent callers convert once; the others wait
            if manifest_version(target / "manifest.json") != VERSION:
                build_pybullet_collection(target, limit=limit, workers=workers, progress=True)
    return AssetSource(target)


def manifest_version(path: Path) -> str | None:
    """The ``version`` of a manifest file, or None if it is missing or unreadable."""
    try:
        return str(json.loads(Path(path).read_text()).get("version"))
    except (OSError, ValueError, AttributeError):
        return None
