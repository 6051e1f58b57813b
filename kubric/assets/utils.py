"""Ready-made scene parts shared by recipes and upstream-style scripts (``kb.assets.utils``).

:data:`CLEVR_LIGHTS` is the one definition of the CLEVR lighting (a sun plus back, key and fill
area lamps, as in CLEVR / MOVi-A and B); :func:`get_clevr_lights` builds it with jittered
positions. Units: positions in metres (world frame, z up), intensities in Kubric's light units
(see :mod:`kubric.core.lights`).
"""

from __future__ import annotations

import numpy as np

from kubric.core.lights import DirectionalLight, RectAreaLight
from kubric.randomness import _require_rng

#: CLEVR lamps, in creation (and rng draw) order: (name, class, keyword arguments, base position).
CLEVR_LIGHTS = (
    ("sun", DirectionalLight, {"color": "white", "shadow_softness": 0.2, "intensity": 0.45},
     (11.6608, -6.62799, 25.8232)),
    ("lamp_back", RectAreaLight, {"color": "white", "intensity": 50.0},
     (-1.1685, 2.64602, 5.81574)),
    ("lamp_key", RectAreaLight, {"color": "#ffedd0", "intensity": 100.0, "width": 0.5,
                                 "height": 0.5}, (6.44671, -2.90517, 4.2584)),
    ("lamp_fill", RectAreaLight, {"color": "#c2d0ff", "intensity": 30.0, "width": 0.5,
                                  "height": 0.5}, (-4.67112, -4.0136, 3.01122)),
)


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
        the order of :data:`CLEVR_LIGHTS`. ``None`` means the worker rng bound by ``kb.setup``
        (see :mod:`kubric.randomness`); without one it is a ``TypeError``.
    Returns:
      ``[sun (DirectionalLight), lamp_back, lamp_key, lamp_fill (RectAreaLight)]``, not yet
      added to any scene (``scene += get_clevr_lights(rng=rng)`` adds them all).
    """
    rng = _require_rng(rng, "kb.assets.utils.get_clevr_lights")
    jitter = float(light_jitter)
    if not np.isfinite(jitter) or jitter < 0:
        raise ValueError(f"get_clevr_lights: light_jitter must be a finite number >= 0 (metres), "
                         f"got {light_jitter!r}")
    lights = []
    for name, cls, kwargs, position in CLEVR_LIGHTS:
        light = cls(name=name, **kwargs)
        light.position = np.asarray(position, dtype=np.float64) + _unit_cube_sample(rng) * jitter
        light.look_at((0.0, 0.0, 0.0))
        lights.append(light)
    return lights
