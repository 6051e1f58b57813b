"""Scene-level settings in Blender: frame range, fps, resolution, world (background / ambient).

World node tree: ``World Output ← Mix Shader(fac = Light Path "Is Camera Ray")`` with
input 1 = ambient background (what every non-camera ray sees: lighting) and input 2 = camera
background (what the camera sees behind everything). Each is a Background shader whose colour is a
constant or an equirectangular Environment Texture (HDRI) looked up in world directions rotated by
``texture.rotation`` (XYZ Euler, radians), with strength ``texture.strength``.
"""

from __future__ import annotations

import bpy

from kubric.core.materials import Texture
from kubric.renderer.blender_materials import load_image


def build_scene(view, scene):
    bscene = view.bpy_scene
    world = bpy.data.worlds.new("kubric_world")
    bscene.world = world
    nodes, links = world.node_tree.nodes, world.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputWorld")
    mix = nodes.new("ShaderNodeMixShader")
    mix.name = "mix"
    path = nodes.new("ShaderNodeLightPath")
    for name, slot in (("ambient", 1), ("camera", 2)):
        bg = nodes.new("ShaderNodeBackground")
        bg.name = name
        links.new(bg.outputs["Background"], mix.inputs[slot])
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return bscene


def _set_background_node(world, name, value):
    nodes, links = world.node_tree.nodes, world.node_tree.links
    bg = nodes[name]
    for link in list(bg.inputs["Color"].links):
        links.remove(link)
    for n in [n for n in nodes if n.name.startswith(name + ":")]:
        nodes.remove(n)
    if isinstance(value, Texture):
        if value.mapping != "environment":
            raise ValueError(f"{value.uid}: a scene background / ambient texture must use "
                             f"mapping='environment', got {value.mapping!r}")
        tex = nodes.new("ShaderNodeTexEnvironment")
        tex.image = load_image(value)
        coords = nodes.new("ShaderNodeTexCoord")
        mapping = nodes.new("ShaderNodeMapping")
        mapping.vector_type = "VECTOR"
        mapping.inputs["Rotation"].default_value = tuple(float(v) for v in value.rotation)
        links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], bg.inputs["Color"])
        for n in (tex, coords, mapping):
            n.name = f"{name}:{n.name}"
        bg.inputs["Strength"].default_value = float(value.strength)
    else:
        bg.inputs["Color"].default_value = tuple(value)
        bg.inputs["Strength"].default_value = 1.0


def set_background(view, scene, bscene, value):
    _set_background_node(bscene.world, "camera", value)


def set_ambient(view, scene, bscene, value):
    _set_background_node(bscene.world, "ambient", value)


def set_frame_range(view, scene, bscene, value):
    """Both ends from the model (Blender pushes the other end when one crosses it)."""
    bscene.frame_end = 1048574
    bscene.frame_start = int(scene.frame_start)
    bscene.frame_end = int(scene.frame_end)


def set_frame_rate(view, scene, bscene, value):
    bscene.render.fps = int(value)
    bscene.render.fps_base = 1.0


def set_resolution(view, scene, bscene, value):
    w, h = value
    bscene.render.resolution_x, bscene.render.resolution_y = int(w), int(h)
    bscene.render.resolution_percentage = 100
    bscene.render.pixel_aspect_x = bscene.render.pixel_aspect_y = 1.0


def set_camera(view, scene, bscene, value):
    obj = value.linked_objects.get(view)
    if obj is not None:
        bscene.camera = obj


SCENE_SETTERS = {
    "frame_start": set_frame_range,
    "frame_end": set_frame_range,
    "frame_rate": set_frame_rate,
    "resolution": set_resolution,
    "camera": set_camera,
    "background": set_background,
    "ambient_illumination": set_ambient,
}
