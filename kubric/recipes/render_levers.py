"""Cycles' levers as recipe options: ``--set clamp_indirect=1``, ``--set fast_gi=1``, ...

:class:`RenderLevers` is part of :class:`kubric.recipes.render_quality.RenderQuality`: one option
per lever of :mod:`kubric.renderer.blender_sampling` (same name, same meaning, same bounds), unset
(``None``) by default = the quality profile's value (Blender's default for every profile today).
A lever that is set overrides the chosen profile's field; ``metadata["renderer"]`` then records
it (the renderer's settings list every lever that is not Blender's default, and
``quality_setting`` names it). The exact layers never see the levers (byte-identical).
Measured cost and error of each lever: docs/render-cost.md.
"""

from __future__ import annotations

from kubric.pipeline import Option
from kubric.renderer.blender_sampling import BLENDER_DEFAULTS, GUIDES, GUIDING


def scrambling(value):
    """Converter: ``"auto"`` or a number in [0, 1]."""
    if isinstance(value, str) and value.strip().lower() == "auto":
        return "auto"
    if isinstance(value, bool):
        raise ValueError("expected 'auto' or a number")
    number = float(value.strip() if isinstance(value, str) else value)
    if not 0 <= number <= 1:
        raise ValueError("expected 'auto' or a number in [0, 1]")
    return number


scrambling.allowed = "'auto' or a number in [0, 1]"


def _bounces(kind: str, default: int) -> Option:
    return Option(None, f"Cycles' most {kind} bounces of a path (default {default})", type=int,
                  low=0, high=1024)


class RenderLevers:
    """The levers of :mod:`kubric.renderer.blender_sampling` as recipe options (module doc)."""

    path_guiding = Option(None, "Cycles path guiding, CPU only (default off)", type=str,
                          choices=GUIDING)
    clamp_direct = Option(None, "largest direct-light sample value, 0 = no clamp (default 0)",
                          type=float, low=0, high=1e8)
    clamp_indirect = Option(None, "largest indirect-light sample value, 0 = no clamp (default "
                            "10)", type=float, low=0, high=1e8)
    filter_glossy = Option(None, "blur of glossy reflections after blurry bounces (default 1)",
                           type=float, low=0, high=10)
    adaptive_min_samples = Option(None, "samples before adaptive sampling may stop a pixel, 0 = "
                                  "Cycles' choice (default 0)", type=int, low=0, high=4096)
    denoising_input_passes = Option(None, "OIDN's guide passes (default RGB_ALBEDO_NORMAL)",
                                    type=str, choices=GUIDES)
    total_bounces = _bounces("total", 12)
    diffuse_bounces = _bounces("diffuse", 4)
    glossy_bounces = _bounces("glossy", 4)
    transmission_bounces = _bounces("transmission", 12)
    fast_gi = Option(None, "Cycles' fast GI: ambient occlusion replaces the light after this "
                     "many bounces, 0 = off (default 0)", type=int, low=0, high=1024)
    light_threshold = Option(None, "lights estimated below this are not sampled, 0 = always "
                             "(default 0.01)", type=float, low=0, high=1)
    caustics = Option(None, "reflective and refractive caustics (default true)", type=bool)
    min_light_bounces = Option(None, "bounces before Russian roulette may end a path (default "
                               "0)", type=int, low=0, high=1024)
    scrambling_distance = Option(None, "Cycles' scrambling distance, 'auto' or 0–1 (default 1)",
                                 type=scrambling)
    tile_size = Option(None, "render tile side in pixels (default 2048)", type=int, low=8,
                       high=16384)

    def lever_overrides(self) -> dict:
        """{lever: value} of the lever options that were set (they override the profile)."""
        return {name: getattr(self, name) for name in BLENDER_DEFAULTS
                if getattr(self, name) is not None}
