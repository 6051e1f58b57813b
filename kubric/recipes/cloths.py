"""Cloth sheets for MOVi-C–F (option ``cloths=N``; docs/deformables.md).

Each sheet is a :meth:`kubric.Deformable.cloth` square of edge U(``CLOTH_SIZE``) m at
``CLOTH_RESOLUTION``² vertices, turned by a random yaw, its centre at x, y U(``CLOTH_REGION``) m
and U(``CLOTH_CLEARANCE``) m above the highest point of the foreground objects at the start, so it
falls onto the objects and drapes over them (two-way: it pushes them too). It is textured with a
checkerboard of two random hues (``CLOTH_SQUARES``² squares over its UV square, written as a PNG
in the scene's scratch folder) so that its motion is visible. Instance metadata: ``scale`` (the
edge, m), ``is_dynamic`` True, ``cloth`` True. Mass ``CLOTH_MASS`` kg, spring stiffness and
margin as the Deformable defaults: the configuration measured stable at the MOVi step rate (240
steps/s; docs/deformables.md).
"""

from __future__ import annotations

import colorsys
import pathlib

import numpy as np

import kubric as kb
from kubric.core.deformables import checker_image

CLOTH_SIZE = (1.5, 3.0)
CLOTH_RESOLUTION = 16
CLOTH_REGION = (-1.0, 1.0)
CLOTH_CLEARANCE = (0.3, 1.0)
CLOTH_SQUARES = 8
CLOTH_MASS = 0.2


def _hue_pair(rng) -> np.ndarray:
    """Two sRGB colours of opposite-ish random hues, one light and one dark."""
    hue = float(rng.uniform(0, 1))
    light = colorsys.hsv_to_rgb(hue, 0.25, 0.95)
    dark = colorsys.hsv_to_rgb((hue + 0.5) % 1.0, 0.8, 0.45)
    return np.array([light, dark])


def add_cloths(scene, rng, count: int, folder: pathlib.Path) -> list:
    """``count`` cloth sheets (module doc) added to ``scene``; their textures go to ``folder``."""
    from PIL import Image
    cloths = []
    tops = [float(a.aabbox[1, 2]) for a in scene.foreground_assets
            if isinstance(a, kb.PhysicalObject)]
    top = max(tops, default=0.0)
    for k in range(count):
        size = float(rng.uniform(*CLOTH_SIZE))
        x, y = rng.uniform(*CLOTH_REGION, size=2)
        position = (float(x), float(y), top + float(rng.uniform(*CLOTH_CLEARANCE)))
        yaw = float(rng.uniform(0, 2 * np.pi))
        path = pathlib.Path(folder) / f"cloth_{k}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(checker_image((CLOTH_SQUARES, CLOTH_SQUARES), 8,
                                      _hue_pair(rng))).save(path)
        material = kb.PrincipledBSDFMaterial(color=kb.Texture(filename=str(path), mapping="uv"),
                                             roughness=0.9, name=f"cloth_{k}_material")
        cloth = kb.Deformable.cloth(size=(size, size), resolution=(CLOTH_RESOLUTION,) * 2,
                                    position=position, euler=(0.0, 0.0, yaw),
                                    mass=CLOTH_MASS, friction=0.5, material=material,
                                    name=f"cloth_{k}")
        cloth.metadata = {"scale": size, "is_dynamic": True, "cloth": True}
        scene += cloth
        cloths.append(cloth)
    return cloths
