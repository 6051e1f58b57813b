"""Time a distorted camera against a pinhole one at the same output size (every layer: rgba and
the eight exact layers), on the same simulated MOVi-A scene in one run: the raycast backend, and
with ``--blender`` also Cycles (a custom OSL lens camera; ``--samples`` per pixel).

The lens's camera-frame pixel rays are computed once per (lens, intrinsics, size) and reused for
every frame (:func:`kubric.core.camera_geometry.pixel_centre_rays`), so the per-frame cost of a
lens is the rotation of those rays and the projection of the flow targets through the model.
Reported: CPU seconds per frame (the stable measure on a shared machine) and the ratio to the
pinhole; the first frame (which pays for the rays and the mesh files) is timed separately.

Run: ``.venv/bin/python benchmarks/bench_lens.py [--size 256] [--frames 8] [--seed 3]
[--blender] [--samples 16] [--repeat 3]``. Frames 2.. are rendered ``--repeat`` times, the
lenses interleaved, and the median is reported.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile

import smoke_mode
from bench_raycast import cpu_seconds, simulated_scene

from kubric.core import lenses
from kubric.recipes.lens_options import DEFAULT_COEFFICIENTS
from kubric.renderer import ALL_LAYERS, create

LENSES = {"pinhole": lenses.PINHOLE,
          # all but pinhole: k1 = 1e-9 sends it through the lens machinery (Blender: the custom
          # OSL camera) with a pinhole's image — what the machinery itself costs
          "near-pinhole": lenses.from_record("opencv", (1e-9, 0.0, 0.0, 0.0, 0.0)),
          "opencv": lenses.from_record("opencv", DEFAULT_COEFFICIENTS["opencv"]),
          "fisheye": lenses.from_record("fisheye", DEFAULT_COEFFICIENTS["fisheye"])}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=smoke_mode.size(256, 16))
    ap.add_argument("--frames", type=int, default=smoke_mode.size(8, 2))
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--blender", action="store_true")
    ap.add_argument("--samples", type=int, default=smoke_mode.size(16, 1))
    ap.add_argument("--repeat", type=int, default=smoke_mode.size(3, 1))
    args = ap.parse_args()
    scene = simulated_scene("movi_a", args.size, args.frames, args.seed, "renderer=raycast")
    rest = list(range(2, args.frames + 1))
    backends = {"raycast": {}}
    if args.blender:
        backends["blender"] = {"samples_per_pixel": args.samples, "use_denoising": False}
    for backend, settings in backends.items():
        scratch = tempfile.TemporaryDirectory()
        renderer = create(backend, scene, scratch.name, **settings)  # one per scene (Blender)
        first, per_frame = {}, {name: [] for name in LENSES}
        for name, lens in LENSES.items():  # the first frame pays for rays, meshes, kernels
            scene.camera.lens = lens
            start = cpu_seconds()
            renderer.render(frames=[1], return_layers=ALL_LAYERS)
            first[name] = cpu_seconds() - start
        for _ in range(args.repeat):  # interleaved, so a load change hits every lens alike
            for name, lens in LENSES.items():
                scene.camera.lens = lens
                start = cpu_seconds()
                renderer.render(frames=rest, return_layers=ALL_LAYERS)
                per_frame[name].append((cpu_seconds() - start) / len(rest))
        scratch.cleanup()
        print(f"movi_a seed {args.seed}, {args.size}², frames 2..{args.frames}, median of "
              f"{args.repeat} interleaved runs (all layers, {backend} {settings or ''})")
        base = statistics.median(per_frame["pinhole"])
        for name, runs in per_frame.items():
            median = statistics.median(runs)
            print(f"  {name:12s} {median:.3f} CPU-s/frame ({median / base:.2f}× pinhole; runs "
                  f"{', '.join(f'{r:.3f}' for r in runs)}); first frame {first[name]:.2f} CPU-s")

if __name__ == "__main__":
    main()
