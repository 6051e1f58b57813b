"""The recipes' opt-in ground truth (``--set extra_layers=amodal,scene_flow,...``): what each name
adds to a scene and to its schema, and how it is computed (docs/conventions.md).

==========================  =======================================================================
name                        adds
==========================  =======================================================================
``amodal``                  layer ``amodal_segmentation`` (bit planes, :mod:`kubric.io.bitmask`):
                            bit k = instance k + 1's full silhouette; instances'
                            ``amodal_bboxes``, ``amodal_area``, ``visible_fraction``
``scene_flow``              layers ``forward_scene_flow`` / ``backward_scene_flow``: metres, world
``scene_flow_camera``       layers ``forward_scene_flow_camera`` / ``backward_scene_flow_camera``:
                            metres, the camera frame of each frame
``occlusion_boundaries``    layer ``occlusion_boundaries`` (edge bits, which side occludes)
``material_ids``            layer ``material_ids`` and the table ``metadata.materials``
``part_ids``                layer ``part_ids`` and the table ``metadata.parts`` (articulated links)
==========================  =======================================================================

Amodal masks are cast from the scene model with Embree (:mod:`kubric.renderer.scene_model_layers`),
whichever backend renders RGB; scene flow (:mod:`kubric.annotations.scene_flow`) and occlusion
boundaries (:mod:`kubric.annotations.boundaries`), material and part ids
(:mod:`kubric.annotations.materials_parts`) are computed from the backend's exact depth and
labels and the scene model's poses. None is computed unless asked for, so a default scene costs
what it did.
"""

from __future__ import annotations

from kubric.annotations.amodal import annotate_amodal
from kubric.annotations.boundaries import occlusion_boundaries
from kubric.annotations.materials_parts import (
    character_part_ids,
    id_layer,
    material_table,
    part_table,
)
from kubric.annotations.scene_flow import CAMERA_LAYERS, WORLD_LAYERS, scene_flow
from kubric.io.bitmask import pack_masks
from kubric.io.schema import Feature, Schema

EXTRA_LAYERS = ("amodal", "scene_flow", "scene_flow_camera", "occlusion_boundaries",
                "material_ids", "part_ids")
F = Feature
_FLOW_DOC = "3D displacement of the surface point seen at the pixel centre to the {} frame"
FEATURES = {
    "amodal": (
        F("amodal_segmentations", "uint16", ("T", "H", "W", 4), "layer:amodal_segmentation",
          "png", doc="bit k % 16 of channel k // 16 = pixel in instance k + 1's amodal mask "
          "(kubric.io.bitmask.unpack_masks)"),
        F("instances/amodal_bboxes", "float32", ("T", 4), "instance:amodal_bboxes",
          doc="normalised (ymin, xmin, ymax, xmax) of the amodal mask; 0 where empty"),
        F("instances/amodal_area", "int32", ("T",), "instance:amodal_area", unit="px",
          doc="amodal mask pixels per frame"),
        F("instances/visible_fraction", "float32", ("T",), "instance:visible_fraction",
          doc="visible pixels / amodal pixels (0 where the amodal mask is empty)"),
    ),
    "scene_flow": tuple(
        F(f"{d}_scene_flow", "float32", ("T", "H", "W", 3), f"layer:{d}_scene_flow", "zlib",
          unit="m", doc=_FLOW_DOC.format(w) + ", world frame; 0 where nothing is hit")
        for d, w in (("forward", "next"), ("backward", "previous"))),
    "scene_flow_camera": tuple(
        F(f"{d}_scene_flow_camera", "float32", ("T", "H", "W", 3),
          f"layer:{d}_scene_flow_camera", "zlib", unit="m",
          doc=_FLOW_DOC.format(w) + ": its position in that frame's camera minus its position "
          "in this frame's camera (Blender axes)") for d, w in (("forward", "next"),
                                                              ("backward", "previous"))),
    "occlusion_boundaries": (
        F("occlusion_boundaries", "uint8", ("T", "H", "W", 1), "layer:occlusion_boundaries",
          "png", doc="bits 0–3: boundary towards up / down / left / right; bits 4–7: this pixel "
          "occludes across it (docs/conventions.md)"),
    ),
    "material_ids": (
        F("material_ids", "uint16", ("T", "H", "W", 1), "layer:material_ids", "png",
          doc="0 = nothing hit, k = metadata materials[k − 1] (docs/conventions.md)"),
    ),
    "part_ids": (
        F("part_ids", "uint16", ("T", "H", "W", 1), "layer:part_ids", "png",
          doc="0 = nothing hit, k = metadata parts[k − 1]: {object, part (URDF link or a "
          "character's bone)}"),
    ),
}


def extra_layers(value) -> tuple[str, ...]:
    """Option converter: ``"amodal,scene_flow"`` / a list / ``""`` → names of
    :data:`EXTRA_LAYERS` in that table's order."""
    if isinstance(value, str):
        value = [v for v in value.replace(" ", "").split(",") if v and v != "none"]
    if not isinstance(value, (list, tuple)) or not all(isinstance(v, str) for v in value):
        raise ValueError("expected comma-separated names")
    unknown = sorted(set(value) - set(EXTRA_LAYERS))
    if unknown:
        raise ValueError(f"unknown extra layer(s) {unknown}")
    return tuple(name for name in EXTRA_LAYERS if name in value)


extra_layers.allowed = "comma-separated names of " + ", ".join(EXTRA_LAYERS) + " (or none)"
extra_layers.__name__ = "names"


#: the names that make sense for a static scene seen from many views (scene flow needs motion)
STATIC_EXTRA_LAYERS = tuple(n for n in EXTRA_LAYERS if not n.startswith("scene_flow"))


def static_extra_layers(value) -> tuple[str, ...]:
    """Option converter of the multi-view recipes: :func:`extra_layers` without scene flow (their
    views are one instant of a static scene)."""
    names = extra_layers(value)
    flow = [n for n in names if n not in STATIC_EXTRA_LAYERS]
    if flow:
        raise ValueError(f"{flow} need motion: a multi-view scene's views show one instant")
    return names


static_extra_layers.allowed = ("comma-separated names of " + ", ".join(STATIC_EXTRA_LAYERS)
                               + " (or none)")
static_extra_layers.__name__ = "names"


def schema_with(schema: Schema, names) -> Schema:
    """``schema`` plus the features of ``names`` (same name: the scene's schema.json carries
    them, so the packer, loaders and viewer read them without the recipe)."""
    if not names:
        return schema
    added = tuple(f for name in names for f in FEATURES[name])
    return schema.extend(schema.name, added, description=f"{schema.description} With "
                         f"{', '.join(names)}.")


def add_before_relabel(scene, layers: dict, names) -> None:
    """The layers that need the renderer's own labels (scene flow, boundaries, material and part
    ids; the tables go to ``scene.metadata``)."""
    # Embree's casters (trimesh, scipy: ~1 s to import) only when a layer needs them, not with
    # the recipes nor in a scene without such layers
    if "scene_flow" in names or "scene_flow_camera" in names:
        from kubric.renderer.scene_model_layers import skinned_anchor
        flows = scene_flow(scene, layers["depth"], layers["segmentation"],
                           camera_frame="scene_flow_camera" in names, anchor=skinned_anchor)
        for key in (WORLD_LAYERS if "scene_flow" in names else ()) + \
                (CAMERA_LAYERS if "scene_flow_camera" in names else ()):
            layers[key] = flows[key]
    for name, table_of, key in (("material_ids", material_table, "materials"),
                                ("part_ids", part_table, "parts")):
        if name in names:
            table, ids = table_of(scene.assets)
            scene.metadata[key] = table
            layers[name] = id_layer(layers["segmentation"], scene.assets, ids)
            if name == "part_ids":  # a character's body parts, by the face each ray hits
                from kubric.renderer.scene_model_layers import skinned_anchor
                character_part_ids(scene, layers["depth"], layers["segmentation"],
                                   layers[name], ids, anchor=skinned_anchor)
    if "occlusion_boundaries" in names:
        layers["occlusion_boundaries"] = occlusion_boundaries(layers["depth"],
                                                              layers["segmentation"])


def add_after_relabel(scene, layers: dict, names, instances) -> None:
    """The amodal layer and annotations (instance k = bit k, the relabelled order)."""
    if "amodal" in names:
        from kubric.renderer.scene_model_layers import amodal_masks
        masks = amodal_masks(scene, instances)
        annotate_amodal(masks, layers["segmentation"], instances)
        layers["amodal_segmentation"] = pack_masks(masks)
