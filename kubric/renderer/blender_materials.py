"""Blender counterparts of the model's materials and textures (node trees for Cycles).

* :class:`~kubric.core.materials.PrincipledBSDFMaterial` → a Principled BSDF with bpy 5.0's input
  names: ``Base Color``, ``Metallic``, ``Specular IOR Level`` (← ``specular``), ``Specular Tint``
  (a colour in 5.0: the model's scalar tint t gives ``(1−t)·white + t·base colour``),
  ``Roughness``, ``IOR``, ``Transmission Weight``, ``Emission Color`` with ``Emission Strength`` 1.
  bpy 5.0 has no ``Transmission Roughness`` input: the model property is kept but has no effect.
  Nodes keep Blender's default names (``"Principled BSDF"``, ``"Material Output"``), as upstream
  Kubric's did, so scripts can look them up by name.
* :class:`~kubric.core.materials.FlatMaterial` → Emission (strength 1) seen by camera rays; other
  rays see a Transparent BSDF when ``indirect_visibility`` is False (no reflections, no shadows);
  ``holdout`` replaces the camera-ray shader by a Holdout (alpha 0 in RGBA; annotation layers still
  show the object because they are rendered with an override material). ``catch_shadows`` gives
  camera rays that hit an upward-facing point a Diffuse BSDF of albedo ``colour · catch_scale``
  (``catch_scale`` = π / E, set before each render by :mod:`kubric.renderer.blender_shadows`).
* A colour that is a :class:`~kubric.core.materials.Texture`: ``"uv"`` mapping → Image Texture on
  the mesh UVs; ``"environment"`` mapping → equirectangular lookup by the direction from the
  projection centre ``origin + (0, 0, texture.projection_height)`` to the shaded point (world
  axes, rotated by ``texture.rotation``), which lets a dome show an HDRI as floor + backdrop (with
  a height > 0 the floor shows the HDRI's ground, not its horizon row smeared radially).
  ``texture.strength`` multiplies the colour.
"""

from __future__ import annotations

import bpy

from kubric.core.materials import Texture


def load_image(texture: Texture):
    if not texture.filename:
        raise ValueError(f"{texture.uid}: Texture.filename is empty")
    try:
        return bpy.data.images.load(texture.filename, check_existing=True)
    except RuntimeError as err:
        raise ValueError(f"{texture.uid}: cannot load Texture.filename "
                         f"{texture.filename!r}: {err}") from None


#: Blender's own default node names, which upstream Kubric's materials kept and its scripts look
#: up (``material.node_tree.nodes["Principled BSDF"]``); a flat material's nodes likewise
#: ("Emission", "Holdout", "Transparent BSDF", "Light Path", "Mix Shader").
PRINCIPLED_NODE = "Principled BSDF"
OUTPUT_NODE = "Material Output"


def _new_material(asset):
    mat = bpy.data.materials.new(asset.uid)
    nodes = mat.node_tree.nodes
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    out.name = OUTPUT_NODE
    return mat, out


def texture_color_output(node_tree, texture: Texture, prefix: str):
    """Build (or reuse) the nodes that turn ``texture`` into a colour; return the colour socket."""
    nodes, links = node_tree.nodes, node_tree.links
    for n in [n for n in nodes if n.name.startswith(prefix + ":")]:
        nodes.remove(n)
    image = load_image(texture)
    if texture.mapping == "uv":
        tex = nodes.new("ShaderNodeTexImage")
        coords = nodes.new("ShaderNodeTexCoord")
        links.new(coords.outputs["UV"], tex.inputs["Vector"])
    else:
        tex = nodes.new("ShaderNodeTexEnvironment")
        geom = nodes.new("ShaderNodeNewGeometry")
        info = nodes.new("ShaderNodeObjectInfo")
        centre = nodes.new("ShaderNodeVectorMath")  # the projection centre above the origin
        centre.operation = "ADD"
        centre.inputs[1].default_value = (0.0, 0.0, float(texture.projection_height))
        sub = nodes.new("ShaderNodeVectorMath")
        sub.operation = "SUBTRACT"
        mapping = nodes.new("ShaderNodeMapping")
        mapping.vector_type = "VECTOR"
        mapping.inputs["Rotation"].default_value = tuple(float(v) for v in texture.rotation)
        links.new(info.outputs["Location"], centre.inputs[0])
        links.new(geom.outputs["Position"], sub.inputs[0])
        links.new(centre.outputs["Vector"], sub.inputs[1])
        links.new(sub.outputs["Vector"], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
        for n in (geom, info, centre, sub, mapping):
            n.name = f"{prefix}:{n.name}"
    tex.image = image
    tex.name = f"{prefix}:{tex.name}"
    scale = nodes.new("ShaderNodeMix")
    scale.data_type = "RGBA"
    scale.blend_type = "MULTIPLY"
    scale.name = f"{prefix}:strength"
    scale.inputs["Factor"].default_value = 1.0
    s = float(texture.strength)
    scale.inputs[7].default_value = (s, s, s, 1.0)
    links.new(tex.outputs["Color"], scale.inputs[6])
    return scale.outputs[2]


def _connect_color(mat, socket, value, prefix):
    """Drive ``socket`` by a constant colour or a texture."""
    links = mat.node_tree.links
    for link in list(socket.links):
        links.remove(link)
    if isinstance(value, Texture):
        links.new(texture_color_output(mat.node_tree, value, prefix), socket)
    else:
        for n in [n for n in mat.node_tree.nodes if n.name.startswith(prefix + ":")]:
            mat.node_tree.nodes.remove(n)
        socket.default_value = tuple(value)


# ---------------------------------------------------------------------------------- principled
def build_principled(view, asset):
    mat, out = _new_material(asset)
    bsdf = mat.node_tree.nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = PRINCIPLED_NODE
    mat.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    bsdf.inputs["Emission Strength"].default_value = 1.0
    return mat


def _bsdf_input(input_name):
    def setter(view, asset, mat, value):
        mat.node_tree.nodes[PRINCIPLED_NODE].inputs[input_name].default_value = float(value)
    return setter


def _set_specular_tint(view, asset, mat, value):
    color = asset.color
    base = (1.0, 1.0, 1.0) if isinstance(color, Texture) else tuple(color)[:3]
    t = float(value)
    tint = tuple((1.0 - t) + t * c for c in base) + (1.0,)
    mat.node_tree.nodes[PRINCIPLED_NODE].inputs["Specular Tint"].default_value = tint


def _set_principled_color(view, asset, mat, value):
    _connect_color(mat, mat.node_tree.nodes[PRINCIPLED_NODE].inputs["Base Color"], value, "color")
    _set_specular_tint(view, asset, mat, asset.specular_tint)


def _set_emission(view, asset, mat, value):
    mat.node_tree.nodes[PRINCIPLED_NODE].inputs["Emission Color"].default_value = tuple(value)


PRINCIPLED_SETTERS = {
    "color": _set_principled_color,
    "metallic": _bsdf_input("Metallic"),
    "specular": _bsdf_input("Specular IOR Level"),
    "specular_tint": _set_specular_tint,
    "roughness": _bsdf_input("Roughness"),
    "ior": _bsdf_input("IOR"),
    "transmission": _bsdf_input("Transmission Weight"),
    "emission": _set_emission,
}


def _color_keyframer(socket_of):
    def key(view, asset, mat, frame):
        value = asset.keyframes["color"][frame]
        if isinstance(value, Texture):
            return
        socket = socket_of(mat)
        socket.default_value = tuple(value)
        socket.keyframe_insert("default_value", frame=frame)
        if not isinstance(asset.color, Texture):
            socket.default_value = tuple(asset.color)
    key.blender_path = lambda mat: (socket_of(mat), "default_value")
    key.blender_paths = lambda mat: [key.blender_path(mat)]
    return key


PRINCIPLED_KEYFRAMERS = {
    "color": _color_keyframer(lambda m: m.node_tree.nodes[PRINCIPLED_NODE].inputs["Base Color"]),
}


# ---------------------------------------------------------------------------------- flat
def build_flat(view, asset):
    mat, out = _new_material(asset)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    emission = _named(nodes, "ShaderNodeEmission", "Emission")
    emission.inputs["Strength"].default_value = 1.0
    _named(nodes, "ShaderNodeHoldout", "Holdout")
    _named(nodes, "ShaderNodeBsdfTransparent", "Transparent BSDF")
    path = _named(nodes, "ShaderNodeLightPath", "Light Path")
    mix = _named(nodes, "ShaderNodeMixShader", "Mix Shader")
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(mix.outputs["Shader"], out.inputs["Surface"])
    _build_catch_nodes(nodes, links, emission)
    return mat


def _named(nodes, node_type: str, name: str):
    node = nodes.new(node_type)
    node.name = name
    return node


#: a point catches shadows when its normal's z component exceeds this (within 2.6° of +z).
CATCH_MIN_NORMAL_Z = 0.999


def _build_catch_nodes(nodes, links, emission):
    """Diffuse BSDF (albedo = colour × catch_scale) on upward-facing points, emission elsewhere."""
    scale = _named(nodes, "ShaderNodeMix", "catch_scale")
    scale.data_type = "RGBA"
    scale.blend_type = "MULTIPLY"
    scale.inputs["Factor"].default_value = 1.0
    scale.inputs[7].default_value = (1.0, 1.0, 1.0, 1.0)
    diffuse = _named(nodes, "ShaderNodeBsdfDiffuse", "catch_diffuse")
    diffuse.inputs["Roughness"].default_value = 0.0
    links.new(scale.outputs[2], diffuse.inputs["Color"])
    geometry = _named(nodes, "ShaderNodeNewGeometry", "catch_geometry")
    split = _named(nodes, "ShaderNodeSeparateXYZ", "catch_normal")
    upward = _named(nodes, "ShaderNodeMath", "catch_upward")
    upward.operation = "GREATER_THAN"
    upward.inputs[1].default_value = CATCH_MIN_NORMAL_Z
    links.new(geometry.outputs["Normal"], split.inputs[0])
    links.new(split.outputs["Z"], upward.inputs[0])
    choose = _named(nodes, "ShaderNodeMixShader", "catch_mix")
    links.new(upward.outputs[0], choose.inputs["Fac"])
    links.new(emission.outputs[0], choose.inputs[1])
    links.new(diffuse.outputs[0], choose.inputs[2])


def _rewire_flat(asset, mat):
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    mix = nodes["Mix Shader"]
    for socket in (mix.inputs[1], mix.inputs[2]):
        for link in list(socket.links):
            links.remove(link)
    if asset.holdout:
        camera_shader = nodes["Holdout"]
    else:
        camera_shader = nodes["catch_mix"] if asset.catch_shadows else nodes["Emission"]
    other = nodes["Emission"] if asset.indirect_visibility else nodes["Transparent BSDF"]
    links.new(other.outputs[0], mix.inputs[1])
    links.new(camera_shader.outputs[0], mix.inputs[2])


def _set_flat_color(view, asset, mat, value):
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    emitted = nodes["Emission"].inputs["Color"]
    _connect_color(mat, emitted, value, "color")
    caught = nodes["catch_scale"].inputs[6]  # the same colour feeds the shadow catcher
    for link in list(caught.links):
        links.remove(link)
    if emitted.links:
        links.new(emitted.links[0].from_socket, caught)
    else:
        caught.default_value = tuple(value)


def _set_flat_switch(view, asset, mat, value):
    _rewire_flat(asset, mat)


FLAT_SETTERS = {
    "color": _set_flat_color,
    "holdout": _set_flat_switch,
    "indirect_visibility": _set_flat_switch,
    "catch_shadows": _set_flat_switch,
}

def _flat_color_keyframer():
    """Key the emitted colour and the shadow catcher's colour together."""
    parts = [_color_keyframer(lambda m: m.node_tree.nodes["Emission"].inputs["Color"]),
             _color_keyframer(lambda m: m.node_tree.nodes["catch_scale"].inputs[6])]

    def key(view, asset, mat, frame):
        for part in parts:
            part(view, asset, mat, frame)
    key.blender_paths = lambda mat: [part.blender_path(mat) for part in parts]
    return key


FLAT_KEYFRAMERS = {
    "color": _flat_color_keyframer(),
}


def default_material():
    """The neutral grey used for objects whose material is UndefinedMaterial."""
    mat = bpy.data.materials.get("kubric_default")
    if mat is None:
        mat = bpy.data.materials.new("kubric_default")
        bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
        bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    return mat
