"""Per-pixel material and part ids from the renderer's labels and the scene model. Pure numpy.

Two tables, stored in ``metadata.json["metadata"]`` (1-based ids; 0 = nothing hit):

* ``materials``: the distinct materials of the scene's physical assets, in ``scene.assets``
  order, each described by ``type`` (``PrincipledBSDFMaterial``, ``FlatMaterial``, or
  ``file`` for a mesh file's own material) and its parameters (``color`` linear RGB or
  ``texture`` file name without its folder, ``metallic``, ``roughness``, ``ior``,
  ``transmission`` …; ``asset``: the asset of a file material; a procedural or image PBR
  material: its ``describe()``, :mod:`kubric.core.pbr_materials`). Assets whose materials
  describe the same are one entry (two red rubber spheres share an id). An asset has one
  material: a mesh file with several materials counts as one ``file`` entry.
* ``parts``: every physical asset as ``{"object", "part"}``: an articulated object's link
  (``object`` = the base's name, ``part`` = the URDF link name, ``""`` for the base link); a
  skinned character's body parts (``part`` = a bone name: one entry per bone that is the body
  part of some face, :meth:`~kubric.core.characters.Character.triangle_bones`, in bone order);
  any other asset is one part of itself (``part`` ``""``).

Layers ``material_ids`` and ``part_ids`` (kind ``labels``): the id of the surface seen at each
pixel centre; on a character, the body part of the face its ray hits on the mesh skinned at
that frame (:func:`character_part_ids`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence

import numpy as np

from kubric.annotations.segmentation import instance_labels
from kubric.core import camera_geometry as geo
from kubric.core import materials
from kubric.core.characters import Character
from kubric.core.color import Color
from kubric.core.objects import PhysicalObject

_PARAMETERS = ("metallic", "specular", "roughness", "ior", "transmission", "holdout")


def describe_material(asset) -> dict:
    """The JSON-able description of ``asset``'s material (module doc)."""
    material = asset.material
    if isinstance(material, materials.UndefinedMaterial) or material is None:
        return {"type": "file", "asset": getattr(asset, "asset_id", "") or asset.name}
    if hasattr(material, "describe"):  # kubric.core.pbr_materials: plain data of its own
        return material.describe()
    out = {"type": type(material).__name__}
    color = getattr(material, "color", None)
    if isinstance(color, Color):
        out["color"] = [round(float(c), 6) for c in color.rgb]
    elif isinstance(color, materials.Texture):
        out["texture"] = os.path.basename(str(color.filename))
    for name in _PARAMETERS:
        if hasattr(material, name):
            value = getattr(material, name)
            out[name] = value if isinstance(value, bool) else round(float(value), 6)
    return out


def material_table(assets: Sequence) -> tuple[list[dict], dict]:
    """(table, {asset: 1-based id}) over the physical assets of ``assets``."""
    table, ids, index = [], {}, {}
    for asset in assets:
        if isinstance(asset, PhysicalObject):
            key = json.dumps(describe_material(asset), sort_keys=True)
            if key not in index:
                table.append(json.loads(key))
                index[key] = len(table)
            ids[asset] = index[key]
    return table, ids


def part_table(assets: Sequence) -> tuple[list[dict], dict]:
    """(table, {asset: 1-based id}) over the physical assets of ``assets``; a character's value
    is ``{bone index: 1-based id}`` (its body parts)."""
    table, ids = [], {}
    for asset in assets:
        if isinstance(asset, Character):
            bones = np.unique(asset.triangle_bones())
            ids[asset] = {}
            for bone in bones.tolist():
                table.append({"object": asset.name, "part": asset.bone_names[bone]})
                ids[asset][bone] = len(table)
        elif isinstance(asset, PhysicalObject):
            meta = asset.metadata
            table.append({"object": str(meta.get("articulated_base", asset.name)),
                          "part": str(meta.get("articulated_link", ""))})
            ids[asset] = len(table)
    return table, ids


def character_part_ids(scene, depth, segmentation, part_ids, ids: dict, anchor,
                       frames: Sequence[int] | None = None) -> None:
    """Write into ``part_ids`` (T, H, W, 1) each character pixel's body part (``ids`` from
    :func:`part_table`): the part of the face its ray hits on the mesh skinned at that frame,
    found by ``anchor`` (:func:`kubric.annotations.character_tracks.anchor_queries`' signature,
    as :func:`kubric.annotations.scene_flow.scene_flow` takes it)."""
    characters = [a for a in scene.assets if isinstance(a, Character)]
    if not characters:
        return
    d = np.asarray(depth, np.float64)
    lab = np.asarray(segmentation)
    d, lab = (a[..., 0] if a.ndim == 4 else a for a in (d, lab))
    t_, h, w = d.shape
    frames = list(scene.frames if frames is None else frames)
    labels = dict(zip(scene.assets, instance_labels(scene.assets).tolist(), strict=True))
    centres = geo.pixel_centres(h, w)
    for t, frame in enumerate(frames):
        hit = d[t] < geo.BACKGROUND_DEPTH
        points = geo.unproject_pixels(scene.camera, centres, np.where(hit, d[t], 0.0), frame)
        for character in characters:
            sel = hit & (lab[t] == labels[character])
            if not sel.any():
                continue
            tri, _ = anchor(character, scene.camera, frame, centres[sel], points[sel], (w, h))
            lookup = np.zeros(character.num_bones, np.uint32)
            for bone, part in ids[character].items():
                lookup[bone] = part
            part_ids[t, ..., 0][sel] = lookup[character.triangle_bones()[tri]]


def id_layer(segmentation, assets: Sequence, ids: dict) -> np.ndarray:
    """(T, H, W, 1) uint32: ``ids[asset]`` of the asset each pixel's renderer label names (label
    k = ``assets[k − 1]`` or its ``segmentation_id``), 0 where nothing (or no asset of ``ids``)
    is hit."""
    seg = np.asarray(segmentation)
    seg = seg if seg.ndim == 4 else seg[..., None]
    labels = instance_labels(assets)
    lookup = np.zeros(int(max(labels.max(initial=0), seg.max(initial=0))) + 1, np.uint32)
    for label, asset in zip(labels, assets, strict=True):
        value = ids.get(asset, 0)
        lookup[label] = value if isinstance(value, int) else 0  # a character's: its own pass
    return lookup[seg]
