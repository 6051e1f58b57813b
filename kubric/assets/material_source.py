"""Material sources: folders of PBR image sets (``kubric assets materials``) and the built-in
procedural source.

A material source folder holds ``materials.json``::

    {"name": "PolyHavenMaterials", "version": "1.0", "resolution": "1k",
     "materials": {ID: {"maps": {"base_color": "ID/ID_base_color.jpg", "roughness": ...,
                                 "metallic": ..., "normal": ..., "displacement": ...},
                        "files": {"ID/ID_base_color.jpg": {"size": N, "md5": "..."}, ...},
                        "license": "CC0-1.0 ...", "attribution": "...", "source_url": "..."}}}

(every map but ``base_color`` optional; paths relative to the folder; a file is listed only once
it was downloaded whole and its checksum matched). :func:`open_material_source` opens one (or
``"procedural"``: :class:`ProceduralSource`); each source's ``sample(rng, kind)`` gives a random
material for an ``"object"`` or a ``"floor"`` from an explicit rng.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from kubric.core.pbr_materials import (
    IMAGE_MAPS,
    PATTERNS,
    ImageMaterial,
    sample_procedural_material,
)
from kubric.errors import InputError

MANIFEST = "materials.json"
PROCEDURAL = "procedural"
#: pattern frequency (cells over the generated coordinates) of objects and of floors (the dome
#: spans tens of metres), and image repeats per UV unit
OBJECT_SCALES, FLOOR_SCALES = (2.0, 8.0), (20.0, 60.0)
OBJECT_UV_REPEATS, FLOOR_UV_REPEATS = (1.0, 3.0), (8.0, 24.0)
KINDS = ("object", "floor")


def _check_kind(kind):
    if kind not in KINDS:
        raise ValueError(f"material kind {kind!r}; allowed: {list(KINDS)}")


class ProceduralSource:
    """The built-in source: :func:`~kubric.core.pbr_materials.sample_procedural_material` over
    ``patterns``."""

    name = PROCEDURAL

    def __init__(self, patterns=PATTERNS):
        self.patterns = tuple(patterns)

    def sample(self, rng, kind: str = "object"):
        _check_kind(kind)
        scales = OBJECT_SCALES if kind == "object" else FLOOR_SCALES
        return sample_procedural_material(rng, self.patterns, scales)


class ImageSource:
    """A folder of PBR image sets (module doc)."""

    def __init__(self, root: Path, manifest: dict):
        self.root = Path(root)
        self.name = str(manifest.get("name", self.root.name))
        self.materials = manifest["materials"]
        self.ids = sorted(self.materials)

    def create(self, material_id: str, uv_scale: float = 1.0) -> ImageMaterial:
        """The :class:`ImageMaterial` of ``material_id`` with absolute file names."""
        if material_id not in self.materials:
            raise KeyError(f"material {material_id!r} is not in {str(self.root)!r}; "
                           f"it has {len(self.ids)}: {self.ids[:5]}…")
        entry = self.materials[material_id]
        maps = {k: str(self.root / v) for k, v in entry["maps"].items()}
        return ImageMaterial(
            name=material_id, base_color=maps["base_color"],
            roughness_map=maps.get("roughness", ""), metallic_map=maps.get("metallic", ""),
            normal_map=maps.get("normal", ""), displacement_map=maps.get("displacement", ""),
            uv_scale=uv_scale, material_id=material_id, license=str(entry.get("license", "")),
            attribution=str(entry.get("attribution", "")),
            source_url=str(entry.get("source_url", "")))

    def sample(self, rng, kind: str = "object") -> ImageMaterial:
        _check_kind(kind)
        material_id = self.ids[rng.randint(len(self.ids))]
        lo, hi = OBJECT_UV_REPEATS if kind == "object" else FLOOR_UV_REPEATS
        return self.create(material_id, float(rng.uniform(lo, hi)))


def read_manifest(root: Path) -> dict:
    """The checked ``materials.json`` of ``root``; InputError (one line) when it is missing or
    malformed, or when a listed file is missing or has another size than recorded."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise InputError(f"{str(root)!r} is no material source: no {MANIFEST} (build one with "
                         "`kubric assets materials polyhaven|ambientcg --out DIR`)")
    try:
        manifest = json.loads(path.read_text())
        materials = manifest["materials"]
        for material_id, entry in materials.items():
            unknown = sorted(set(entry["maps"]) - set(IMAGE_MAPS))
            if "base_color" not in entry["maps"] or unknown:
                raise ValueError(f"material {material_id!r}: maps need base_color and may "
                                 f"hold {list(IMAGE_MAPS)}, got {sorted(entry['maps'])}")
            for rel, info in entry["files"].items():
                f = Path(root) / rel
                if not f.is_file() or f.stat().st_size != int(info["size"]):
                    raise ValueError(f"file {rel!r} of material {material_id!r} is missing or "
                                     f"not {int(info['size'])} bytes")
    except (json.JSONDecodeError, KeyError, TypeError, AttributeError, ValueError) as err:
        raise InputError(f"{str(path)!r}: bad material source ({type(err).__name__}: "
                         f"{err})") from None
    if not materials:
        raise InputError(f"{str(path)!r}: the material source holds no material")
    return manifest


def open_material_source(location, patterns=PATTERNS):
    """``"procedural"`` → :class:`ProceduralSource` (``patterns``), a folder →
    :class:`ImageSource`."""
    if str(location) == PROCEDURAL:
        return ProceduralSource(patterns)
    root = Path(location)
    return ImageSource(root, read_manifest(root))


def derived_rng(seed: int) -> np.random.RandomState:
    """The rng of a scene's random materials: derived from the seed, so that drawing materials
    changes no other number of the scene."""
    return np.random.RandomState([int(seed), 0x6D617472])
