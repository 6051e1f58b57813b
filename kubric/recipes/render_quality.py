"""Render quality profiles: the RGB render's samples and denoiser, chosen by one ``quality`` option.

Every recipe that path-traces RGB mixes in :class:`RenderQuality`: ``--set quality=draft|default|
final`` picks a profile, and ``samples`` / ``denoise`` (unset by default) override its fields. The
exact layers (depth, segmentation, flow, normals, object coordinates, UV) come from a separate
1-sample render with no denoising, so they are bit-identical under every profile.

The profiles were chosen from the cost/quality curve measured on MOVi-A (256², 24 frames, seed 3)
by ``benchmarks/bench_scene_cost.py``: RGB RMSE (8-bit values) against a 1024-spp undenoised
reference of frames 1–4, and CPU-seconds per scene on the 2-core reference machine; the measured
table is in docs/render-cost.md. Path tracing costs ~0.10 CPU-s per sample per 256² frame and
OIDN (HIGH quality, ACCURATE prefilter) ~0.8 CPU-s per 256² frame, so at 16 samples the denoiser
is a third of the frame's cost; below 16 samples the RMSE of object and edge pixels grows fast.

* ``draft``: 4 spp, OIDN BALANCED with FAST prefilter — previews and pipeline debugging.
* ``default``: 16 spp, OIDN HIGH / ACCURATE — datasets.
* ``final``: 64 spp, OIDN HIGH / ACCURATE — the previous default; lowest noise on objects.
"""

from __future__ import annotations

from dataclasses import dataclass

from kubric.pipeline import Option


@dataclass(frozen=True)
class QualityProfile:
    """The RGB render settings of one quality level (OIDN names as Blender's)."""
    samples: int                 # Cycles samples per pixel
    denoise: bool                # OIDN on the RGB render
    denoising_quality: str       # HIGH | BALANCED | FAST (OIDN network size)
    denoising_prefilter: str     # ACCURATE | FAST | NONE (cleaning of the albedo/normal guides)


PROFILES: dict[str, QualityProfile] = {
    "draft": QualityProfile(4, True, "BALANCED", "FAST"),
    "default": QualityProfile(16, True, "HIGH", "ACCURATE"),
    "final": QualityProfile(64, True, "HIGH", "ACCURATE"),
}


def _profile_help() -> str:
    return "; ".join(f"{name}: {p.samples} spp" + (f", OIDN {p.denoising_quality.lower()}"
                                                   if p.denoise else "")
                     for name, p in PROFILES.items())


class RenderQuality:
    """Mixin of a recipe: the ``quality`` / ``samples`` / ``denoise`` options and their resolution
    into renderer keyword arguments and ``metadata["renderer"]`` fields.

    ``renderer``: the backend of :data:`kubric.renderer.base.BACKENDS` the recipe renders with
    (``blender`` unless the recipe declares a ``renderer`` option); the quality profile applies
    to Blender only."""

    renderer = "blender"

    quality = Option("default", "RGB render quality profile (" + _profile_help() +
                     "; measured cost and RMSE in docs/render-cost.md)", choices=tuple(PROFILES))
    samples = Option(None, "Cycles samples per pixel (default: the quality profile's)", type=int,
                     low=1, high=65536, limit=4096)
    denoise = Option(None, "denoise the RGB render with OIDN (default: the quality profile's)",
                     type=bool)

    def quality_profile(self) -> QualityProfile:
        """The chosen profile with ``samples`` / ``denoise`` overrides applied."""
        p = PROFILES[self.quality]
        return QualityProfile(p.samples if self.samples is None else self.samples,
                              p.denoise if self.denoise is None else self.denoise,
                              p.denoising_quality, p.denoising_prefilter)

    def renderer_quality(self) -> dict:
        """Keyword arguments of :class:`kubric.renderer.Blender` for the RGB render."""
        p = self.quality_profile()
        return {"samples_per_pixel": p.samples, "use_denoising": p.denoise,
                "denoising_quality": p.denoising_quality,
                "denoising_prefilter": p.denoising_prefilter}

    def renderer_settings(self, **options) -> dict:
        """Keyword settings of :func:`kubric.renderer.create` for ``self.renderer``: Blender gets
        the quality profile (:meth:`renderer_quality`) and ``options``; other backends ``options``
        only (they have no path-traced RGB to tune)."""
        if self.renderer == "blender":
            return {**self.renderer_quality(), **options}
        return dict(options)

    def render_metadata(self, renderer) -> dict:
        """``metadata["renderer"]``: the renderer's own ``settings()``, plus the quality profile's
        name where it applies (Blender)."""
        settings = renderer.settings()
        if self.renderer == "blender":
            settings["quality"] = self.quality
        return settings
