"""Time what cloth adds to a scene: the PyBullet simulation of ``--cloths`` sheets against the
render of the same scene (RGB + exact layers), in the same run (issue #36's goal: the cloth
simulation ≤ 25 % of the default scene's render cost at 256²).

Scene: a MOVi-C-like default scene simulated, not keyframed: a floor, 10 dynamic cubes and spheres
dropped from 1–3 m, ``--cloths`` checker-textured sheets (``kubric.recipes.deformable_objects``:
16² vertices, edge 1.5–3 m) above them; ``--frames`` frames at 12 frames/s, 240 steps/s, ``--size``², RGB at
``--samples`` spp (OIDN on) plus the exact annotation pass. Measured (CPU seconds, the least of 3
runs for the simulations): the simulation with the sheets minus the same simulation without them,
and the render of the scene with the sheets (``--render-frames K``: only K frames spread evenly
over the range are rendered and their cost is scaled by (frames + 1) / K, printed as such: the
render's cost per frame is about constant, so this estimates the full render on a machine where
rendering every frame does not fit).
Run: ``.venv/bin/python benchmarks/bench_deformables.py [--samples 64] [--frames 24]``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import smoke_mode  # noqa: E402
from bench_render import timed  # noqa: E402

import kubric as kb  # noqa: E402
from kubric.recipes.deformable_objects import add_deformables  # noqa: E402


def make_scene(args, cloths: int, folder) -> kb.Scene:
    rng = np.random.RandomState(0)
    scene = kb.Scene(resolution=(args.size, args.size), frame_start=0, frame_end=args.frames,
                     frame_rate=12, step_rate=240)
    scene += kb.Cube(name="floor", scale=(20, 20, 0.5), position=(0, 0, -0.5), static=True,
                     background=True)
    scene += kb.DirectionalLight(position=(3, -2, 6), look_at=(0, 0, 0), intensity=2.0)
    scene.ambient_illumination = kb.Color(0.05, 0.05, 0.05)
    scene += kb.PerspectiveCamera(position=(6, -6, 5), look_at=(0, 0, 0.5), focal_length=35)
    for k in range(10):
        cls = kb.Cube if k % 2 else kb.Sphere
        scene += cls(scale=float(rng.uniform(0.2, 0.4)), mass=1.0,
                     position=(*rng.uniform(-1.5, 1.5, 2), float(rng.uniform(1, 3))),
                     material=kb.PrincipledBSDFMaterial(color=kb.random_hue_color(rng=rng)))
    add_deformables(scene, rng, cloths, 0, folder)
    return scene


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=smoke_mode.size(64, 1))
    parser.add_argument("--frames", type=int, default=smoke_mode.size(24, 2))
    parser.add_argument("--size", type=int, default=smoke_mode.size(256, 16))
    parser.add_argument("--cloths", type=int, default=smoke_mode.size(2, 1))
    parser.add_argument("--render-frames", type=int, default=None,
                        help="render only this many frames, evenly spread (default: all)")
    args = parser.parse_args(argv)
    repeats = smoke_mode.size(3, 1)
    folder = pathlib.Path(tempfile.mkdtemp(prefix="kubric-bench-cloth-"))

    def simulated(cloths):
        scene = make_scene(args, cloths, folder)
        kb.simulator.PyBullet(scene).run(0, args.frames)
        return scene

    def best(cloths):
        runs = [timed(lambda: simulated(cloths)) for _ in range(repeats)]
        return runs[-1][0], min(r[1] for r in runs)

    _, bare_cpu = best(0)
    scene, cloth_cpu = best(args.cloths)
    extra = max(0.0, cloth_cpu - bare_cpu)
    renderer = kb.renderer.Blender(scene, samples_per_pixel=args.samples, use_denoising=True)
    all_frames = args.frames + 1
    k = all_frames if args.render_frames is None else args.render_frames
    if not 1 <= k <= all_frames:
        raise SystemExit(f"--render-frames {k}: allowed 1..{all_frames}")
    frames = sorted({int(round(x)) for x in np.linspace(0, args.frames, k)})
    _, render_cpu, render_wall = timed(lambda: renderer.render(frames=frames))
    scale = all_frames / len(frames)
    if scale != 1:
        print(f"rendered frames {frames}: {render_cpu:.3f} CPU-s ({render_wall:.2f} s wall), "
              f"scaled by {all_frames}/{len(frames)} to the {all_frames} frames")
        render_cpu, render_wall = render_cpu * scale, render_wall * scale
    print(f"scene: {args.frames + 1} frames {args.size}², floor + 10 falling objects + "
          f"{args.cloths} cloth sheets (16² vertices); RGB {args.samples} spp + OIDN + "
          "annotation pass")
    print(f"render (RGB + layers)     : {render_cpu:8.3f} CPU-s ({render_wall:.2f} s wall)"
          + (" (scaled)" if scale != 1 else ""))
    print(f"simulation without cloth  : {bare_cpu:8.3f} CPU-s")
    print(f"cloth simulation (extra)  : {extra:8.3f} CPU-s")
    print(f"cloth simulation / render : {100 * extra / render_cpu:.2f}% (goal ≤ 25%)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
