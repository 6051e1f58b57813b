"""glTF / GLB sources keep their own PBR materials (``kubric assets convert``, ``objaverse``).

A glTF file is read by trimesh as one triangle mesh per (mesh, material) primitive with the scene
graph's transforms applied. The converter writes those parts back as **one GLB primitive each,
with its own material**, instead of baking them into one texture (what the OBJ path does), so
what glTF's metallic-roughness model says survives:

* base colour: ``baseColorTexture`` × ``baseColorFactor``;
* ``metallicRoughnessTexture`` (G = roughness, B = metallic) × ``metallicFactor`` /
  ``roughnessFactor`` (glTF's default 1 when absent);
* ``normalTexture``, ``occlusionTexture``, ``emissiveTexture`` / ``emissiveFactor``;
* ``alphaMode`` (``OPAQUE`` | ``MASK`` with ``alphaCutoff`` | ``BLEND``) and ``doubleSided``.

Blender's glTF importer turns each into a Principled BSDF (the renderer joins the parts into one
object with several material slots). Not kept: material extensions (``KHR_materials_*``),
``KHR_texture_transform``, a second UV set, texture samplers (Blender repeats and filters
linearly), vertex colours on textured parts, skins, morph targets and animations (the rest pose
is converted). trimesh decodes no Draco / Meshopt compression and no KTX2 textures: such a file
fails (reported by the converter) or loses those parts. ``metadata["materials"]`` records, per
part, what its material holds (:func:`material_summary`).
"""

from __future__ import annotations

from pathlib import Path

from kubric.asset_tools.mesh_load import as_rgba, split_parts
from kubric.core.imports import uninterrupted_import
from kubric.errors import InputError

GLTF_SUFFIXES = (".glb", ".gltf")
#: glTF (y up) → Kubric (z up): (x, y, z) → (x, -z, y)
_Y_UP_TO_Z_UP = ((1, 0, 0, 0), (0, 0, -1, 0), (0, 1, 0, 0), (0, 0, 0, 1))


def is_gltf(path) -> bool:
    return Path(path).suffix.lower() in GLTF_SUFFIXES


def _factor(value, n: int, default: float) -> list[float] | float:
    """A trimesh factor (None, a number or RGBA bytes / floats) as floats in [0, 1]."""
    import numpy as np

    if value is None:
        return [default] * n if n > 1 else default
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.dtype.kind in "iu" or arr.max(initial=0) > 1.0:
        arr = arr / 255.0
    return [float(v) for v in arr[:n]] if n > 1 else float(arr[0])


def material_summary(material) -> dict:
    """What a trimesh ``PBRMaterial`` holds: ``base_color_factor`` (RGBA), ``metallic``,
    ``roughness`` (factors; glTF's default 1), which textures it has, ``alpha_mode``
    (``alpha_cutoff`` with MASK) and ``double_sided``."""
    if material is None:
        return {"material": None}
    out = {"name": str(getattr(material, "name", "") or ""),
           "base_color_factor": _factor(material.baseColorFactor, 4, 1.0),
           "metallic": _factor(material.metallicFactor, 1, 1.0),
           "roughness": _factor(material.roughnessFactor, 1, 1.0),
           "alpha_mode": str(material.alphaMode or "OPAQUE"),
           "double_sided": bool(material.doubleSided)}
    if out["alpha_mode"] == "MASK":
        out["alpha_cutoff"] = 0.5 if material.alphaCutoff is None else float(material.alphaCutoff)
    out["textures"] = [name for name, attr in (
        ("base_color", "baseColorTexture"), ("metallic_roughness", "metallicRoughnessTexture"),
        ("normal", "normalTexture"), ("occlusion", "occlusionTexture"),
        ("emissive", "emissiveTexture")) if getattr(material, attr, None) is not None]
    return out


def _part_material(part, fallback):
    """The part's glTF material (trimesh ``PBRMaterial``), or one made from ``fallback`` RGBA
    (dielectric) for a part without any, or None (a part with vertex colours or nothing)."""
    from trimesh.visual.material import PBRMaterial
    from trimesh.visual.texture import TextureVisuals

    vis = part.visual
    mat = getattr(vis, "material", None)
    if isinstance(vis, TextureVisuals) and mat is not None:
        if not isinstance(mat, PBRMaterial):
            mat = mat.to_pbr()
            vis.material = mat
        return mat
    if vis.kind in ("vertex", "face") or fallback is None:
        return None
    mat = PBRMaterial(baseColorFactor=fallback, metallicFactor=0.0, roughnessFactor=0.5)
    part.visual = TextureVisuals(material=mat)
    return mat


def load_gltf_parts(path: str, scale=1.0, color=None):
    """Load a glTF / GLB file as z-up parts that keep their materials.

    Returns ``(geometry, parts, look)``: ``geometry`` one plain trimesh of every part (for the
    collision and mass computations), ``parts`` the textured / coloured trimeshes (same frame),
    ``look`` = ``{"appearance": "gltf_pbr", "materials": [summary per part]}`` (or
    ``"vertex_color"`` / ``"none"`` when no part has a material). ``color``: fallback RGBA for
    parts without a material.
    """
    import numpy as np
    trimesh = uninterrupted_import("trimesh")
    fallback = None if color is None else as_rgba(color, f"color of {path}")
    resolver = trimesh.resolvers.FilePathResolver(path, allow_anywhere=True)
    parts = split_parts(trimesh.load(path, process=True, resolver=resolver))
    factors = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,))
    if not np.all(factors > 0):
        raise InputError(f"scale must be positive, got {scale!r}")
    transform = np.diag([*factors, 1.0]) @ np.asarray(_Y_UP_TO_Z_UP, dtype=np.float64)
    summaries = []
    for part in parts:
        part.apply_transform(transform)
        summaries.append(material_summary(_part_material(part, fallback)))
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    geometry = trimesh.Trimesh(np.concatenate([p.vertices for p in parts]),
                               np.concatenate([p.faces + o for p, o in
                                               zip(parts, offsets[:-1], strict=True)]),
                               process=False)
    if len(geometry.faces) == 0 or not np.all(np.isfinite(geometry.vertices)):
        raise InputError("empty mesh or non-finite vertex coordinates")
    if np.min(geometry.extents) <= 0:
        raise InputError(f"degenerate (flat) mesh with extents {geometry.extents.tolist()}")
    if all(s == {"material": None} for s in summaries):
        kinds = {p.visual.kind for p in parts}
        return geometry, parts, {"appearance": "vertex_color" if kinds & {"vertex", "face"}
                                 else "none"}
    return geometry, parts, {"appearance": "gltf_pbr", "materials": summaries}


def normalise_extent(geometry, parts, max_extent: float) -> float:
    """Scale ``geometry`` and ``parts`` in place about the origin so that the largest side of
    the bounding box is ``max_extent`` metres; returns the factor applied."""
    import numpy as np

    if not max_extent > 0:
        raise InputError(f"max_extent must be a positive length in metres, got {max_extent!r}")
    factor = float(max_extent) / float(np.max(geometry.extents))
    for mesh in (geometry, *parts):
        mesh.apply_scale(factor)
    return factor
