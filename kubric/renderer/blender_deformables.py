"""Blender counterpart of :class:`kubric.core.deformables.Deformable` (the model is the truth).

What is built for a deformable (rows of the Blender view's tables):

* a **mesh object** with the identity transform (the simulated vertices are world positions, so
  the model's pose rows are replaced by no-ops) whose basis shape is the rest mesh placed by the
  model's pose, the model's triangles as they are, flat shaded (as the raycast backend draws
  them), the per-corner UVs, and the two point attributes the annotation pass reads (as for
  characters, :mod:`kubric.renderer.blender_characters`): ``kubric_rest_position`` (the rest
  vertex, model frame: object coordinates name the material point) and ``kubric_skinned`` (1.0);
* one **shape key per keyed frame** of ``simulated_vertices`` holding that frame's vertices, its
  value keyed 1 at its frame and 0 at the neighbouring keyed frames (linear keys): between two
  frames the mesh is the linear blend of their vertices, as the model interpolates, and outside
  the keyed range the end shapes hold. Cycles' Vector pass follows shape-key motion (deformation
  motion), so flow follows the simulated vertices.
"""

from __future__ import annotations

import bpy
import numpy as np

from kubric.renderer.blender_characters import deforming_mesh
from kubric.renderer.blender_utils import name_and_link

_PREFIX = "kubric_frame_"


def build_deformable(view, asset):
    mesh = deforming_mesh(asset, asset.rest_world_vertices(), smooth=False)  # flat, as raycast
    obj = bpy.data.objects.new(asset.uid, mesh)
    name_and_link(obj, asset, view.bpy_scene.collection)
    obj.shape_key_add(name="Basis", from_mix=False)
    return obj


def _key_vertices(view, asset, obj, frame):
    """Rebuild every frame's shape key and its value keys from the model's keys (cheap: a few
    dozen frames; an earlier run's stale frames disappear with it)."""
    keys = obj.data.shape_keys
    for block in [b for b in keys.key_blocks if b.name.startswith(_PREFIX)]:
        obj.shape_key_remove(block)
    if keys.animation_data is not None:
        keys.animation_data_clear()
    frames = sorted(asset.keyframes.get("simulated_vertices", {}))
    blocks = []
    for f in frames:
        block = obj.shape_key_add(name=f"{_PREFIX}{f}", from_mix=False)
        block.data.foreach_set("co", np.asarray(asset.keyframes["simulated_vertices"][f],
                                                np.float32).reshape(-1))
        blocks.append(block)
    for i, block in enumerate(blocks):
        for j in (i - 1, i, i + 1):
            if 0 <= j < len(frames):
                block.value = 1.0 if j == i else 0.0
                block.keyframe_insert("value", frame=frames[j])
    obj.data.update()


_key_vertices.blender_paths = lambda obj: []  # deletions: the next key rebuilds every shape


def _nothing(view, asset, obj, value):
    """The object's own transform stays the identity (module doc)."""


SETTERS = {"position": _nothing, "quaternion": _nothing, "scale": _nothing,
           "simulated_vertices": _nothing}
#: the pose keys are not Blender's (None: no keyframer), the vertices are shape keys
KEYFRAMERS = {"position": None, "quaternion": None, "scale": None,
              "simulated_vertices": _key_vertices}
