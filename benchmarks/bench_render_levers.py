"""The render-cost levers one by one: CPU-s per frame and RGB RMSE against a 1024-spp reference.

One MOVi-A scene (seed 3, its defaults: 256², 24 frames) is built once; frames 1–4 are rendered in
this process under each Cycles setting (samples, OIDN on/off, OIDN quality and prefilter, guide
passes, sampling pattern, adaptive sampling, light tree, caustics, fewer bounces), every setting
starting from the recipe's renderer state (no setting leaks into the next). Quality: RMSE of the
8-bit RGB against a 1024-spp undenoised reference of the same frames rendered first in the same
process, over all pixels, object pixels and a band of ±2 px around segmentation edges. Cost: process
CPU seconds (every thread) per frame, after a warm-up render. This is the curve behind the
``quality`` profiles (kubric/recipes/render_quality.py, docs/render-cost.md).

Run: ``.venv/bin/python benchmarks/bench_render_levers.py [--seed 3] [--reference-samples 1024]
[--set KEY=VALUE ...]``. About 10 min on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import smoke_mode  # noqa: E402
from bench_quality_calibration import with_renderer  # noqa: E402
from bench_scene_cost import edge_band, rmse  # noqa: E402

#: (label, renderer options, extra Cycles attributes)
HIGH = {"denoising_quality": "HIGH", "denoising_prefilter": "ACCURATE"}
LEVERS = [
    *[(f"{n} spp + OIDN", {"samples_per_pixel": n, "use_denoising": True, **HIGH}, {})
      for n in (4, 8, 12, 16, 24, 32, 64)],
    ("16 spp, no denoising", {"samples_per_pixel": 16, "use_denoising": False}, {}),
    ("64 spp, no denoising", {"samples_per_pixel": 64, "use_denoising": False}, {}),
    ("16 spp + OIDN BALANCED", {"samples_per_pixel": 16, "denoising_quality": "BALANCED"}, {}),
    ("16 spp + OIDN FAST", {"samples_per_pixel": 16, "denoising_quality": "FAST"}, {}),
    ("16 spp + OIDN prefilter FAST", {"samples_per_pixel": 16, "denoising_prefilter": "FAST"},
     {}),
    ("16 spp + OIDN prefilter NONE", {"samples_per_pixel": 16, "denoising_prefilter": "NONE"},
     {}),
    ("16 spp + OIDN, albedo guide only", {"samples_per_pixel": 16},
     {"denoising_input_passes": "RGB_ALBEDO"}),
    ("16 spp + OIDN, blue-noise pattern", {"samples_per_pixel": 16},
     {"sampling_pattern": "BLUE_NOISE"}),
    ("16 spp + OIDN, light tree", {"samples_per_pixel": 16}, {"use_light_tree": True}),
    ("16 spp + OIDN, no caustics", {"samples_per_pixel": 16},
     {"caustics_reflective": False, "caustics_refractive": False}),
    ("16 spp + OIDN, bounces 2/2/4", {"samples_per_pixel": 16},
     {"diffuse_bounces": 2, "glossy_bounces": 2, "max_bounces": 4, "transmission_bounces": 4}),
    ("64 spp + OIDN, adaptive 0.01", {"samples_per_pixel": 64, "adaptive_sampling": True,
                                      "adaptive_threshold": 0.01}, {}),
    ("64 spp + OIDN, adaptive 0.03", {"samples_per_pixel": 64, "adaptive_sampling": True,
                                      "adaptive_threshold": 0.03}, {}),
    ("64 spp + OIDN, adaptive 0.1 (default)", {"samples_per_pixel": 64,
                                                "adaptive_sampling": True,
                                                "adaptive_threshold": 0.1}, {}),
    ("8 spp + OIDN prefilter FAST", {"samples_per_pixel": 8, "denoising_prefilter": "FAST"}, {}),
    ("8 spp + OIDN BALANCED", {"samples_per_pixel": 8, "denoising_quality": "BALANCED"}, {}),
    ("8 spp + OIDN BALANCED/FAST (fast)", {"samples_per_pixel": 8,
                                            "denoising_quality": "BALANCED",
                                            "denoising_prefilter": "FAST"}, {}),
    ("4 spp + OIDN BALANCED/FAST (draft)", {"samples_per_pixel": 4,
                                             "denoising_quality": "BALANCED",
                                             "denoising_prefilter": "FAST"}, {}),
]
BASE = {"samples_per_pixel": 16, "use_denoising": True, "adaptive_sampling": False,
        "adaptive_threshold": 0.01, **HIGH}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--reference-samples", type=int, default=smoke_mode.size(1024, 4))
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        default=smoke_mode.size([], ["resolution=16"]))
    args = parser.parse_args(argv)
    os.environ.setdefault("KUBRIC_CACHE_DIR",
                          str(pathlib.Path(__file__).resolve().parents[1] / ".cache" / "kubric"))
    from kubric.renderer import blender
    frames = smoke_mode.size([1, 2, 3, 4], [1])
    with tempfile.TemporaryDirectory(prefix="bench_levers_") as tmp:
        # the MOVi-A recipe's renderer for the seed, stopped just before it renders
        r = with_renderer("movi_a", args.seed, args.set, pathlib.Path(tmp), lambda r: r)
        cycles = r.bpy_scene.cycles
        extra: dict = {}
        defaults: dict = {}
        configure = blender.Blender._configure_rgb

        def configure_with_extra(self, prefix):
            configure(self, prefix)
            for key, value in {**defaults, **extra}.items():
                setattr(cycles, key, value)

        blender.Blender._configure_rgb = configure_with_extra
        seg = r.render(frames, ("segmentation",))["segmentation"][..., 0]
        background = [i for i, a in enumerate(r.scene.assets, start=1)
                      if getattr(a, "background", False)]  # the renderer's labels: asset index
        band, objects = edge_band(seg), (seg > 0) & ~np.isin(seg, background)

        def render(options, attrs):
            nonlocal extra
            for k in attrs:
                defaults.setdefault(k, getattr(cycles, k))
            extra = attrs
            for k, v in {**BASE, **options}.items():
                setattr(r, k, v)
            c0, w0 = time.process_time(), time.perf_counter()
            rgb = r.render(frames, ("rgba",))["rgba"][..., :3]
            return rgb, (time.process_time() - c0) / len(frames), \
                (time.perf_counter() - w0) / len(frames)

        render({"samples_per_pixel": 1}, {})  # warm-up: kernels, OIDN weights
        print(f"reference: {args.reference_samples} spp, no denoising ...", flush=True)
        ref, ref_cpu, _ = render({"samples_per_pixel": args.reference_samples,
                                  "use_denoising": False}, {})
        print(f"MOVi-A seed {args.seed} {', '.join(args.set) or '(defaults: 256², 24 frames)'}, "
              f"frames {frames[0]}-{frames[-1]}; reference {ref_cpu:.1f} CPU-s/frame; "
              f"object pixels {objects.mean():.1%}, edge band {band.mean():.1%}")
        print(f"{'setting':38s} {'CPU-s/frame':>11s} {'wall/frame':>10s} {'RMSE':>6s} "
              f"{'objects':>8s} {'edges':>6s}")
        for label, options, attrs in LEVERS:
            rgb, cpu, wall = render(options, attrs)
            print(f"{label:38s} {cpu:11.2f} {wall:10.2f} {rmse(rgb, ref):6.3f} "
                  f"{rmse(rgb, ref, objects):8.3f} {rmse(rgb, ref, band):6.3f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
