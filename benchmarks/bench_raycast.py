"""Time the raycast backend against Cycles' exact annotation layers on a real MOVi scene, in the
same run (the ratio is what to quote on a loaded machine).

Both render the same eight exact layers (depth, z, segmentation, forward/backward flow, normal,
object coordinates, uv) of the same simulated scene. Reported per frame: wall and CPU seconds of
``render()``; the one-off set-up (Blender: reset + linking the scene; raycast: reading the mesh
files) separately. Raycast also renders its simple rgba in a third timing.

Run: ``.venv/bin/python benchmarks/bench_raycast.py [--recipe movi_a] [--size 256] [--frames 8]``.
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time

import numpy as np
import smoke_mode

import kubric as kb
from kubric.pipeline import get_recipe
from kubric.renderer import ANNOTATION_LAYERS, create


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(fn):
    w, c = time.perf_counter(), cpu_seconds()
    value = fn()
    return value, time.perf_counter() - w, cpu_seconds() - c


def simulated_scene(recipe: str, size: int, frames: int, seed: int, *options: str):
    """The recipe's scene for ``seed`` (size², frames 1..frames, ``options`` as ``key=value``),
    populated and simulated, not rendered."""
    rec = get_recipe(recipe).from_assignments([f"resolution={size}", f"frame_end={frames}",
                                               *options])
    with tempfile.TemporaryDirectory() as scratch:
        scene = rec.make_scene()
        sim = kb.simulator.PyBullet(scene, scratch)
        rec.populate(scene, sim, np.random.RandomState(seed), rec.open_sources())
        sim.run(frame_start=0, frame_end=scene.frame_end + 1)
        sim.close()
    return scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="movi_a")
    ap.add_argument("--size", type=int, default=smoke_mode.size(256, 16))
    ap.add_argument("--frames", type=int, default=smoke_mode.size(8, 2))
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    scene = simulated_scene(args.recipe, args.size, args.frames, args.seed)
    with tempfile.TemporaryDirectory() as scratch:
        n = args.frames
        ray = create("raycast", scene)
        _, setup_r, _ = timed(lambda: ray.render(frames=[1], return_layers=("segmentation",)))
        _, wall_r, cpu_r = timed(lambda: ray.render(return_layers=ANNOTATION_LAYERS))
        _, wall_rgba, cpu_rgba = timed(lambda: ray.render(return_layers=("rgba",)))
        cycles, setup_c, _ = timed(lambda: create("blender", scene, scratch, samples_per_pixel=1,
                                                  use_denoising=False))
        _, wall_c, cpu_c = timed(lambda: cycles.render(return_layers=ANNOTATION_LAYERS))
    print(f"{args.recipe} seed {args.seed}, {args.size}², {n} frames, {len(scene.assets)} assets")
    print(f"raycast exact layers: {wall_r / n:.3f} s/frame wall, {cpu_r / n:.3f} CPU-s/frame "
          f"(set-up incl. mesh files {setup_r:.2f} s)")
    print(f"raycast rgba:         {wall_rgba / n:.3f} s/frame wall, {cpu_rgba / n:.3f} CPU-s/frame")
    print(f"Cycles exact layers:  {wall_c / n:.3f} s/frame wall, {cpu_c / n:.3f} CPU-s/frame "
          f"(set-up {setup_c:.2f} s)")
    print(f"ratio Cycles / raycast (exact layers): wall {wall_c / wall_r:.1f}×, "
          f"CPU {cpu_c / cpu_r:.1f}×")


if __name__ == "__main__":
    main()
