"""Cloth sheets and soft toys for MOVi-C–F (options ``cloths=N``, ``soft_objects=N``;
docs/deformables.md).

Cloth: a :meth:`kubric.Deformable.cloth` square of edge U(``CLOTH_SIZE``) m at
``CLOTH_RESOLUTION``² vertices, mass ``CLOTH_MASS`` kg (spring stiffness and margin: the
Deformable defaults, measured stable at MOVi's 240 steps/s). Soft toy: a
:meth:`kubric.Deformable.soft_box` cube of edge U(``SOFT_SIZE``) m, ``SOFT_RESOLUTION``³ cells,
mass ``SOFT_MASS`` kg (NeoHookean defaults). Each is turned by a random yaw, its centre at x, y
U(``DROP_REGION``) m and U(``DROP_CLEARANCE``) m above the highest point of the foreground objects
at the start, so it falls onto the objects (two-way: it pushes them too), and textured with a
checkerboard of two random hues (``SQUARES``² squares over its UVs, a PNG in the scene's scratch
folder) so that its motion is visible. Instance metadata: ``scale`` (the edge, m),
``is_dynamic`` True, ``cloth`` or ``soft`` True.
"""

from __future__ import annotations

import colorsys
import pathlib

import numpy as np

import kubric as kb
from kubric.core.deformables import checker_image

CLOTH_SIZE = (1.5, 3.0)
CLOTH_RESOLUTION = 16
CLOTH_MASS = 0.2
SOFT_SIZE = (0.4, 0.8)
SOFT_RESOLUTION = 3
SOFT_MASS = 0.5
DROP_REGION = (-1.0, 1.0)
DROP_CLEARANCE = (0.3, 1.0)
SQUARES = 8


def _hue_pair(rng) -> np.ndarray:
    """Two sRGB colours of opposite-ish random hues, one light and one dark."""
    hue = float(rng.uniform(0, 1))
    light = colorsys.hsv_to_rgb(hue, 0.25, 0.95)
    dark = colorsys.hsv_to_rgb((hue + 0.5) % 1.0, 0.8, 0.45)
    return np.array([light, dark])


def _top(scene) -> float:
    tops = [float(a.aabbox[1, 2]) for a in scene.foreground_assets
            if isinstance(a, kb.PhysicalObject)]
    return max(tops, default=0.0)


def _drop(scene, rng, kind: str, k: int, folder: pathlib.Path, top: float):
    """One deformable of ``kind`` (module doc) added to ``scene``."""
    from PIL import Image
    size = float(rng.uniform(*(CLOTH_SIZE if kind == "cloth" else SOFT_SIZE)))
    x, y = rng.uniform(*DROP_REGION, size=2)
    position = (float(x), float(y), top + float(rng.uniform(*DROP_CLEARANCE)))
    yaw = float(rng.uniform(0, 2 * np.pi))
    name = f"{kind}_{k}"
    path = pathlib.Path(folder) / f"{name}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(checker_image((SQUARES, SQUARES), 8, _hue_pair(rng))).save(path)
    material = kb.PrincipledBSDFMaterial(color=kb.Texture(filename=str(path), mapping="uv"),
                                         roughness=0.9, name=f"{name}_material")
    common = dict(position=position, euler=(0.0, 0.0, yaw), friction=0.5, material=material,
                  name=name)
    if kind == "cloth":
        obj = kb.Deformable.cloth(size=(size, size), resolution=(CLOTH_RESOLUTION,) * 2,
                                  mass=CLOTH_MASS, **common)
    else:
        obj = kb.Deformable.soft_box(size=(size,) * 3, resolution=(SOFT_RESOLUTION,) * 3,
                                     mass=SOFT_MASS, **common)
    obj.metadata = {"scale": size, "is_dynamic": True, kind: True}
    scene += obj
    return obj


def add_deformables(scene, rng, cloths: int, soft_objects: int, folder: pathlib.Path) -> list:
    """``cloths`` sheets then ``soft_objects`` toys (module doc) added to ``scene``, all above
    the objects present now; their textures go to ``folder``."""
    top = _top(scene)
    return [_drop(scene, rng, kind, k, folder, top)
            for kind, count in (("cloth", cloths), ("soft", soft_objects))
            for k in range(count)]
