"""Cycles' levers beyond samples and the denoiser's network: noise levers (path guiding, clamping,
filter glossy, adaptive sampling's minimum samples), OIDN's guide passes, and the per-sample cost
levers that change bias (bounces, fast GI, light threshold, caustics, minimum light bounces) or
only the work's order (scrambling distance, tile size) (Blender 5.0 ``CyclesRenderSettings`` names).

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
  (``adaptive_min_samples``; 0 = Cycles' automatic choice from the noise threshold);
* ``denoising_input_passes``: the guides OIDN gets beside the noisy colour: ``"RGB"`` (none),
  ``"RGB_ALBEDO"`` or ``"RGB_ALBEDO_NORMAL"`` (default);
* ``total_bounces`` / ``diffuse_bounces`` / ``glossy_bounces`` / ``transmission_bounces``: the
  most bounces of a path, in all and of each kind (``max_bounces`` ... ``transmission_bounces``;
  Blender's defaults 12 / 4 / 4 / 12; the renderer's own ``max_bounces`` option, when given,
  sets every kind and wins over these);
* ``fast_gi``: 0 (default) = off; N ≥ 1 = Cycles' fast GI approximation, which replaces the light
  of bounces after the N-th by ambient occlusion tinted by the world (``use_fast_gi``,
  ``fast_gi_method`` REPLACE, ``ao_bounces_render`` N);
* ``light_threshold``: lights whose contribution is estimated below it are not sampled
  (``light_sampling_threshold``; 0 = never skip; Blender's default 0.01);
* ``caustics``: False turns reflective and refractive caustics off (``caustics_reflective`` /
  ``caustics_refractive``; default True);
* ``min_light_bounces``: bounces before Russian roulette may end a path (default 0);
* ``scrambling_distance``: a number in [0, 1] (default 1 = uncorrelated pixels) or ``"auto"``
  (``scrambling_distance`` / ``auto_scrambling_distance``: lower values correlate neighbouring
  pixels' sample sequences for GPU speed; Cycles ignores it under adaptive sampling);
* ``tile_size``: the side in pixels of the tiles a frame is rendered in (``tile_size``, with
  ``use_auto_tile``; default 2048: frames up to 2048² are one tile).

:func:`recorded` gives the levers that differ from Blender's defaults, for ``metadata["renderer"]``.
Measured cost and error: docs/render-cost.md.
"""

from __future__ import annotations

import math

import numpy as np

#: Blender's own default of every lever (what a render without the lever uses)
BLENDER_DEFAULTS = {"path_guiding": "off", "clamp_direct": 0.0, "clamp_indirect": 10.0,
                    "filter_glossy": 1.0, "adaptive_min_samples": 0,
                    "denoising_input_passes": "RGB_ALBEDO_NORMAL", "total_bounces": 12,
                    "diffuse_bounces": 4, "glossy_bounces": 4, "transmission_bounces": 12,
                    "fast_gi": 0, "light_threshold": 0.01, "caustics": True,
                    "min_light_bounces": 0, "scrambling_distance": 1.0, "tile_size": 2048}
GUIDING = ("off", "surface", "volume", "all")
GUIDES = ("RGB", "RGB_ALBEDO", "RGB_ALBEDO_NORMAL")


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


def _as_integer(name, value, low, high) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or not low <= value <= high:
        raise ValueError(f"Blender option {name} must be an integer in [{low}, {high}], "
                         f"got {value!r}")
    return int(value)


def as_min_samples(name, value) -> int:
    return _as_integer(name, value, 0, 4096)


def as_bounces(name, value) -> int:
    return _as_integer(name, value, 0, 1024)


def as_tile_size(name, value) -> int:
    return _as_integer(name, value, 8, 16384)


def as_light_threshold(name, value) -> float:
    return _as_number(name, value, 0, 1)


def as_guides(name, value) -> str:
    if not isinstance(value, str) or value.upper() not in GUIDES:
        raise ValueError(f"Blender option {name} must be one of {list(GUIDES)}, got {value!r}")
    return value.upper()


def as_caustics(name, value) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"Blender option {name} must be True or False, got {value!r}")
    return bool(value)


def as_scrambling(name, value):
    if isinstance(value, str) and value.lower() == "auto":
        return "auto"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.number)) \
            or not math.isfinite(value) or not 0 <= value <= 1:
        raise ValueError(f"Blender option {name} must be 'auto' or a number in [0, 1], "
                         f"got {value!r}")
    return float(value)


CONVERTERS = {"path_guiding": as_guiding, "clamp_direct": as_clamp, "clamp_indirect": as_clamp,
              "filter_glossy": as_filter_glossy, "adaptive_min_samples": as_min_samples,
              "denoising_input_passes": as_guides, "total_bounces": as_bounces,
              "diffuse_bounces": as_bounces, "glossy_bounces": as_bounces,
              "transmission_bounces": as_bounces, "fast_gi": as_bounces,
              "light_threshold": as_light_threshold, "caustics": as_caustics,
              "min_light_bounces": as_bounces, "scrambling_distance": as_scrambling,
              "tile_size": as_tile_size}
#: lever → the Cycles setting it is, where it is one setting of the same value
_CYCLES_NAMES = {"clamp_direct": "sample_clamp_direct", "clamp_indirect": "sample_clamp_indirect",
                 "filter_glossy": "blur_glossy", "adaptive_min_samples": "adaptive_min_samples",
                 "denoising_input_passes": "denoising_input_passes",
                 "total_bounces": "max_bounces", "diffuse_bounces": "diffuse_bounces",
                 "glossy_bounces": "glossy_bounces",
                 "transmission_bounces": "transmission_bounces",
                 "light_threshold": "light_sampling_threshold",
                 "min_light_bounces": "min_light_bounces"}


def apply_one(cycles, name: str, value) -> None:
    """Set lever ``name`` (already validated) on a ``bpy`` scene's ``cycles`` settings."""
    if name == "path_guiding":
        cycles.use_guiding = value != "off"
        cycles.use_surface_guiding = value in ("surface", "all")
        cycles.use_volume_guiding = value in ("volume", "all")
    elif name == "fast_gi":
        cycles.use_fast_gi = value > 0
        cycles.fast_gi_method = "REPLACE"
        cycles.ao_bounces_render = value
    elif name == "caustics":
        cycles.caustics_reflective = cycles.caustics_refractive = value
    elif name == "scrambling_distance":
        cycles.auto_scrambling_distance = value == "auto"
        cycles.scrambling_distance = 1.0 if value == "auto" else value
    elif name == "tile_size":
        cycles.use_auto_tile = True
        cycles.tile_size = value
    else:
        setattr(cycles, _CYCLES_NAMES[name], value)


def apply(cycles, values: dict) -> None:
    """Set every lever of ``values`` ({name: validated value}) on ``cycles``."""
    for name, value in values.items():
        apply_one(cycles, name, value)


def recorded(values: dict) -> dict:
    """The levers of ``values`` that differ from Blender's defaults (what metadata records)."""
    return {name: value for name, value in values.items() if value != BLENDER_DEFAULTS[name]}
