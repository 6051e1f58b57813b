"""Blender node trees of :mod:`kubric.core.pbr_materials` (Cycles).

* :class:`~kubric.core.pbr_materials.ProceduralMaterial` → Texture Coordinate ``Generated`` +
  ``offset`` (Vector Math) → the pattern's texture node (``Scale`` = ``scale``) → factor →
  Mix (``color_a`` … ``color_b``) into ``Base Color``, Map Range (``roughness_a`` …
  ``roughness_b``) into ``Roughness``, Bump (``Strength`` = ``bump``, ``Height`` = factor) into
  ``Normal``; ``Metallic`` constant. Node settings: checker as is; brick with mortar smooth 0
  (:data:`kubric.renderer.procedural_patterns.BRICK`); wave bands along x, sine, distortion 0;
  noise ``Detail`` = ``detail``; Voronoi F1 Euclidean, ``Distance`` output.
* :class:`~kubric.core.pbr_materials.ImageMaterial` → Image Texture nodes on the UVs × ``uv_scale``
  (base colour sRGB, the other maps Non-Color): roughness / metallic into the BSDF, the normal map
  through a Normal Map node (tangent space), displacement through a Bump node (``Distance`` =
  ``displacement_scale``) after it.

``indirect_visibility`` False: a Mix Shader on Light Path ``Is Camera Ray`` shows the BSDF to
camera rays and a Transparent BSDF to every other ray. Every property rebuilds the tree (the
materials are static: no keyframes).
"""

from __future__ import annotations

import bpy

from kubric.core.materials import Texture
from kubric.core.pbr_materials import ImageMaterial, ProceduralMaterial
from kubric.renderer.blender_materials import OUTPUT_NODE, PRINCIPLED_NODE, load_image
from kubric.renderer.procedural_patterns import BRICK

#: pattern → (texture node type, its factor output)
PATTERN_NODES = {
    "checker": ("ShaderNodeTexChecker", "Fac"),
    "brick": ("ShaderNodeTexBrick", "Fac"),
    "wave": ("ShaderNodeTexWave", "Fac"),
    "noise": ("ShaderNodeTexNoise", "Fac"),
    "voronoi": ("ShaderNodeTexVoronoi", "Distance"),
}


def build(view, asset):
    """An empty material; the setters fill it."""
    mat = bpy.data.materials.new(asset.uid)
    return mat


def _fresh_tree(mat, indirect_visibility=True):
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    out = nodes.new("ShaderNodeOutputMaterial")
    out.name = OUTPUT_NODE
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.name = PRINCIPLED_NODE
    if indirect_visibility:
        links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    else:  # camera rays see the BSDF, every other ray passes through
        path = nodes.new("ShaderNodeLightPath")
        clear = nodes.new("ShaderNodeBsdfTransparent")
        mix = nodes.new("ShaderNodeMixShader")
        links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
        links.new(clear.outputs[0], mix.inputs[1])
        links.new(bsdf.outputs["BSDF"], mix.inputs[2])
        links.new(mix.outputs["Shader"], out.inputs["Surface"])
    return nodes, links, bsdf


def _pattern_node(nodes, material):
    kind, output = PATTERN_NODES[material.pattern]
    tex = nodes.new(kind)
    tex.name = "pattern"
    tex.inputs["Scale"].default_value = float(material.scale)
    if material.pattern == "brick":
        tex.offset, tex.offset_frequency = BRICK["offset"], BRICK["offset_frequency"]
        tex.squash, tex.squash_frequency = BRICK["squash"], BRICK["squash_frequency"]
        for name, key in (("Mortar Size", "mortar_size"), ("Mortar Smooth", "mortar_smooth"),
                          ("Bias", "bias"), ("Brick Width", "brick_width"),
                          ("Row Height", "row_height")):
            tex.inputs[name].default_value = BRICK[key]
    elif material.pattern == "wave":
        tex.wave_type, tex.bands_direction, tex.wave_profile = "BANDS", "X", "SIN"
        tex.inputs["Distortion"].default_value = 0.0
        tex.inputs["Phase Offset"].default_value = 0.0
    elif material.pattern == "noise":
        tex.inputs["Detail"].default_value = float(material.detail)
    elif material.pattern == "voronoi":
        tex.feature, tex.distance = "F1", "EUCLIDEAN"
    return tex, output


def rebuild_procedural(view, asset, mat, value=None):
    nodes, links, bsdf = _fresh_tree(mat, asset.indirect_visibility)
    coords = nodes.new("ShaderNodeTexCoord")
    shift = nodes.new("ShaderNodeVectorMath")
    shift.operation = "ADD"
    shift.inputs[1].default_value = tuple(float(v) for v in asset.offset)
    links.new(coords.outputs["Generated"], shift.inputs[0])
    tex, output = _pattern_node(nodes, asset)
    links.new(shift.outputs["Vector"], tex.inputs["Vector"])
    factor = tex.outputs[output]
    mix = nodes.new("ShaderNodeMix")
    mix.name = "base_color"
    mix.data_type = "RGBA"
    links.new(factor, mix.inputs["Factor"])
    mix.inputs[6].default_value = tuple(asset.color_a)
    mix.inputs[7].default_value = tuple(asset.color_b)
    links.new(mix.outputs[2], bsdf.inputs["Base Color"])
    rough = nodes.new("ShaderNodeMapRange")
    rough.name = "roughness"
    rough.inputs["To Min"].default_value = float(asset.roughness_a)
    rough.inputs["To Max"].default_value = float(asset.roughness_b)
    links.new(factor, rough.inputs["Value"])
    links.new(rough.outputs["Result"], bsdf.inputs["Roughness"])
    bsdf.inputs["Metallic"].default_value = float(asset.metallic)
    if asset.bump > 0:
        bump = nodes.new("ShaderNodeBump")
        bump.name = "bump"
        bump.inputs["Strength"].default_value = float(asset.bump)
        bump.inputs["Distance"].default_value = 0.02
        links.new(factor, bump.inputs["Height"])
        links.new(bump.outputs["Normal"], bsdf.inputs["Normal"])


def _image(nodes, links, uv, path, non_color):
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = load_image(Texture(filename=path))
    if non_color:
        tex.image.colorspace_settings.name = "Non-Color"
    links.new(uv.outputs["Vector"], tex.inputs["Vector"])
    return tex


def rebuild_image(view, asset, mat, value=None):
    nodes, links, bsdf = _fresh_tree(mat, asset.indirect_visibility)
    coords = nodes.new("ShaderNodeTexCoord")
    uv = nodes.new("ShaderNodeVectorMath")
    uv.operation = "SCALE"
    uv.inputs["Scale"].default_value = float(asset.uv_scale)
    links.new(coords.outputs["UV"], uv.inputs[0])
    if not asset.base_color:
        raise ValueError(f"{asset.uid}: ImageMaterial.base_color is empty")
    links.new(_image(nodes, links, uv, asset.base_color, False).outputs["Color"],
              bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = float(asset.roughness)
    bsdf.inputs["Metallic"].default_value = 0.0
    for path, socket in ((asset.roughness_map, "Roughness"), (asset.metallic_map, "Metallic")):
        if path:
            links.new(_image(nodes, links, uv, path, True).outputs["Color"], bsdf.inputs[socket])
    normal = None
    if asset.normal_map:
        node = nodes.new("ShaderNodeNormalMap")
        links.new(_image(nodes, links, uv, asset.normal_map, True).outputs["Color"],
                  node.inputs["Color"])
        normal = node.outputs["Normal"]
    if asset.displacement_map:
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Distance"].default_value = float(asset.displacement_scale)
        links.new(_image(nodes, links, uv, asset.displacement_map, True).outputs["Color"],
                  bump.inputs["Height"])
        if normal is not None:
            links.new(normal, bump.inputs["Normal"])
        normal = bump.outputs["Normal"]
    if normal is not None:
        links.new(normal, bsdf.inputs["Normal"])


def _every(cls, rebuild):
    return {name: rebuild for name in cls.property_names()
            if name not in ("background", "metadata")}


PROCEDURAL_SETTERS = _every(ProceduralMaterial, rebuild_procedural)
IMAGE_SETTERS = _every(ImageMaterial, rebuild_image)
