"""Render quality profiles: the RGB render's samples and denoiser, chosen by one ``quality`` option.

Every recipe that path-traces RGB mixes in :class:`RenderQuality`: ``--set quality=draft|fast|
default|final`` picks a profile, and ``samples`` / ``denoise`` (unset by default) override its
fields. The exact layers (depth, segmentation, flow, normals, object coordinates, UV) come from a
separate 1-sample render with no denoising, so they are bit-identical under every profile.

* ``draft``: 4 spp, OIDN BALANCED with the FAST prefilter — previews and pipeline debugging.
* ``fast``: 8 spp, OIDN BALANCED / FAST — the cheapest profile at upstream Kubric's MOVi-A quality
  (RMSE ≤ 1.07 at ≤ 23 CPU-s per MOVi-A scene; the FAST prefilter makes OIDN nearly free, so the
  budget buys samples).
* ``default``: **calibrated per recipe** — :data:`CALIBRATED_DEFAULTS`, chosen by the rule of
  :func:`choose_default` from ``benchmarks/bench_quality_calibration.py``'s table (every recipe at
  its own resolution and content, three seeds, errors against a 1024-spp reference over all,
  object, edge and textured pixels and 1 − SSIM). A recipe outside the table gets 16 spp + OIDN
  HIGH / ACCURATE.
* ``final``: 64 spp, OIDN HIGH / ACCURATE — the rule's yardstick; lowest noise on objects.

``metadata["renderer"]`` records the profile's name (``quality``), the resolved setting in one line
(``quality_setting``) and the resolved renderer fields. Measured numbers: docs/render-cost.md.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

from kubric.pipeline import Option, OptionError
from kubric.recipes.render_levers import RenderLevers
from kubric.renderer.base import BACKENDS, capabilities, refusal


@dataclass(frozen=True)
class QualityProfile:
    """The RGB render settings of one quality level (OIDN names as Blender's)."""
    samples: int                 # Cycles samples per pixel (with adaptive sampling: the most)
    denoise: bool                # OIDN on the RGB render
    denoising_quality: str       # HIGH | BALANCED | FAST (OIDN network size)
    denoising_prefilter: str     # ACCURATE | FAST | NONE (cleaning of the albedo/normal guides)
    adaptive_threshold: float | None = None  # Cycles' noise threshold; None = adaptive off
    #: reuse freed frame buffers (kubric.renderer.allocator): ~0.5 CPU-s per MOVi-A scene for
    #: 40–100 MiB of peak RSS, so only the cheap profiles, where that is 2 % of a scene, ask for it
    keep_freed_memory: bool = False
    #: Cycles' noise levers (kubric.renderer.blender_sampling; the defaults are Blender's):
    path_guiding: str = "off"            # off | surface | volume | all (CPU only)
    clamp_direct: float = 0.0            # largest direct-light sample value; 0 = no clamp
    clamp_indirect: float = 10.0         # largest indirect-light sample value; 0 = no clamp
    filter_glossy: float = 1.0           # blur of glossy after blurry bounces (0–10)
    adaptive_min_samples: int = 0        # samples before adaptive sampling may stop; 0 = auto
    #: OIDN's guides and the per-sample cost levers (blender_sampling; defaults Blender's)
    denoising_input_passes: str = "RGB_ALBEDO_NORMAL"  # RGB | RGB_ALBEDO | RGB_ALBEDO_NORMAL
    total_bounces: int = 12
    diffuse_bounces: int = 4
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    fast_gi: int = 0                     # 0 = off; N = AO replaces light after N bounces
    light_threshold: float = 0.01        # lights estimated below it are not sampled
    caustics: bool = True                # reflective and refractive caustics
    min_light_bounces: int = 0           # bounces before Russian roulette
    scrambling_distance: float | str = 1.0  # [0, 1] or "auto"
    tile_size: int = 2048                # render tile side, px

    def levers(self) -> dict:
        """The noise levers that differ from Blender's defaults ({Blender option: value})."""
        from kubric.renderer.blender_sampling import BLENDER_DEFAULTS
        return {name: getattr(self, name) for name, default in BLENDER_DEFAULTS.items()
                if getattr(self, name) != default}

    @property
    def label(self) -> str:
        """One readable line that names the setting, e.g. ``32 spp + OIDN HIGH/FAST`` or
        ``≤64 spp adaptive 0.2 min 16 + OIDN HIGH/ACCURATE, guiding surface, clamp 0/1``."""
        spp = (f"≤{self.samples} spp adaptive {self.adaptive_threshold:g}"
               if self.adaptive_threshold else f"{self.samples} spp")
        if self.adaptive_threshold and self.adaptive_min_samples:
            spp += f" min {self.adaptive_min_samples}"
        out = spp + (f" + OIDN {self.denoising_quality}/{self.denoising_prefilter}"
                     if self.denoise else ", no denoising")
        levers = self.levers()
        if "path_guiding" in levers:
            out += f", guiding {self.path_guiding}"
        if "clamp_direct" in levers or "clamp_indirect" in levers:
            out += f", clamp {self.clamp_direct:g}/{self.clamp_indirect:g}"
        if "filter_glossy" in levers:
            out += f", filter glossy {self.filter_glossy:g}"
        return out + self._cost_label(levers)

    def _cost_label(self, levers: dict) -> str:
        """The label's part for OIDN's guides and the per-sample cost levers."""
        out = ""
        if "denoising_input_passes" in levers:
            out += ", OIDN guides " + {"RGB": "none", "RGB_ALBEDO": "albedo"}.get(
                self.denoising_input_passes, "albedo+normal")
        if {"total_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces"} & \
                set(levers):
            out += (f", bounces {self.total_bounces}/{self.diffuse_bounces}/"
                    f"{self.glossy_bounces}/{self.transmission_bounces}")
        if "fast_gi" in levers:
            out += f", fast GI {self.fast_gi}"
        if "light_threshold" in levers:
            out += f", light threshold {self.light_threshold:g}"
        if "caustics" in levers:
            out += ", no caustics"
        if "min_light_bounces" in levers:
            out += f", min light bounces {self.min_light_bounces}"
        if "scrambling_distance" in levers:
            d = self.scrambling_distance
            out += f", scrambling {d if d == 'auto' else format(d, 'g')}"
        if "tile_size" in levers:
            out += f", tile {self.tile_size}"
        return out


def _oidn(samples, quality="HIGH", prefilter="ACCURATE", adaptive=None) -> QualityProfile:
    return QualityProfile(samples, True, quality, prefilter, adaptive)


#: The settings every recipe is calibrated on (benchmarks/bench_quality_calibration.py), in the
#: order the table lists them: sample counts with the full denoiser, OIDN's cheaper prefilters
#: and networks, and adaptive sampling with a noise threshold. ANCHOR is the rule's yardstick.
CALIBRATION_SETTINGS: tuple[QualityProfile, ...] = (
    _oidn(4, "BALANCED", "FAST"), _oidn(6, "BALANCED", "FAST"), _oidn(8, "BALANCED", "FAST"),
    _oidn(8), _oidn(16), _oidn(16, prefilter="FAST"), _oidn(16, prefilter="NONE"), _oidn(24),
    _oidn(32), _oidn(32, prefilter="FAST"), _oidn(48), _oidn(48, prefilter="FAST"), _oidn(64),
    _oidn(64, adaptive=0.05), _oidn(64, adaptive=0.1))
ANCHOR = _oidn(64)

#: The rule that picks a recipe's default from its calibration: the cheapest setting (CPU-s per
#: frame or view) whose error on every measure is at most RULE_FACTOR × the ANCHOR setting's,
#: errors pooled over the calibration's seeds. Measures: RGB RMSE (8-bit values) over all pixels,
#: object pixels, edge pixels and textured pixels, and 1 − SSIM.
RULE_FACTOR = 1.15
RULE_MEASURES = ("rmse_all", "rmse_objects", "rmse_edges", "rmse_textured", "dssim")


def choose_default(rows: dict[str, dict]) -> str:
    """The label the rule picks from ``{label: {"cpu": CPU-s per frame, measure: error}}`` (a
    measure that is None, e.g. no textured pixels in any seed, is left out of the comparison)."""
    if ANCHOR.label not in rows:
        raise ValueError(f"the calibration has no {ANCHOR.label!r} row; it has {sorted(rows)}")
    anchor = rows[ANCHOR.label]
    passing = [label for label, row in rows.items()
               if all(row[m] <= RULE_FACTOR * anchor[m] for m in RULE_MEASURES
                      if anchor[m] is not None and row[m] is not None)]
    return min(passing, key=lambda label: rows[label]["cpu"])


PROFILES: dict[str, QualityProfile] = {
    "draft": replace(_oidn(4, "BALANCED", "FAST"), keep_freed_memory=True),
    "fast": replace(_oidn(8, "BALANCED", "FAST"), keep_freed_memory=True),
    "default": _oidn(16),
    "final": _oidn(64),
}

#: Each built-in recipe's ``default``, chosen by :func:`choose_default` from the calibration
#: (docs/data/render-calibration.json, tabled in docs/render-cost.md); a recipe not listed (a
#: user's) gets PROFILES["default"]. tests/test_render_calibration.py re-applies the rule.
CALIBRATED_DEFAULTS: dict[str, QualityProfile] = {
    "movi_a": _oidn(64, adaptive=0.1), "movi_b": _oidn(64, adaptive=0.1),
    "movi_c": _oidn(64, adaptive=0.1), "movi_d": _oidn(48), "movi_e": _oidn(64, adaptive=0.1),
    "movi_f": _oidn(48), "complex_brdf": _oidn(64), "klevr": _oidn(48),
    "toybox": _oidn(64, adaptive=0.05), "multiview_matting": _oidn(64, adaptive=0.05),
    "nvs": _oidn(64, adaptive=0.05), "robust_nerf": _oidn(48), "svr": _oidn(64, adaptive=0.05),
    "texture_nerf": _oidn(64), "pose_estimation": _oidn(48), "vbr": _oidn(64),
}


def profile_by_label(label: str) -> QualityProfile:
    """The calibration setting (or profile) whose :attr:`QualityProfile.label` is ``label``."""
    for p in (*CALIBRATION_SETTINGS, *PROFILES.values()):
        if p.label == label:
            return p
    raise ValueError(f"unknown render setting {label!r}; known: "
                     f"{[p.label for p in CALIBRATION_SETTINGS]}")


def _profile_help() -> str:
    return "; ".join(f"{name}: " + ("the recipe's calibrated setting" if name == "default"
                                     else p.label) for name, p in PROFILES.items())


def _backends_help() -> str:
    """The ``renderer`` option's help: each backend of BACKENDS with what it can do."""
    rows = []
    for name, row in BACKENDS.items():
        caps = row.capabilities
        can = ["photoreal RGB" if caps.photoreal else "RGB not photoreal"]
        can += sorted(caps.effects) + (["saves state"] if caps.can_save_state else [])
        rows.append(f"{name}: {', '.join(can)}")
    return "; ".join(rows)


class RenderQuality(RenderLevers):
    """Mixin of every recipe that renders: the ``renderer`` option (a backend of
    :data:`kubric.renderer.base.BACKENDS`), the ``quality`` / ``samples`` / ``denoise`` options,
    Cycles' levers (:class:`~kubric.recipes.render_levers.RenderLevers`: ``clamp_indirect``,
    ``fast_gi``, ...) and their resolution into renderer keyword arguments and
    ``metadata["renderer"]`` fields.

    A recipe asks its backend for capabilities, never for a name: :attr:`renderer_needs` (what
    it always needs, e.g. ``("photoreal",)``) and :meth:`renderer_requests` (what its options
    ask for) are checked by :meth:`check_renderer` before anything renders — one line naming the
    backend, the request and the backends that can. The quality profile applies to backends with
    ``quality_profiles``."""

    renderer = Option("blender", "rendering backend (docs/renderers.md): " + _backends_help(),
                      choices=tuple(BACKENDS))
    #: capabilities (kubric.renderer.base.NEEDS) this recipe always needs of its backend
    renderer_needs: ClassVar[tuple[str, ...]] = ()

    quality = Option("default", "RGB render quality profile (" + _profile_help() +
                     "; measured cost and error in docs/render-cost.md)", choices=tuple(PROFILES))
    samples = Option(None, "Cycles samples per pixel, exactly (default: the quality profile's; "
                     "turns the profile's adaptive sampling off)", type=int,
                     low=1, high=65536, limit=4096)
    denoise = Option(None, "denoise the RGB render with OIDN (default: the quality profile's)",
                     type=bool)

    def base_profile(self) -> QualityProfile:
        """The chosen profile before overrides: ``default`` is this recipe's calibrated setting
        (:data:`CALIBRATED_DEFAULTS`) where it has one."""
        if self.quality == "default":
            return CALIBRATED_DEFAULTS.get(self.name, PROFILES["default"])
        return PROFILES[self.quality]

    def quality_profile(self) -> QualityProfile:
        """The chosen profile with ``samples`` / ``denoise`` and lever overrides applied:
        ``samples=N`` is exactly N samples per pixel (a profile's adaptive sampling is turned off
        with it)."""
        p = replace(self.base_profile(), **self.lever_overrides())
        if self.denoise is not None:
            p = replace(p, denoise=self.denoise)
        if self.samples is not None:
            p = replace(p, samples=self.samples, adaptive_threshold=None)
        return p

    def renderer_quality(self) -> dict:
        """Keyword arguments of :class:`kubric.renderer.Blender` for the RGB render."""
        p = self.quality_profile()
        out = {"samples_per_pixel": p.samples, "use_denoising": p.denoise,
               "denoising_quality": p.denoising_quality,
               "denoising_prefilter": p.denoising_prefilter}
        if p.adaptive_threshold:
            out.update(adaptive_sampling=True, adaptive_threshold=p.adaptive_threshold)
        if p.keep_freed_memory:
            out["keep_freed_memory"] = True
        out.update(p.levers())
        return out

    def renderer_requests(self) -> dict[str, str]:
        """What this recipe's options ask of its backend: capability (NEEDS) → the request, for
        :meth:`check_renderer`. Recipes extend it (e.g. ``max_motion_blur`` → motion_blur)."""
        out = {need: f"the {self.name} recipe" for need in self.renderer_needs}
        given = [f"{name}={getattr(self, name)}" for name in ("samples", "denoise")
                 if getattr(self, name) is not None]
        given += [f"{name}={value}" for name, value in self.lever_overrides().items()]
        if self.quality != "default":
            given.append(f"quality={self.quality}")
        if given:
            out["quality_profiles"] = ", ".join(given)
        return out

    def check_renderer(self) -> None:
        """One line (OptionError) when the chosen backend lacks a capability the recipe or its
        options ask for (:meth:`renderer_requests`)."""
        message = refusal(self.renderer, self.renderer_requests(), self.name)
        if message:
            raise OptionError(message)

    def renderer_settings(self, **options) -> dict:
        """Keyword settings of :func:`kubric.renderer.create` for ``self.renderer``: a backend
        with ``quality_profiles`` gets the quality profile (:meth:`renderer_quality`) and
        ``options``; others ``options`` only (they have no path-traced RGB to tune)."""
        if capabilities(self.renderer).quality_profiles:
            return {**self.renderer_quality(), **options}
        return dict(options)

    def render_metadata(self, renderer) -> dict:
        """``metadata["renderer"]``: the renderer's own ``settings()``, plus the quality profile's
        name where it applies (``quality_profiles``)."""
        settings = renderer.settings()
        if capabilities(self.renderer).quality_profiles:
            settings["quality"] = self.quality
            settings["quality_setting"] = self.quality_profile().label
        return settings
