"""Blender counterpart of :class:`kubric.core.characters.Character` (the model is the truth).

What is built for a character (rows of the Blender view's tables):

* a **mesh object** (linked to the asset: name, pose, scale, material, pass index as any object)
  holding every model vertex in the model frame (helper vertices that no face uses stay loose and
  are not rendered), the model's triangles as they are (no quads, so Blender never re-splits a
  face), the per-corner UVs, and two point attributes read by the annotation pass:
  ``kubric_rest_position`` (the rest vertex, model frame) and ``kubric_skinned`` (1.0);
* an **armature object** ``<uid>_rig``, child of the mesh object with the identity transform (so
  the armature modifier works in the model frame and the object's pose applies after skinning, as
  in the model), one bone per model bone: head, tail and roll from ``bone_rest`` / ``bone_tails``
  (``EditBone.matrix`` = ``bone_rest``), parents as the model's, not connected;
* one **vertex group** per bone with the model's normalised weights, and an Armature modifier;
* **pose keys**: ``bone_rotations`` → each pose bone's ``rotation_quaternion``; ``root_offset`` →
  the root pose bone's ``location`` (bone-local: ``R_rest_rootᵀ · offset``). Keys are linear, as
  every key of this view; quaternion signs are made continuous per bone before keying.

tests/test_characters_blender.py checks that Blender's evaluated mesh equals the model's
skinning (< 1e-5 m) at keyed frames.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from kubric.renderer.blender_utils import name_and_link

REST_ATTRIBUTE = "kubric_rest_position"
SKINNED_ATTRIBUTE = "kubric_skinned"


def rig_of(obj):
    """The armature object built for the character mesh ``obj``."""
    for child in obj.children:
        if child.type == "ARMATURE":
            return child
    raise RuntimeError(f"character {obj.name!r} has no armature child")


def deforming_mesh(asset, vertices=None, smooth: bool = True):
    """A Blender mesh of ``asset``'s triangles at ``vertices`` (default: its rest vertices) with
    its UVs and the two point attributes the annotation pass reads (module doc); shared with
    :mod:`kubric.renderer.blender_deformables`."""
    mesh = bpy.data.meshes.new(asset.uid)
    points = asset.vertices if vertices is None else vertices
    mesh.from_pydata(np.asarray(points).tolist(), [], asset.faces.tolist())
    if asset.uv is not None:
        layer = mesh.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", np.asarray(asset.uv, np.float32).reshape(-1))
    rest = mesh.attributes.new(REST_ATTRIBUTE, "FLOAT_VECTOR", "POINT")
    rest.data.foreach_set("vector", np.asarray(asset.vertices, np.float32).reshape(-1))
    flag = mesh.attributes.new(SKINNED_ATTRIBUTE, "FLOAT", "POINT")
    flag.data.foreach_set("value", np.ones(len(asset.vertices), np.float32))
    mesh.update()
    if smooth:
        mesh.shade_smooth()
    else:
        mesh.shade_flat()
    return mesh


def _armature(view, asset, parent):
    data = bpy.data.armatures.new(asset.uid + "_rig")
    rig = bpy.data.objects.new(asset.uid + "_rig", data)
    view.bpy_scene.collection.objects.link(rig)
    rig.parent = parent
    rig.matrix_parent_inverse = Matrix.Identity(4)
    layer = bpy.context.view_layer
    previous = layer.objects.active
    layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    try:
        for j, name in enumerate(asset.bone_names):
            eb = data.edit_bones.new(name)
            eb.head = tuple(asset.bone_rest[j, :3, 3])
            eb.tail = tuple(asset.bone_tails[j])
            eb.matrix = Matrix(asset.bone_rest[j].tolist())
            eb.use_connect = False
            eb.use_deform = True
            p = int(asset.bone_parents[j])
            if p >= 0:
                eb.parent = data.edit_bones[asset.bone_names[p]]
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
        layer.objects.active = previous
    for pb in rig.pose.bones:
        pb.rotation_mode = "QUATERNION"
    return rig


def _weights(obj, asset):
    groups = [obj.vertex_groups.new(name=n) for n in asset.bone_names]
    idx, wts = asset.skin_indices, asset.skin_weights
    for k in range(idx.shape[1]):
        for j, group in enumerate(groups):
            sel = np.flatnonzero((idx[:, k] == j) & (wts[:, k] > 0))
            if not len(sel):
                continue
            # vertex groups take one weight per call: group equal weights together
            values, inverse = np.unique(wts[sel, k].astype(np.float32), return_inverse=True)
            for u, value in enumerate(values):
                group.add(sel[inverse == u].tolist(), float(value), "ADD")


def build_character(view, asset):
    obj = bpy.data.objects.new(asset.uid, deforming_mesh(asset))
    name_and_link(obj, asset, view.bpy_scene.collection)
    rig = _armature(view, asset, obj)
    _weights(obj, asset)
    mod = obj.modifiers.new("Armature", "ARMATURE")
    mod.object = rig
    mod.use_vertex_groups = True
    mod.use_bone_envelopes = False
    mod.use_deform_preserve_volume = False
    return obj


# ---------------------------------------------------------------------------------- pose
def _root_location(asset, offset):
    root = int(np.flatnonzero(asset.bone_parents < 0)[0])
    return asset.bone_rest[root, :3, :3].T @ np.asarray(offset, np.float64), root


def set_bone_rotations(view, asset, obj, value):
    rig = rig_of(obj)
    for name, q in zip(asset.bone_names, np.asarray(value, np.float64), strict=True):
        rig.pose.bones[name].rotation_quaternion = tuple(float(c) for c in q)


def set_root_offset(view, asset, obj, value):
    loc, root = _root_location(asset, value)
    rig_of(obj).pose.bones[asset.bone_names[root]].location = tuple(float(c) for c in loc)


def _continuous(keys: dict, frame: int) -> np.ndarray:
    """The (J, 4) key at ``frame`` with each bone's sign continuous with the earlier keys."""
    prev = None
    for f in sorted(keys):
        q = np.asarray(keys[f], np.float64)
        if prev is not None:
            q = np.where(np.sum(q * prev, axis=1, keepdims=True) < 0, -q, q)
        prev = q
        if f == frame:
            return q
    raise KeyError(frame)


def _key_bone_rotations(view, asset, obj, frame):
    rig = rig_of(obj)
    q = _continuous(asset.keyframes["bone_rotations"], frame)
    for name, row in zip(asset.bone_names, q, strict=True):
        pb = rig.pose.bones[name]
        pb.rotation_quaternion = tuple(float(c) for c in row)
        pb.keyframe_insert("rotation_quaternion", frame=frame)
    set_bone_rotations(view, asset, obj, asset.bone_rotations)


_key_bone_rotations.blender_paths = lambda obj: [
    (pb, "rotation_quaternion") for pb in rig_of(obj).pose.bones]


def _key_root_offset(view, asset, obj, frame):
    loc, root = _root_location(asset, asset.keyframes["root_offset"][frame])
    pb = rig_of(obj).pose.bones[asset.bone_names[root]]
    pb.location = tuple(float(c) for c in loc)
    pb.keyframe_insert("location", frame=frame)
    set_root_offset(view, asset, obj, asset.root_offset)


_key_root_offset.blender_paths = lambda obj: [
    (pb, "location") for pb in rig_of(obj).pose.bones if pb.parent is None]

SETTERS = {"bone_rotations": set_bone_rotations, "root_offset": set_root_offset}
KEYFRAMERS = {"bone_rotations": _key_bone_rotations, "root_offset": _key_root_offset}


def evaluated_vertices(view, asset, frame: int) -> np.ndarray:
    """(V, 3) world positions of the evaluated (deformed) Blender mesh at ``frame``."""
    obj = asset.linked_objects[view]
    view.bpy_scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    m = np.array(ev.matrix_world)
    return co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
