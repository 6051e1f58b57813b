"""The factor of a :class:`~kubric.core.pbr_materials.ProceduralMaterial` in numpy, for the raycast
backend's base colour: the patterns whose Cycles formula is closed-form, written after Cycles'
kernels (``svm_checker``, ``svm_brick``, ``svm_wave``) with the node settings
:mod:`kubric.renderer.blender_procedural` uses. Noise and Voronoi hash their lattice with
Cycles' own integer hash and are not reproduced: the raycast backend declares that it does not
render them (``Capabilities.procedural_patterns``) and refuses them in one line.

Input: (N, 3) generated coordinates (the ``object_coordinates`` layer: [0, 1]³ over the unscaled
local bounds); output: (N,) factors in [0, 1].
"""

from __future__ import annotations

import numpy as np

#: the brick node's settings (Blender's defaults, but mortar smooth 0: sharp mortar edges)
BRICK = {"mortar_size": 0.02, "mortar_smooth": 0.0, "bias": 0.0, "brick_width": 0.5,
         "row_height": 0.25, "offset": 0.5, "offset_frequency": 2, "squash": 1.0,
         "squash_frequency": 2}


def checker(p: np.ndarray) -> np.ndarray:
    """Cycles' checker: 1 where the parities of ⌊x⌋, ⌊y⌋, ⌊z⌋ give the second colour."""
    p = (p + 1e-6) * 0.999999
    xi, yi, zi = (np.abs(np.floor(p[:, k])).astype(np.int64) for k in range(3))
    return ((xi % 2 == yi % 2) == (zi % 2 == 1)).astype(np.float64)


def brick(p: np.ndarray) -> np.ndarray:
    """Cycles' brick ``Fac`` (the mortar mask) with :data:`BRICK`'s settings."""
    b = BRICK
    row = np.floor(p[:, 1] / b["row_height"]).astype(np.int64)
    width = np.where(row % b["squash_frequency"] != 0, b["brick_width"],
                     b["brick_width"] * b["squash"])
    offset = np.where(row % b["offset_frequency"] != 0, 0.0, width * b["offset"])
    num = np.floor((p[:, 0] + offset) / width)
    x = (p[:, 0] + offset) - width * num
    y = p[:, 1] - b["row_height"] * row
    dist = np.minimum(np.minimum(x, y), np.minimum(width - x, b["row_height"] - y))
    return (dist < b["mortar_size"]).astype(np.float64)


def wave(p: np.ndarray) -> np.ndarray:
    """Cycles' wave ``Fac``: bands along x, sine profile, no distortion, phase 0."""
    p = (p + 1e-6) * 0.999999
    return 0.5 + 0.5 * np.sin(p[:, 0] * 20.0 - np.pi / 2)


#: pattern → factor function of the scaled coordinates
FACTORS = {"checker": checker, "brick": brick, "wave": wave}


def pattern_factor(material, generated: np.ndarray) -> np.ndarray:
    """(N,) factor of ``material`` at the (N, 3) generated coordinates; KeyError for a pattern
    that is not closed-form (noise, voronoi)."""
    p = (np.asarray(generated, np.float64) + np.asarray(material.offset, np.float64))
    return np.clip(FACTORS[material.pattern](p * float(material.scale)), 0.0, 1.0)


def base_color(material, generated: np.ndarray) -> np.ndarray:
    """(N, 3) linear base colour: ``color_a`` · (1 − f) + ``color_b`` · f."""
    f = pattern_factor(material, generated)[:, None]
    a, b = (np.asarray(c.rgb, np.float64) for c in (material.color_a, material.color_b))
    return a * (1.0 - f) + b * f
