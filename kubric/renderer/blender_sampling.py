"""Cycles' noise levers beyond samples and the denoiser: path guiding, clamping, filter glossy and
adaptive sampling's minimum samples (Blender 5.0 ``CyclesRenderSettings`` names).

Each lever is a :class:`~kubric.renderer.blender.Blender` option validated here and applied to the
RGB render only; the exact-layer render sets every lever back to :data:`BLENDER_DEFAULTS`, so the
exact layers are the same bytes whatever the levers (tests/test_render_levers.py). Options:

* ``path_guiding``: ``"off"`` (default), ``"surface"``, ``"volume"`` or ``"all"`` (``True`` =
  ``"all"``, ``False`` = ``"off"``): Cycles' path guiding (OpenPGL; CPU only — the renderer
  refuses it on the GPU device) learns the scene's incident light while it renders and guides
  bounce directions on surfaces and/or inside volumes (``use_guiding``, ``use_surface_guiding``,
  ``use_volume_guiding``);
* ``clamp_direct`` / ``clamp_indirect``: the largest value a direct / indirect light sample may
  carry (scene-linear radiance; 0 = no clamp; ``sample_clamp_direct`` / ``sample_clamp_indirect``;
  Blender's defaults 0 and 10);
* ``filter_glossy``: blur of glossy reflections seen after a blurry bounce (``blur_glossy``,
  0–10; Blender's default 1);
* ``adaptive_min_samples``: samples every pixel takes before adaptive sampling may stop it
  (``adaptive_min_samples``; 0 = Cycles' automatic choice from the noise threshold).

:func:`recorded` gives the levers that differ from Blender's defaults, for ``metadata["renderer"]``.
Measured cost and error: docs/render-cost.md.
"""

from __future__ import annotations

import math

import numpy as np

#: Blender's own default of every lever (what a render without the lever uses)
BLENDER_DEFAULTS = {"path_guiding": "off", "clamp_direct": 0.0, "clamp_indirect": 10.0,
                    "filter_glossy": 1.0, "adaptive_min_samples": 0}
GUIDING = ("off", "surface", "volume", "all")


def as_guiding(name, value) -> str:
    if isinstance(value, (bool, np.bool_)):
        return "all" if value else "off"
    if not isinstance(value, str) or value.lower() not in GUIDING:
        raise ValueError(f"Blender option {name} must be True, False or one of {list(GUIDING)}, "
                         f"got {value!r}")
    return value.lower()


def _as_number(name, value, low, high) -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)) \
            or not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"Blender option {name} must be a number in [{low:g}, {high:g}], "
                         f"got {value!r}")
    return float(value)


def as_clamp(name, value) -> float:
    return _as_number(name, value, 0, 1e8)


def as_filter_glossy(name, value) -> float:
    return _as_number(name, value, 0, 10)


def as_min_samples(name, value) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or not 0 <= value <= 4096:
        raise ValueError(f"Blender option {name} must be an integer in [0, 4096], got {value!r}")
    return int(value)


CONVERTERS = {"path_guiding": as_guiding, "clamp_direct": as_clamp, "clamp_indirect": as_clamp,
              "filter_glossy": as_filter_glossy, "adaptive_min_samples": as_min_samples}


def apply_one(cycles, name: str, value) -> None:
    """Set lever ``name`` (already validated) on a ``bpy`` scene's ``cycles`` settings."""
    if name == "path_guiding":
        cycles.use_guiding = value != "off"
        cycles.use_surface_guiding = value in ("surface", "all")
        cycles.use_volume_guiding = value in ("volume", "all")
    else:
        attr = {"clamp_direct": "sample_clamp_direct", "clamp_indirect": "sample_clamp_indirect",
                "filter_glossy": "blur_glossy"}.get(name, name)
        setattr(cycles, attr, value)


def apply(cycles, values: dict) -> None:
    """Set every lever of ``values`` ({name: validated value}) on ``cycles``."""
    for name, value in values.items():
        apply_one(cycles, name, value)


def recorded(values: dict) -> dict:
    """The levers of ``values`` that differ from Blender's defaults (what metadata records)."""
    return {name: value for name, value in values.items() if value != BLENDER_DEFAULTS[name]}
