"""Per-pixel material and part ids from the renderer's labels and the scene model. Pure numpy.

Two tables, stored in ``metadata.json["metadata"]`` (1-based ids; 0 = nothing hit):

* ``materials``: the distinct materials of the scene's physical assets, in ``scene.assets``
  order, each described by ``type`` (``PrincipledBSDFMaterial``, ``FlatMaterial``, or
  ``file`` for a mesh file's own material) and its parameters (``color`` linear RGB or
  ``texture`` file name without its folder, ``metallic``, ``roughness``, ``ior``,
  ``transmission`` …; ``asset``: the asset of a file material). Assets whose materials
  describe the same are one entry (two red rubber spheres share an id). An asset has one
  material: a mesh file with several materials counts as one ``file`` entry.
* ``parts``: every physical asset as ``{"object", "part"}``: an articulated object's link
  (``object`` = the base's name, ``part`` = the URDF link name, ``""`` for the base link);
  any other asset is one part of itself (``part`` ``""``).

Layers ``material_ids`` and ``part_ids`` (kind ``labels``): the id of the surface seen at each
pixel centre.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence

import numpy as np

from kubric.annotations.segmentation import instance_labels
from kubric.core import materials
from kubric.core.color import Color
from kubric.core.objects import PhysicalObject

_PARAMETERS = ("metallic", "specular", "roughness", "ior", "transmission", "holdout")


def describe_material(asset) -> dict:
    """The JSON-able description of ``asset``'s material (module doc)."""
    material = asset.material
    if isinstance(material, materials.UndefinedMaterial) or material is None:
        return {"type": "file", "asset": getattr(asset, "asset_id", "") or asset.name}
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
    """(table, {asset: 1-based id}) over the physical assets of ``assets``."""
    table, ids = [], {}
    for asset in assets:
        if isinstance(asset, PhysicalObject):
            meta = asset.metadata
            table.append({"object": str(meta.get("articulated_base", asset.name)),
                          "part": str(meta.get("articulated_link", ""))})
            ids[asset] = len(table)
    return table, ids


def id_layer(segmentation, assets: Sequence, ids: dict) -> np.ndarray:
    """(T, H, W, 1) uint32: ``ids[asset]`` of the asset each pixel's renderer label names (label
    k = ``assets[k − 1]`` or its ``segmentation_id``), 0 where nothing (or no asset of ``ids``)
    is hit."""
    seg = np.asarray(segmentation)
    seg = seg if seg.ndim == 4 else seg[..., None]
    labels = instance_labels(assets)
    lookup = np.zeros(int(max(labels.max(initial=0), seg.max(initial=0))) + 1, np.uint32)
    for label, asset in zip(labels, assets, strict=True):
        lookup[label] = ids.get(asset, 0)
    return lookup[seg]
