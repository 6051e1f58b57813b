"""Ready-made scene parts shared by recipes and upstream-style scripts (``kb.assets.utils``).

:func:`get_clevr_lights` builds the CLEVR lighting (a sun plus back, key and fill area lamps, as in
CLEVR / MOVi-A and B; the data is :data:`kubric.assets.clevr.LIGHTS`) with jittered positions.
Units: positions in metres (world frame, z up), intensities in Kubric's light units (see
:mod:`kubric.core.lights`).
"""

from __future__ import annotations

import numpy as np

from kubric.assets import clevr
from kubric.core import lights as core_lights
from kubric.core.rng import require_rng


def _unit_cube_sample(rng) -> np.ndarray:
    """Three U[0, 1) numbers: ``rng.rand(3)`` (RandomState) or ``rng.random(3)`` (Generator)."""
    if isinstance(rng, np.random.Generator):
        return rng.random(3)
    return rng.rand(3)


def get_clevr_lights(light_jitter: float = 1.0, rng=None) -> list:
    """The four CLEVR lights, each at its base position + ``U[0,1)³ · light_jitter`` (metres),
    oriented to look at the world origin.

    Args:
      light_jitter: scale of the positional jitter (m); 0 gives the base positions. Must be ≥ 0.
      rng: ``numpy.random.RandomState`` or ``Generator``, drawn from three numbers per light in
        the order of :data:`kubric.assets.clevr.LIGHTS`. ``None`` means the worker rng bound by
        ``kb.setup``, else (as upstream) an unseeded generator whose jitter is not reproducible
        (see :mod:`kubric.core.rng`).
    Returns:
      ``[sun (DirectionalLight), lamp_back, lamp_key, lamp_fill (RectAreaLight)]``, not yet
      added to any scene (``scene += get_clevr_lights(rng=rng)`` adds them all).
    """
    rng = require_rng(rng, "kb.assets.utils.get_clevr_lights")
    jitter = float(light_jitter)
    if not np.isfinite(jitter) or jitter < 0:
        raise ValueError(f"get_clevr_lights: light_jitter must be a finite number >= 0 (metres), "
                         f"got {light_jitter!r}")
    lights = []
    for name, class_name, kwargs, position in clevr.LIGHTS:
        light = getattr(core_lights, class_name)(name=name, **kwargs)
        light.position = np.asarray(position, dtype=np.float64) + _unit_cube_sample(rng) * jitter
        light.look_at((0.0, 0.0, 0.0))
        lights.append(light)
    return lights
