"""The CLEVR facts in one module: shapes, colours, sizes, materials, lamps and camera.

Source: CLEVR (J. Johnson et al., "CLEVR: A Diagnostic Dataset for Compositional Language and
Elementary Visual Reasoning", CVPR 2017): 3 shapes, 8 colours, 2 sizes, 2 materials, a sun and
three area lamps, one camera. The values are the ones upstream Kubric uses for them (its MOVi-A/B
workers and ``kubric/assets/utils.py``):

- sizes are scale factors of the unit-sized KuBasic shapes (small 0.7, large 1.4);
- colours are CLEVR's sRGB triplets (0–255);
- materials are Principled BSDF parameters plus friction, restitution and density (kg per unit
  volume: an object of scale ``s`` gets the mass ``asset mass · density · s³``);
- lamps and camera are positions in metres (world frame, z up); light intensities are in
  Kubric's light units (see :mod:`kubric.core.lights`).

:data:`KUBASIC_SHAPES` are the asset ids of the KuBasic source (upstream's ``KUBASIC_OBJECTS``):
CLEVR's three shapes followed by the eight that Kubric added, in upstream's order.

Plain data (colours as :class:`kubric.core.color.Color`); no engine is imported. Readers:
:mod:`kubric.randomness` (``sample_color`` / ``sample_sizes`` with ``"clevr"``),
:func:`kubric.assets.utils.get_clevr_lights`, the MOVi recipes and their schema, complex BRDF's
metal, klevr, and the KuBasic builder (:mod:`kubric.asset_tools.kubasic`, its shape set).
"""

from __future__ import annotations

from types import MappingProxyType
from typing import NamedTuple

from kubric.core.color import Color

#: CLEVR's shapes (KuBasic asset ids).
SHAPES = ("cube", "cylinder", "sphere")

#: the KuBasic source's shapes (without the ``dome`` backdrop), upstream's order.
KUBASIC_SHAPES = SHAPES + ("cone", "torus", "gear", "torus_knot", "sponge", "spot", "teapot",
                           "suzanne")

#: CLEVR's 8 colours, sRGB 0–255, in alphabetical order (the order of the colour labels).
COLORS_RGB255 = MappingProxyType({
    "blue": (42, 75, 215), "brown": (129, 74, 25), "cyan": (41, 208, 208),
    "gray": (87, 87, 87), "green": (29, 105, 20), "purple": (129, 38, 192),
    "red": (173, 35, 35), "yellow": (255, 238, 5),
})

#: the same colours as :class:`~kubric.core.color.Color` (sRGB components in [0, 1]).
COLORS = MappingProxyType({name: Color(*(c / 255.0 for c in rgb))
                           for name, rgb in COLORS_RGB255.items()})

#: CLEVR's sizes as scale factors of the unit-sized KuBasic shapes (the order of the size labels).
SIZES = MappingProxyType({"small": 0.7, "large": 1.4})


class Material(NamedTuple):
    """A CLEVR material: Principled BSDF keyword arguments and its physical properties."""

    bsdf: MappingProxyType
    friction: float
    restitution: float
    density: float


#: CLEVR's materials (the order of the material labels).
MATERIALS = MappingProxyType({
    "metal": Material(MappingProxyType({"metallic": 1.0, "roughness": 0.2, "ior": 2.5}),
                      friction=0.4, restitution=0.3, density=2.7),
    "rubber": Material(MappingProxyType({"metallic": 0.0, "roughness": 0.7, "specular": 0.33,
                                         "ior": 1.25}),
                       friction=0.8, restitution=0.7, density=1.1),
})

#: CLEVR's lamps, in creation (and random draw) order: (name, light class name in
#: :mod:`kubric.core.lights`, keyword arguments, base position in metres).
LIGHTS = (
    ("sun", "DirectionalLight",
     MappingProxyType({"color": "white", "shadow_softness": 0.2, "intensity": 0.45}),
     (11.6608, -6.62799, 25.8232)),
    ("lamp_back", "RectAreaLight", MappingProxyType({"color": "white", "intensity": 50.0}),
     (-1.1685, 2.64602, 5.81574)),
    ("lamp_key", "RectAreaLight",
     MappingProxyType({"color": "#ffedd0", "intensity": 100.0, "width": 0.5, "height": 0.5}),
     (6.44671, -2.90517, 4.2584)),
    ("lamp_fill", "RectAreaLight",
     MappingProxyType({"color": "#c2d0ff", "intensity": 30.0, "width": 0.5, "height": 0.5}),
     (-4.67112, -4.0136, 3.01122)),
)

#: CLEVR's camera position (metres); it looks at the world origin.
CAMERA_POSITION = (7.48113, -6.50764, 5.34367)
