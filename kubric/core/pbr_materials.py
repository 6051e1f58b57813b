"""PBR materials beyond a constant Principled BSDF: procedural patterns and image sets.

* :class:`ProceduralMaterial`: a texture pattern of Blender's (``checker``, ``brick``, ``wave``,
  ``noise``, ``voronoi``) evaluated at the surface point's **generated coordinates** (the point in
  the object's unscaled local bounding box, normalised to [0, 1]³: the ``object_coordinates``
  layer), shifted by ``offset`` and multiplied by ``scale``. Its factor f ∈ [0, 1] mixes the base
  colour (``color_a`` at f = 0 … ``color_b`` at f = 1) and the roughness (``roughness_a`` …
  ``roughness_b``) and drives a bump map of strength ``bump``; ``metallic`` is constant. What f
  is per pattern (Blender's node and output): checker ``Fac`` (1 on the cells of the second
  colour), brick ``Fac`` (1 in the mortar, sharp edges), wave ``Fac`` (sine bands along x, no
  distortion), noise ``Fac`` (fBm, ``detail`` octaves), voronoi ``Distance`` (F1, Euclidean).
  Needs no download; :func:`sample_procedural_material` draws one from an explicit rng.
* :class:`ImageMaterial`: a scanned / authored PBR set (base colour, roughness, metallic, normal,
  displacement image files, e.g. from ``kubric assets materials``) on the mesh's UVs, repeated
  ``uv_scale`` times; its licence and attribution travel with it.

Both describe themselves as plain data (``describe()``), which the scene metadata records per
object (``metadata.json`` instances' ``material``, and ``metadata.materials``).
"""

from __future__ import annotations

import colorsys
import os

import numpy as np

from kubric.core import traits as kt
from kubric.core.color import Color
from kubric.core.materials import Material

#: the procedural patterns (Blender texture nodes), in sampling order
PATTERNS = ("checker", "brick", "wave", "noise", "voronoi")
#: the image maps an :class:`ImageMaterial` may carry (all optional but ``base_color``)
IMAGE_MAPS = ("base_color", "roughness", "metallic", "normal", "displacement")


def _rounded(value):
    if isinstance(value, Color):
        return [round(float(c), 6) for c in value.rgb]
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, np.ndarray):
        return [round(float(c), 6) for c in value]
    return round(float(value), 6)


class ProceduralMaterial(Material):
    """A procedural PBR surface (module doc).

    Attributes:
      pattern: one of :data:`PATTERNS`.
      color_a, color_b: linear base colours at factor 0 and 1.
      roughness_a, roughness_b: roughness at factor 0 and 1, in [0, 1].
      metallic: in [0, 1].
      scale: pattern frequency over the generated coordinates (cells across the object), > 0.
      offset: added to the generated coordinates before scaling (moves the pattern).
      detail: noise octaves, in [0, 15] (noise only).
      bump: bump-map strength of the factor, in [0, 1] (0 = flat).
      indirect_visibility: False: rays other than camera rays pass through the surface (as
        ``FlatMaterial.indirect_visibility``: a dome floor that neither blocks the environment
        light nor shows in reflections, while camera rays see it lit and shadowed).
    """

    pattern = kt.Property("checker", kt.as_choice(PATTERNS), "texture pattern")
    color_a = kt.RGBA("white", "base colour at factor 0")
    color_b = kt.RGBA("black", "base colour at factor 1")
    roughness_a = kt.Float(0.5, 0.0, 1.0, "roughness at factor 0")
    roughness_b = kt.Float(0.5, 0.0, 1.0, "roughness at factor 1")
    metallic = kt.Float(0.0, 0.0, 1.0, "metalness")
    scale = kt.Float(4.0, 1e-6, 1e6, "pattern frequency over the generated coordinates")
    offset = kt.Vector3D((0.0, 0.0, 0.0), "shift of the generated coordinates")
    detail = kt.Float(2.0, 0.0, 15.0, "noise octaves")
    bump = kt.Float(0.0, 0.0, 1.0, "bump strength")
    indirect_visibility = kt.Property(True, kt.as_bool(), "visible to non-camera rays")

    def describe(self) -> dict:
        """The material as plain JSON-able data."""
        out = {"type": "ProceduralMaterial", "source": "procedural"}
        for name in ("pattern", "color_a", "color_b", "roughness_a", "roughness_b", "metallic",
                     "scale", "offset", "detail", "bump", "indirect_visibility"):
            out[name] = _rounded(getattr(self, name))
        return out


class ImageMaterial(Material):
    """A PBR image set on the mesh's UVs (module doc). Empty file names: the map is absent
    (roughness then ``roughness``, metallic 0, no normal / displacement).

    Attributes:
      base_color, roughness_map, metallic_map, normal_map, displacement_map: image paths
        (normal maps in OpenGL convention, +y up).
      roughness: constant roughness used when there is no roughness map.
      uv_scale: repeats of the images per UV unit (> 0).
      displacement_scale: bump height (m) of a displacement value of 1.
      indirect_visibility: as :class:`ProceduralMaterial`'s.
      material_id, license, attribution, source_url: where the set comes from.
    """

    base_color = kt.Property("", kt.as_str(), "base colour image (sRGB)")
    roughness_map = kt.Property("", kt.as_str(), "roughness image (non-colour)")
    metallic_map = kt.Property("", kt.as_str(), "metallic image (non-colour)")
    normal_map = kt.Property("", kt.as_str(), "tangent-space normal image, OpenGL (+y up)")
    displacement_map = kt.Property("", kt.as_str(), "displacement image (non-colour)")
    roughness = kt.Float(0.5, 0.0, 1.0, "roughness without a roughness map")
    uv_scale = kt.Float(1.0, 1e-6, 1e6, "image repeats per UV unit")
    displacement_scale = kt.Float(0.01, 0.0, 10.0, "bump height (m) of displacement 1")
    indirect_visibility = kt.Property(True, kt.as_bool(), "visible to non-camera rays")
    material_id = kt.Property("", kt.as_str(), "id in its material source")
    license = kt.Property("", kt.as_str(), "licence of the images")
    attribution = kt.Property("", kt.as_str(), "authors / publisher")
    source_url = kt.Property("", kt.as_str(), "page of the set")

    def describe(self) -> dict:
        """The material as plain JSON-able data (file names without their folder)."""
        out = {"type": "ImageMaterial", "source": "images", "material_id": self.material_id,
               "license": self.license, "attribution": self.attribution,
               "source_url": self.source_url,
               "uv_scale": _rounded(self.uv_scale),
               "indirect_visibility": self.indirect_visibility}
        for name, prop in (("base_color", "base_color"), ("roughness", "roughness_map"),
                           ("metallic", "metallic_map"), ("normal", "normal_map"),
                           ("displacement", "displacement_map")):
            path = getattr(self, prop)
            out[f"{name}_map" if name != "base_color" else name] = (
                os.path.basename(path) if path else "")
        return out


def _random_color(rng) -> Color:
    h, s, v = rng.uniform(0, 1), rng.uniform(0.2, 0.9), rng.uniform(0.25, 1.0)
    return Color(*colorsys.hsv_to_rgb(h, s, v))


def sample_procedural_material(rng, patterns=PATTERNS, scale_range=(2.0, 8.0),
                               name: str | None = None) -> ProceduralMaterial:
    """A random :class:`ProceduralMaterial` drawn from ``rng`` (a ``numpy.random.RandomState``)
    in a fixed order — the same rng state gives the same material. The pattern is uniform over
    ``patterns``; colours uniform in hue, saturation U(0.2, 0.9), value U(0.25, 1); roughness
    U(0.1, 0.9) each; metallic 1 with probability 0.2, else 0; scale log-uniform in
    ``scale_range``; offset U(−10, 10)³; detail U(0, 6); bump U(0, 0.5)."""
    patterns = tuple(patterns)
    unknown = sorted(set(patterns) - set(PATTERNS))
    if not patterns or unknown:
        raise ValueError(f"patterns {list(patterns)}: give one or more of {list(PATTERNS)}")
    lo, hi = (float(v) for v in scale_range)
    if not 0 < lo <= hi:
        raise ValueError(f"scale_range {scale_range!r}: need 0 < low ≤ high")
    pattern = patterns[rng.randint(len(patterns))]
    color_a, color_b = _random_color(rng), _random_color(rng)
    rough = rng.uniform(0.1, 0.9, 2)
    metallic = 1.0 if rng.uniform() < 0.2 else 0.0
    scale = float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
    offset = rng.uniform(-10, 10, 3)
    detail, bump = rng.uniform(0, 6), rng.uniform(0, 0.5)
    return ProceduralMaterial(
        name=name, pattern=pattern, color_a=color_a, color_b=color_b,
        roughness_a=float(rough[0]), roughness_b=float(rough[1]), metallic=metallic,
        scale=scale, offset=tuple(float(v) for v in offset), detail=float(detail),
        bump=float(bump))
