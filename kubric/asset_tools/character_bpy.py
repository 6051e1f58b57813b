"""Extract a rigged character / animation from a glTF, FBX or BVH file with bpy's importers.

Run in a fresh process (``python -m kubric.asset_tools.character_bpy INPUT OUT.npz [y|z]``, as
:mod:`kubric.asset_tools.character_import` does): a process that already imported bpy would see
Blender's internal state. It writes ``OUT.npz`` (arrays) + ``OUT.json`` (names, facts), all in
Blender's world frame after import (Z up, metres; glTF/FBX/BVH importers convert their axes; a
BVH is read as Y up facing +Z — the usual convention — or, with ``z``, as Z up unchanged, as
Blender's own BVH exporter writes it):

- armature: ``bone_names`` (parents first), ``bone_parents``, ``bone_rest`` (J,4,4: rotation
  orthonormalised, translation = head), ``bone_tails``;
- skinned meshes (armature modifier on that armature), merged: ``vertices``, ``faces``
  (triangulated with bmesh, quads by the ``FIXED`` split), ``uv`` (per corner, when present),
  per-vertex ``skin_indices``/``skin_weights`` (≤ 8 largest bone-group weights, normalised)
  and ``weighted`` (False where a vertex has no weight on any bone);
- the armature's active action sampled at every frame of its range: ``pose_world`` (T,J,4,4).

A failure prints one line ``ERROR: <file>: <what>`` and exits 2.
"""

from __future__ import annotations

import json
import sys

import numpy as np

MAX_INFLUENCES = 8


def _fail(path, msg):
    print(f"ERROR: {path}: {msg}", flush=True)
    sys.exit(2)


def _fbx_light_workaround(bpy):
    """bpy 5.0.1's FBX importer reads ``cycles.cast_shadow`` of lights, which no longer exists:
    define it (a plain BoolProperty) so files that contain lights import."""
    import cycles.properties  # Blender's bundled Cycles add-on

    cls = cycles.properties.CyclesLightSettings
    if not hasattr(cls, "cast_shadow"):
        cls.cast_shadow = bpy.props.BoolProperty(name="Cast Shadow", default=True)


def _import(bpy, path, bvh_up="y"):
    ext = path.lower().rsplit(".", 1)[-1]
    if ext == "fbx":
        _fbx_light_workaround(bpy)
        bpy.ops.import_scene.fbx(filepath=path)
    elif ext in ("gltf", "glb"):
        bpy.ops.import_scene.gltf(filepath=path)
    elif ext == "bvh":
        axes = {"y": ("-Z", "Y"), "z": ("Y", "Z")}[bvh_up]  # file's Y up, facing +Z / as is
        bpy.ops.import_anim.bvh(filepath=path, update_scene_fps=True, update_scene_duration=True,
                                axis_forward=axes[0], axis_up=axes[1])
    else:
        _fail(path, f"unsupported extension .{ext} (glTF .gltf/.glb, .fbx, .bvh)")


def _orthonormal(m):
    u, _, vt = np.linalg.svd(m[:3, :3])
    out = np.array(m, dtype=np.float64)
    out[:3, :3] = u @ vt
    return out


def _bone_order(arm):
    order = []

    def visit(b):
        order.append(b)
        for c in sorted(b.children, key=lambda c: c.name):
            visit(c)
    for root in sorted((b for b in arm.data.bones if b.parent is None), key=lambda b: b.name):
        visit(root)
    return order


def _mesh_data(bpy, bmesh, objects, bone_index, world_of):
    verts, faces, uvs, idx, wts, weighted = [], [], [], [], [], []
    has_uv = all(o.data.uv_layers.active is not None for o in objects)
    base = 0
    for obj in objects:
        mw = np.array(world_of(obj))
        bm = bmesh.new()
        bm.from_mesh(obj.data)
        bmesh.ops.triangulate(bm, faces=bm.faces[:], quad_method="FIXED", ngon_method="EAR_CLIP")
        bm.verts.ensure_lookup_table()
        co = np.array([v.co[:] for v in bm.verts], dtype=np.float64)
        verts.append(co @ mw[:3, :3].T + mw[:3, 3])
        uv_layer = bm.loops.layers.uv.active
        for f in bm.faces:
            faces.append([base + v.index for v in f.verts])
            if has_uv:
                uvs.append([lp[uv_layer].uv[:] for lp in f.loops])
        bm.free()
        groups = {g.index: bone_index.get(g.name) for g in obj.vertex_groups}
        for v in obj.data.vertices:
            pairs = [(groups[g.group], g.weight) for g in v.groups
                     if groups.get(g.group) is not None and g.weight > 0]
            pairs.sort(key=lambda p: (-p[1], p[0]))
            pairs = pairs[:MAX_INFLUENCES]
            total = sum(w for _, w in pairs)
            weighted.append(total > 0)
            if total <= 0:
                pairs, total = [(0, 0.0)], 1.0
            row_i = [b for b, _ in pairs] + [0] * (MAX_INFLUENCES - len(pairs))
            row_w = [w / total for _, w in pairs] + [0.0] * (MAX_INFLUENCES - len(pairs))
            idx.append(row_i)
            wts.append(row_w)
        base += len(co)
    out = {"vertices": np.concatenate(verts), "faces": np.array(faces, dtype=np.int64),
           "skin_indices": np.array(idx, dtype=np.int64),
           "skin_weights": np.array(wts, dtype=np.float64), "weighted": np.array(weighted)}
    if has_uv:
        out["uv"] = np.array(uvs, dtype=np.float64)
    return out


def main(path, out, bvh_up="y"):
    # isort: off
    import bpy  # first: puts Blender's modules (bmesh) on the path
    import bmesh
    # isort: on

    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        _import(bpy, path, bvh_up)
    except Exception as err:  # noqa: BLE001 — the importer's own error, reported in one line
        _fail(path, f"the importer failed: {str(err).strip().splitlines()[-1]}")
    scene = bpy.context.scene
    arms = [o for o in scene.objects if o.type == "ARMATURE"]
    if not arms:
        _fail(path, "no armature (not a rigged character or skeletal animation)")
    arm = max(arms, key=lambda o: len(o.data.bones))
    arm_world = np.array(arm.matrix_world)
    scales = np.linalg.norm(arm_world[:3, :3], axis=0)
    if np.ptp(scales) > 1e-6 * scales.max():
        _fail(path, f"armature {arm.name!r} has a non-uniform scale {scales.round(6).tolist()}")
    bones = _bone_order(arm)
    names = [b.name for b in bones]
    index = {n: i for i, n in enumerate(names)}
    rest = np.array([_orthonormal(arm_world @ np.array(b.matrix_local)) for b in bones])
    tails = np.array([(arm_world @ np.r_[np.array(b.tail_local), 1.0])[:3] for b in bones])
    arrays = {"bone_parents": np.array([index[b.parent.name] if b.parent else -1 for b in bones]),
              "bone_rest": rest, "bone_tails": tails}
    info = {"file": path, "armature": arm.name, "bone_names": names}
    skinned = sorted((o for o in scene.objects if o.type == "MESH" and any(
        m.type == "ARMATURE" and m.object == arm for m in o.modifiers)), key=lambda o: o.name)
    info["meshes"] = [o.name for o in skinned]
    info["unskinned_meshes"] = sorted(o.name for o in scene.objects
                                      if o.type == "MESH" and o not in skinned)
    if skinned:
        arrays.update(_mesh_data(bpy, bmesh, skinned, index, lambda o: o.matrix_world))
    action = arm.animation_data.action if arm.animation_data else None
    if action is not None:
        start, end = (int(round(x)) for x in action.frame_range)
        frames = list(range(start, end + 1))
        pose = np.empty((len(frames), len(bones), 4, 4))
        pbs = [arm.pose.bones[n] for n in names]
        for t, f in enumerate(frames):
            scene.frame_set(f)
            mw = np.array(arm.matrix_world)
            for j, pb in enumerate(pbs):
                pose[t, j] = _orthonormal(mw @ np.array(pb.matrix))
        arrays["pose_world"] = pose
        info.update({"action": action.name, "frame_start": start, "frame_end": end,
                     "fps": scene.render.fps / scene.render.fps_base})
    np.savez(out, **arrays)
    with open(out[:-4] + ".json", "w") as fh:
        json.dump(info, fh)
    print("OK", flush=True)


if __name__ == "__main__":
    main(*sys.argv[1:4])
