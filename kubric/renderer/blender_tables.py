"""The Blender renderer's mapping tables: one row per model class (builders) or per property
(setters, keyframers), the rows of :class:`kubric.core.views.TableView` that
:class:`kubric.renderer.blender.Blender` replays the scene through.

* ``BUILDERS``: ``{ModelClass: fn(view, asset) -> bpy object}`` (``None``: built by its user);
* ``SETTERS``: ``{ModelClass: {property: fn(view, asset, bpy_obj, value)}}``;
* ``KEYFRAMERS``: ``{ModelClass: {property: keyframer}}`` (a property animated in Blender).

The rows live in the per-kind modules (objects, cameras and lights in ``blender_objects``,
materials in ``blender_materials`` / ``blender_procedural``, the world in ``blender_world``,
characters and deformables in theirs); a new model class adds its rows here.
"""

from __future__ import annotations

from kubric.core import cameras, characters, deformables, lights, materials, objects
from kubric.core import pbr_materials as pbr
from kubric.core.scene import Scene
from kubric.renderer import blender_characters as bc
from kubric.renderer import blender_deformables as bd
from kubric.renderer import blender_materials as bm
from kubric.renderer import blender_objects as bo
from kubric.renderer import blender_procedural as bpr
from kubric.renderer import blender_world as bw

BUILDERS = {
    Scene: bw.build_scene,
    objects.Cube: bo.build_cube,
    objects.Sphere: bo.build_sphere,
    objects.FileBasedObject: bo.build_file_object,
    characters.Character: bc.build_character,
    deformables.Deformable: bd.build_deformable,
    cameras.PerspectiveCamera: bo.build_perspective_camera,
    cameras.OrthographicCamera: bo.build_orthographic_camera,
    lights.DirectionalLight: bo.build_sun,
    lights.PointLight: bo.build_point,
    lights.SpotLight: bo.build_spot,
    lights.RectAreaLight: bo.build_area,
    materials.PrincipledBSDFMaterial: bm.build_principled,
    materials.FlatMaterial: bm.build_flat,
    pbr.ProceduralMaterial: bpr.build,
    pbr.ImageMaterial: bpr.build,
    materials.Texture: None,  # read by the materials / world that use it
}
SETTERS = {
    Scene: bw.SCENE_SETTERS,
    objects.Object3D: {"position": bo.set_location, "quaternion": bo.set_rotation},
    objects.PhysicalObject: {"scale": bo.set_scale, "material": bo.set_object_material},
    cameras.Camera: {"shift_x": bo.data_setter("shift_x"),
                     "shift_y": bo.data_setter("shift_y")},
    cameras.PerspectiveCamera: {"focal_length": bo.data_setter("lens"),
                                "sensor_width": bo.data_setter("sensor_width"),
                                "use_dof": bo.set_dof,
                                "focus_distance": bo.set_focus_distance,
                                "aperture_fstop": bo.set_fstop},
    cameras.OrthographicCamera: {"orthographic_scale": bo.data_setter("ortho_scale")},
    lights.Light: {"color": bo.set_light_color, "intensity": bo.data_setter("energy")},
    lights.DirectionalLight: {"shadow_softness": bo.data_setter("angle")},
    lights.SpotLight: {"spot_size": bo.data_setter("spot_size"),
                       "spot_blend": bo.data_setter("spot_blend")},
    lights.RectAreaLight: {"width": bo.data_setter("size"),
                           "height": bo.data_setter("size_y")},
    materials.PrincipledBSDFMaterial: bm.PRINCIPLED_SETTERS,
    materials.FlatMaterial: bm.FLAT_SETTERS,
    pbr.ProceduralMaterial: bpr.PROCEDURAL_SETTERS,
    pbr.ImageMaterial: bpr.IMAGE_SETTERS,
    characters.Character: bc.SETTERS,
    deformables.Deformable: bd.SETTERS,
}
KEYFRAMERS = {
    objects.Object3D: bo.object_keyframers(),
    objects.PhysicalObject: bo.physical_keyframers(),
    cameras.PerspectiveCamera: bo.camera_keyframers(),
    lights.Light: bo.light_keyframers(),
    materials.PrincipledBSDFMaterial: bm.PRINCIPLED_KEYFRAMERS,
    materials.FlatMaterial: bm.FLAT_KEYFRAMERS,
    characters.Character: bc.KEYFRAMERS,
    deformables.Deformable: bd.KEYFRAMERS,
}
