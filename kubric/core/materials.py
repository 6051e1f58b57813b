"""Materials and textures (renderer-only: simulators ignore them).

Colours are linear RGBA in [0, 1]. A material's ``color`` may also be a :class:`Texture`, whose
image is then used instead of a constant colour.
"""

from __future__ import annotations

from kubric.core import traits as kt
from kubric.core.assets import Asset, UndefinedAsset
from kubric.core.color import get_color


class Texture(Asset):
    """An image used as a colour map or as environment light / backdrop.

    Attributes:
      filename: path of the image (PNG, JPG, HDR, EXR).
      mapping: ``"uv"`` (the mesh's UV coordinates) or ``"environment"`` (equirectangular lookup by
        direction, for HDRI lighting, backdrops and domes).
      rotation: extrinsic XYZ Euler angles (radians) applied to environment lookups.
      strength: multiplier of the image's values (≥ 0).
      projection_height: metres (≥ 0); for ``"environment"`` mapping on an object, the lookup
        direction of a shaded point p is ``p − (origin + (0, 0, projection_height))``
        (a *ground projection*: a floor at the origin's height shows the image's lower
        hemisphere as seen from that height, the nadir texel straight below it, and points
        far away tend to the horizon row). 0 = plain lookup by direction from the origin.
        Ignored by ``"uv"`` mapping and by scene backgrounds (those are infinitely far).
    """

    filename = kt.Property("", kt.as_str(), "image path")
    mapping = kt.Property("uv", kt.as_choice(["uv", "environment"]), "uv or environment")
    rotation = kt.Vector3D((0.0, 0.0, 0.0), "Euler XYZ (radians) of environment lookups")
    strength = kt.Float(1.0, low=0.0, doc="multiplier of the image values")
    projection_height = kt.Float(0.0, low=0.0, doc="height (m) above the object's origin of "
                                 "the viewpoint of environment lookups (ground projection)")


def _as_color_or_texture():
    color = kt.as_color()

    def convert(value, owner, name):
        if isinstance(value, Texture):
            return value
        return color(value, owner, name)
    return convert


def _color_property(default, doc):
    return kt.Property(default, _as_color_or_texture(), doc, interpolation="linear")


class Material(Asset):
    """Base class of all materials."""


class UndefinedMaterial(Material, UndefinedAsset):
    """Marker: the renderer's default material (neutral grey)."""


class PrincipledBSDFMaterial(Material):
    """Blender's Principled BSDF (Disney-style physically based surface).

    Attributes:
      color: base colour (Color or Texture).
      metallic, specular, specular_tint, roughness, transmission, transmission_roughness: in [0, 1].
      ior: index of refraction (≥ 1).
      emission: emitted colour (black = none).
    """

    color = _color_property(get_color("white"), "base colour")
    metallic = kt.Float(0.0, 0.0, 1.0, "metalness")
    specular = kt.Float(0.5, 0.0, 1.0, "specular IOR level")
    specular_tint = kt.Float(0.0, 0.0, 1.0, "tint of the specular highlight towards the base colour")
    roughness = kt.Float(0.4, 0.0, 1.0, "microfacet roughness")
    ior = kt.Float(1.45, 1.0, 10.0, "index of refraction")
    transmission = kt.Float(0.0, 0.0, 1.0, "transmission weight (glass-like)")
    transmission_roughness = kt.Float(0.0, 0.0, 1.0, "roughness of transmitted light")
    emission = kt.RGBA("black", "emitted colour")


class FlatMaterial(Material):
    """Unlit colour (emission only), e.g. for backdrops and masks.

    Attributes:
      color: the colour seen by the camera (Color or Texture).
      holdout: cut the object out of the image (transparent alpha) while keeping it in annotations.
      indirect_visibility: whether the object shows in reflections and casts light / shadows.
      catch_shadows: on the object's upward-facing flat parts (normal within 2.6° of +z, e.g. a
        dome's floor), show ``color`` where the scene's ambient illumination reaches them
        unoccluded and darker where objects block it (contact shadows, plus light bounced off the
        objects): a diffuse surface whose albedo is ``color · π / E``, E being the irradiance the
        ambient illumination gives an unoccluded upward-facing point. Lamps add light on top and
        are not divided out. Needs a non-black ambient illumination; an ambient texture may be
        rotated about z only. Other parts stay unlit. Ignored when ``holdout`` is set.
    """

    color = _color_property(get_color("white"), "colour seen by the camera")
    holdout = kt.Property(False, kt.as_bool(), "render as transparent holdout")
    indirect_visibility = kt.Property(True, kt.as_bool(), "visible to indirect rays")
    catch_shadows = kt.Property(False, kt.as_bool(),
                                "upward-facing parts receive shadows of the ambient light")
