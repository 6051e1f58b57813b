"""Lights. Orientation follows the camera convention: a light shines along its local −Z axis
(so ``look_at=`` points it at a target). Intensities are in Blender's units: watts for point,
spot and area lights, W/m² (irradiance) for the directional (sun) light.
"""

from __future__ import annotations

import numpy as np

from kubric.core import traits as kt
from kubric.core.assets import UndefinedAsset
from kubric.core.color import get_color
from kubric.core.objects import Object3D


class Light(Object3D):
    """Base class of all lights: ``color`` (RGBA) and ``intensity`` (≥ 0). Lights are part of the
    background (``background`` defaults to True, as upstream), so ``scene.foreground_assets``
    lists objects only."""

    property_defaults = {"background": True}
    color = kt.RGBA(get_color("white"), "light colour")
    intensity = kt.Float(1.0, low=0.0, doc="power (W) or irradiance (W/m², sun)")


class UndefinedLight(Light, UndefinedAsset):
    """Marker: no light."""


class DirectionalLight(Light):
    """Sun-like light at infinity. ``shadow_softness``: angular diameter of the sun (radians)."""

    shadow_softness = kt.Float(0.2, 0.0, np.pi, "angular diameter of the light source (radians)")


class PointLight(Light):
    """Omnidirectional point light."""


class SpotLight(Light):
    """Cone light: ``spot_size`` full cone angle (radians), ``spot_blend`` soft edge in [0, 1]
    (defaults π/4 and 1, as upstream)."""

    spot_size = kt.Float(np.pi / 4, 0.0, np.pi, "full cone angle (radians)")
    spot_blend = kt.Float(1.0, 0.0, 1.0, "softness of the cone edge")


class RectAreaLight(Light):
    """Rectangular area light of ``width`` × ``height`` metres (local x × local y)."""

    width = kt.Float(1.0, low=0.0, doc="extent along local x (m)")
    height = kt.Float(1.0, low=0.0, doc="extent along local y (m)")
