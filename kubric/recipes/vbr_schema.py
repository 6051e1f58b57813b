"""The ``vbr`` recipe's output contract (video-based reconstruction, :mod:`kubric.recipes.vbr`).

A vbr scene is a video, so the schema starts from MOVi's (:data:`kubric.recipes.movi_schema.
MOVI_BASE`): the same names where the meaning is the same (``video``, ``segmentations``,
``forward_flow`` / ``backward_flow`` with their ranges, ``camera/*`` per frame, the instances'
poses, boxes and visibility, collision events), so the ``video``, ``frames`` and ``nerf_rays``
tasks and code written for MOVi read vbr datasets. Differences from MOVi:

* ``depth`` is the scene's float32 samples (zlib), bit-exact, as in the multi-view schemas, not
  quantised to uint16 (pixels that see no surface hold ``metadata/background_depth``); there is
  no ``metadata/depth_range``.
* The object is one instance per part: a rigid object is one instance; an articulated one is its
  base (the URDF's root link) and one instance per other link, each with its own segmentation
  label. ``instances/articulated_link`` names a part's URDF link and ``instances/
  articulated_base`` the ``instances/asset_id`` of its base; both are ``""`` for the base and for
  a rigid object (the scene directory writes them for link parts only).
* The scene's choices: ``metadata/object_type`` (rigid / articulated / character),
  ``metadata/object_model`` (KuBasic shape, asset id, URDF model, or ``<character>/<clip>``),
  ``metadata/background`` (the colour, ``#rrggbbaa``).

The LASR sequence in ``lasr/`` is an export of these layers (:mod:`kubric.datasets.exports.
lasr`) and is not packed.
"""

from __future__ import annotations

from kubric.io.schema import Feature, register_schema
from kubric.recipes.movi_schema import MOVI_BASE

F = Feature

VBR = register_schema(MOVI_BASE.extend("vbr", (
    F("metadata/background", "str", (), "meta:background", "text",
      doc="background colour '#rrggbbaa'"),
    F("metadata/background_depth", "float32", (), "meta:background_depth", unit="m",
      doc="depth of pixels whose ray hits no surface"),
    F("metadata/object_type", "int64", (), "meta:object_type", "class_label",
      names=("rigid", "articulated", "character"),
      doc="rigid object, articulated (multi-link URDF) or character (a skinned person)"),
    F("metadata/object_model", "str", (), "meta:object_model", "text",
      doc="KuBasic shape, asset id of objects_source, URDF model name, or character/clip ids"),
    F("instances/color", "float32", (3,), "instance:color", doc="linear RGB"),
    F("instances/size", "float32", (), "instance:size", unit="m",
      doc="largest extent of the object (articulated: in its rest pose)"),
    F("instances/articulated_link", "str", (), "instance:articulated_link", "text", default="",
      doc="URDF link name of an articulated object's part; '' for its base (root link) and "
          "for a rigid object"),
    F("instances/articulated_base", "str", (), "instance:articulated_base", "text",
      default="", doc="instances/asset_id of the part's base; '' for the base and for a "
                      "rigid object"),
    F("depth", "float32", ("T", "H", "W", 1), "layer:depth", "zlib", unit="m",
      doc="distance to the camera centre along the pixel's ray, the scene's float32 samples"),
), drop=("depth", "metadata/depth_range"),
    description="Video-based reconstruction (LASR): one rigid or articulated object moving and "
                "spinning; one instance per part."))
