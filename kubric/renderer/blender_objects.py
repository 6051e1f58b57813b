"""Blender counterparts of the model's objects, cameras and lights (builders, setters, keyframers).

Every function here is a row of one of :class:`kubric.renderer.blender.Blender`'s tables
(:mod:`kubric.renderer.blender_tables`): builders ``fn(view, asset) -> bpy object``, setters
``fn(view, asset, bpy_obj, value)``, keyframers ``fn(view, asset, bpy_obj, frame)``.

Geometry conventions (must agree with the model):
  * Cube: a mesh with vertices at ±1 (bounds ±1) and Blender's default cube UVs, flat shaded.
  * Sphere: radius 1 UV sphere with 128 segments × 64 rings, smooth shaded (the surface lies within
    1 − cos(π/128) ≈ 3·10⁻⁴ of the true sphere, relative to the radius).
  * FileBasedObject: the file's meshes are joined into ONE mesh object whose local frame is the
    file's frame (hierarchy transforms baked in), so its pose and scale come from the model only.
    OBJ, PLY and STL are imported without axis conversion (file x, y, z = Blender x, y, z); glTF and
    FBX importers convert their Y-up convention to Blender's Z-up (override with
    ``render_import_kwargs``). ``.blend`` files: every mesh object of the file is appended, or
    with upstream's ``render_import_kwargs={"filepath", "directory", "filename"}`` the one object
    ``filename`` from ``directory`` = ``<file>.blend/Object`` (``bpy.ops.wm.append``).
  * Cameras: ``sensor_fit='HORIZONTAL'`` so ``sensor_width`` is the horizontal size and
    ``shift_x``/``shift_y`` are in units of the sensor width (kubric.core.camera_geometry).
  * Lights shine along their local −Z axis (Blender's convention and the model's).

Keyframes are inserted with LINEAR interpolation (the view sets Blender's preference for new keys
and re-checks every F-curve before rendering), so Blender's motion between keys matches the model's
linear interpolation. Quaternions are interpolated component-wise by Blender but by slerp in the
model: the two agree exactly at keyed frames (the simulator keys every frame) and differ by
O(angle³) in between, which only matters for sub-frame motion blur.
"""

from __future__ import annotations

import os

import bmesh
import bpy
import numpy as np

from kubric.renderer.blender_utils import name_and_link

_SPHERE_SEGMENTS, _SPHERE_RINGS = 128, 64


# ---------------------------------------------------------------------------------- meshes
def _mesh_object(view, asset, mesh):
    return name_and_link(bpy.data.objects.new(asset.uid, mesh), asset, view.bpy_scene.collection)


def build_cube(view, asset):
    mesh = bpy.data.meshes.new(asset.uid)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_cube(bm, size=2.0, calc_uvs=True)
    bm.to_mesh(mesh)
    bm.free()
    return _mesh_object(view, asset, mesh)


def build_sphere(view, asset):
    mesh = bpy.data.meshes.new(asset.uid)
    bm = bmesh.new()
    bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=_SPHERE_SEGMENTS, v_segments=_SPHERE_RINGS,
                              radius=1.0, calc_uvs=True)
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    return _mesh_object(view, asset, mesh)


def _import_obj(path, **kw):
    kw.setdefault("forward_axis", "Y")
    kw.setdefault("up_axis", "Z")
    bpy.ops.wm.obj_import(filepath=path, **kw)


def _import_ply(path, **kw):
    kw.setdefault("forward_axis", "Y")
    kw.setdefault("up_axis", "Z")
    bpy.ops.wm.ply_import(filepath=path, **kw)


def _import_stl(path, **kw):
    kw.setdefault("forward_axis", "Y")
    kw.setdefault("up_axis", "Z")
    bpy.ops.wm.stl_import(filepath=path, **kw)


def _import_gltf(path, **kw):
    bpy.ops.import_scene.gltf(filepath=path, **kw)


def _import_fbx(path, **kw):
    bpy.ops.import_scene.fbx(filepath=path, **kw)


#: the keywords of upstream's .blend import (``bpy.ops.wm.append``): ``directory`` is
#: ``<file>.blend/Object`` and ``filename`` an object name in it; ``filepath`` (their join) optional
BLEND_APPEND_KEYS = ("directory", "filename", "filepath")


def _import_blend(path, **kw):
    if not kw:  # every object of the file
        with bpy.data.libraries.load(path, link=False) as (src, dst):
            dst.objects = list(src.objects)
        for obj in dst.objects:
            if obj is not None:
                bpy.context.scene.collection.objects.link(obj)
        return
    unknown = sorted(set(kw) - set(BLEND_APPEND_KEYS))
    if unknown or "directory" not in kw or "filename" not in kw:
        raise ValueError(f".blend render_import_kwargs must be bpy.ops.wm.append's directory= "
                         f"('<file>.blend/Object') and filename= (an object name), filepath= "
                         f"optional; got {sorted(kw)}")
    directory = os.path.normpath(str(kw["directory"]))
    library, _, kind = directory.rpartition(os.sep)
    if os.path.normpath(library) != os.path.normpath(path) or kind != "Object":
        raise ValueError(f".blend render_import_kwargs: directory {kw['directory']!r} must be "
                         f"'{path}/Object' (objects inside render_filename)")
    with bpy.data.libraries.load(path, link=False) as (src, _):
        names = list(src.objects)
    if kw["filename"] not in names:
        raise ValueError(f".blend render_import_kwargs: {path!r} has no object "
                         f"{kw['filename']!r}; objects: {names}")
    args = {"directory": directory + os.sep, "filename": str(kw["filename"])}
    if "filepath" in kw:
        args["filepath"] = str(kw["filepath"])
    bpy.ops.wm.append(**args)


#: file extension → importer(path, **render_import_kwargs)
IMPORTERS = {
    ".obj": _import_obj, ".glb": _import_gltf, ".gltf": _import_gltf, ".ply": _import_ply,
    ".stl": _import_stl, ".fbx": _import_fbx, ".blend": _import_blend,
}


def build_file_object(view, asset):
    path = asset.render_filename
    if not path:
        raise ValueError(f"{asset.uid}: FileBasedObject.render_filename is not set; the renderer "
                         "needs a mesh file (" + ", ".join(sorted(IMPORTERS)) + ")")
    ext = os.path.splitext(path)[1].lower()
    if ext not in IMPORTERS:
        raise ValueError(f"{asset.uid}: cannot import render_filename {path!r}: extension "
                         f"{ext!r} is not one of {sorted(IMPORTERS)}")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{asset.uid}: render_filename {path!r} does not exist")
    before = set(bpy.data.objects)
    with view.quiet():
        IMPORTERS[ext](path, **dict(asset.render_import_kwargs))
    new = [o for o in bpy.data.objects if o not in before]
    meshes = [o for o in new if o.type == "MESH"]
    if not meshes:
        for o in new:
            bpy.data.objects.remove(o, do_unlink=True)
        raise ValueError(f"{asset.uid}: {path!r} contains no mesh")
    # bake every mesh's world transform into its vertices, then join them into one object
    for o in meshes:
        mat = o.matrix_world.copy()
        o.parent = None
        o.data = o.data.copy() if o.data.users > 1 else o.data
        o.data.transform(mat)
        o.matrix_world = ((1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1))
    for o in new:
        if o.type != "MESH":
            bpy.data.objects.remove(o, do_unlink=True)
    target = meshes[0]
    for o in meshes:
        if view.bpy_scene.collection not in o.users_collection:
            for coll in list(o.users_collection):
                coll.objects.unlink(o)
            view.bpy_scene.collection.objects.link(o)
    if len(meshes) > 1:
        with bpy.context.temp_override(active_object=target, object=target,
                                       selected_objects=meshes,
                                       selected_editable_objects=meshes):
            bpy.ops.object.join()
    name_and_link(target, asset, view.bpy_scene.collection)
    view.imported_materials[asset.uid] = list(target.data.materials)
    return target


# ---------------------------------------------------------------------------------- cameras
def build_perspective_camera(view, asset):
    cam = bpy.data.cameras.new(asset.uid)
    cam.type = "PERSP"
    cam.sensor_fit = "HORIZONTAL"
    cam.clip_start, cam.clip_end = 0.01, 1e5
    obj = name_and_link(bpy.data.objects.new(asset.uid, cam), asset, view.bpy_scene.collection)
    if view.scene.camera is asset:
        view.bpy_scene.camera = obj
    return obj


def build_orthographic_camera(view, asset):
    obj = build_perspective_camera(view, asset)
    obj.data.type = "ORTHO"
    return obj


def data_setter(attr, convert=float):
    def setter(view, asset, obj, value):
        setattr(obj.data, attr, convert(value))
    return setter


def set_dof(view, asset, obj, value):
    obj.data.dof.use_dof = bool(value)


def set_focus_distance(view, asset, obj, value):
    obj.data.dof.focus_distance = float(value)


def set_fstop(view, asset, obj, value):
    obj.data.dof.aperture_fstop = float(value)


# ---------------------------------------------------------------------------------- lights
def _light_builder(kind):
    def build(view, asset):
        light = bpy.data.lights.new(asset.uid, kind)
        if kind == "AREA":
            light.shape = "RECTANGLE"
        return name_and_link(bpy.data.objects.new(asset.uid, light), asset,
                             view.bpy_scene.collection)
    return build


build_sun = _light_builder("SUN")
build_point = _light_builder("POINT")
build_spot = _light_builder("SPOT")
build_area = _light_builder("AREA")


def set_light_color(view, asset, obj, value):
    obj.data.color = tuple(value)[:3]


# ---------------------------------------------------------------------------------- poses
def set_location(view, asset, obj, value):
    obj.location = tuple(float(v) for v in value)


def set_rotation(view, asset, obj, value):
    obj.rotation_quaternion = tuple(float(v) for v in value)


def set_scale(view, asset, obj, value):
    obj.scale = tuple(float(v) for v in value)


def set_object_material(view, asset, obj, value):
    view.assign_material(asset, obj, value)


# ---------------------------------------------------------------------------------- keyframes
def keyframer(target, data_path, convert=None, setter=None):
    """A keyframer that writes the model's keyframe value to ``target(obj).data_path``, inserts a
    Blender keyframe there and restores the current (un-keyed) value.

    ``convert`` maps the model value to Blender's; ``setter(view, asset, obj, value)`` restores the
    current value (defaults to plain assignment).
    """
    convert = convert or (lambda v: tuple(float(x) for x in np.ravel(v)) if np.ndim(v) else
                          float(v))

    def key(view, asset, obj, frame):
        name = key.model_name
        owner = target(obj)
        setattr(owner, data_path, convert(asset.keyframes[name][frame]))
        owner.keyframe_insert(data_path, frame=frame)
        setattr(owner, data_path, convert(getattr(asset, name)))
    key.model_name = None
    key.blender_path = lambda obj: (target(obj), data_path)
    return key


def keyframe_rows(rows):
    """{model name: keyframer} with each keyframer told its model property name."""
    for name, key in rows.items():
        key.model_name = name
    return rows


def _self(obj):
    return obj


def _data(obj):
    return obj.data


def continuous_quaternions(keys: dict) -> dict:
    """{frame: WXYZ} with signs flipped so consecutive keys have a non-negative dot product.

    q and −q are the same rotation, but Blender interpolates quaternion components linearly, so
    a sign flip between keys would swing the object through a wrong path between frames (visible
    with motion blur). Keyed frames themselves are unaffected.
    """
    out, prev = {}, None
    for f in sorted(keys):
        q = np.asarray(keys[f], dtype=np.float64)
        if prev is not None and float(np.dot(q, prev)) < 0:
            q = -q
        out[f] = prev = q
    return out


def _key_quaternion(view, asset, obj, frame):
    q = continuous_quaternions(asset.keyframes["quaternion"])[frame]
    obj.rotation_quaternion = tuple(float(v) for v in q)
    obj.keyframe_insert("rotation_quaternion", frame=frame)
    obj.rotation_quaternion = tuple(float(v) for v in asset.quaternion)


_key_quaternion.blender_path = lambda obj: (obj, "rotation_quaternion")


def object_keyframers():
    return keyframe_rows({"position": keyframer(_self, "location"),
                          "quaternion": _key_quaternion})


def physical_keyframers():
    return keyframe_rows({"scale": keyframer(_self, "scale")})


def camera_keyframers():
    return keyframe_rows({"focal_length": keyframer(_data, "lens"),
                          "shift_x": keyframer(_data, "shift_x"),
                          "shift_y": keyframer(_data, "shift_y")})


def light_keyframers():
    return keyframe_rows({"intensity": keyframer(_data, "energy"),
                          "color": keyframer(_data, "color",
                                             lambda v: tuple(float(x) for x in v[:3]))})
