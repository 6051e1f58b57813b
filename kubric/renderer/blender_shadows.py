"""Shadow-catching :class:`~kubric.core.materials.FlatMaterial`\\ s: the albedo scale π / E.

A FlatMaterial with ``catch_shadows`` shows, on its upward-facing points, a Diffuse BSDF of albedo
``colour · π / E`` (see :mod:`kubric.renderer.blender_materials`). A Lambertian surface of albedo ρ
under irradiance E has radiance ρ·E/π, so where the ambient light reaches such a point unoccluded it
shows exactly ``colour`` — the same as the unlit material — and where objects block part of the sky
it is darker: the objects' contact shadows (and the light they bounce) appear on a backdrop that
otherwise looks like its texture.

E is the irradiance the scene's ambient illumination gives an unoccluded point with normal +z:

* a constant colour c (uniform sky of radiance c): E = π·c;
* an equirectangular environment :class:`~kubric.core.materials.Texture` of radiance L(e, φ):
  E = strength · ∫∫ L sin(e) cos(e) de dφ over elevations e ∈ [0, π/2]. Rows map linearly to
  elevation (row 0 = the bottom row of Blender's pixel buffer = e −π/2); the azimuth does not enter,
  which is why such a texture may be rotated about z only. 8-bit sRGB images are linearised first.

:func:`update_shadow_catchers` is called by the renderer before every render and ``save_state``.
"""

from __future__ import annotations

import math

import numpy as np

from kubric.core.color import Color
from kubric.core.materials import FlatMaterial, Texture


def upward_irradiance(radiance: np.ndarray) -> np.ndarray:
    """Irradiance (3,) on an upward-facing point from an equirectangular map.

    Args:
      radiance: (H, W, ≥3) linear radiance, row 0 at the bottom (elevation −π/2), columns spanning
        the full azimuth.
    """
    radiance = np.asarray(radiance, dtype=np.float64)
    if radiance.ndim != 3 or radiance.shape[2] < 3:
        raise ValueError(f"radiance must be (H, W, ≥3), got shape {radiance.shape}")
    h = radiance.shape[0]
    edges = np.clip((np.arange(h + 1) / h - 0.5) * np.pi, 0.0, None)  # row edges, upper half
    weight = 0.5 * np.diff(np.sin(edges) ** 2)  # ∫ sin e cos e de over each row
    row_mean = radiance[..., :3].mean(axis=1)  # (H, 3): ∫ dφ = 2π · mean over columns
    return 2.0 * math.pi * (weight[:, None] * row_mean).sum(axis=0)


def _srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _texture_irradiance(texture: Texture) -> np.ndarray:
    from kubric.renderer.blender_materials import load_image

    rx, ry = float(texture.rotation[0]), float(texture.rotation[1])
    if abs(rx) > 1e-9 or abs(ry) > 1e-9:
        raise ValueError(f"{texture.uid}: a shadow-catching FlatMaterial needs an ambient texture "
                         f"rotated about z only, got rotation {texture.rotation.tolist()}")
    image = load_image(texture)
    w, h = image.size
    pixels = np.empty(w * h * image.channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(h, w, image.channels)[..., :3]
    if not image.is_float and image.colorspace_settings.name.lower().startswith("srgb"):
        pixels = _srgb_to_linear(pixels)
    return upward_irradiance(pixels) * float(texture.strength)


def ambient_irradiance(ambient) -> np.ndarray:
    """E (3,) for the scene's ``ambient_illumination`` (a Color or an environment Texture)."""
    if isinstance(ambient, Texture):
        if ambient.mapping != "environment":
            raise ValueError(f"{ambient.uid}: ambient illumination texture must use "
                             f"mapping='environment', got {ambient.mapping!r}")
        return _texture_irradiance(ambient)
    if isinstance(ambient, Color):
        return math.pi * np.asarray(ambient.rgb, dtype=np.float64)
    raise TypeError(f"scene.ambient_illumination must be a Color or Texture, got {ambient!r}")


def update_shadow_catchers(view) -> None:
    """Set ``catch_scale`` = π / E on every shadow-catching FlatMaterial that ``view`` renders."""
    catchers = [a for a in view.scene.assets
                if isinstance(a, FlatMaterial) and a.catch_shadows and not a.holdout
                and view in a.linked_objects]
    if not catchers:
        return
    irradiance = ambient_irradiance(view.scene.ambient_illumination)
    if not (irradiance > 0).all():
        raise ValueError(f"{catchers[0].uid}: catch_shadows needs an ambient illumination that "
                         f"lights every colour channel; its upward irradiance is "
                         f"{np.round(irradiance, 6).tolist()}")
    scale = tuple(float(v) for v in math.pi / irradiance) + (1.0,)
    for material in catchers:
        material.linked_objects[view].node_tree.nodes["catch_scale"].inputs[7].default_value = scale
