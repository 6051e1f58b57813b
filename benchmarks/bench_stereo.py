"""Time a stereo MOVi-A scene against a mono one: the whole recipe (``generate``: build, one
simulation, render every layer of every camera, annotations, point tracks, writing and the
write-time check), the same seed and options, ``cameras=stereo`` the only difference.

A stereo scene simulates once and renders twice, so its cost is at most twice the mono scene's;
the issue's target is ≤ 2.1×. Reported: CPU seconds per scene (median of ``--repeat`` runs,
mono and stereo interleaved, the stable measure on a shared machine) and the ratio.

Run: ``.venv/bin/python benchmarks/bench_stereo.py [--size 128] [--frames 8] [--seed 3]
[--repeat 3] [--renderer raycast|blender] [--samples 16]``.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import tempfile

import smoke_mode
from bench_raycast import cpu_seconds

from kubric.pipeline import get_recipe


def scene_cost(options: list[str], seed: int) -> float:
    """CPU seconds of one ``movi_a`` scene with ``options`` (``key=value``)."""
    recipe = get_recipe("movi_a").from_assignments(options)
    recipe.prepare()
    with tempfile.TemporaryDirectory() as out:
        start = cpu_seconds()
        recipe.generate(seed, pathlib.Path(out) / "scene")
        return cpu_seconds() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=smoke_mode.size(128, 16))
    ap.add_argument("--frames", type=int, default=smoke_mode.size(8, 2))
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=smoke_mode.size(3, 1))
    ap.add_argument("--renderer", default="raycast", choices=("raycast", "blender"))
    ap.add_argument("--samples", type=int, default=smoke_mode.size(16, 1))
    args = ap.parse_args()
    options = [f"resolution={args.size}", f"frame_end={args.frames}",
               f"renderer={args.renderer}", "tracks=64", "track_stride=2"]
    if args.renderer == "blender":
        options += [f"samples={args.samples}", "denoise=false"]
    scene_cost(options, args.seed)  # warm-up: asset sources, imports, mesh files
    costs = {"mono": [], "stereo": []}
    for _ in range(args.repeat):
        costs["mono"].append(scene_cost(options, args.seed))
        costs["stereo"].append(scene_cost(options + ["cameras=stereo"], args.seed))
    mono = statistics.median(costs["mono"])
    stereo = statistics.median(costs["stereo"])
    print(f"movi_a seed {args.seed}, {args.size}², frames 1..{args.frames}, {args.renderer}, "
          f"median of {args.repeat}")
    print(f"  mono   {mono:.3f} CPU-s/scene")
    print(f"  stereo {stereo:.3f} CPU-s/scene ({stereo / mono:.2f}× mono; target ≤ 2.1×)")


if __name__ == "__main__":
    main()
