"""Time exact point tracks against the render of the same scene: 2048 tracks over 24 frames at
256² (TAP-Vid sampling, per-frame poses, projection, occlusion, visible fraction, tracks.npz
written) vs rendering that scene (RGB at ``--samples`` spp plus the exact annotation layers the
tracks are computed from), all in the same run.

Scene: bench_render's MOVi-like scene (floor, 10 moving cubes and spheres, 24 frames at 256²).
Run: ``.venv/bin/python benchmarks/bench_tracks.py [--samples 64] [--tracks 2048]``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import smoke_mode  # noqa: E402
from bench_render import movi_like_scene, timed  # noqa: E402

import kubric as kb  # noqa: E402
from kubric.annotations import tracks as tr  # noqa: E402
from kubric.annotations.track_files import write_tracks  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=smoke_mode.size(64, 1))
    parser.add_argument("--frames", type=int, default=smoke_mode.size(24, 2))
    parser.add_argument("--size", type=int, default=smoke_mode.size(256, 32))
    parser.add_argument("--tracks", type=int, default=smoke_mode.size(2048, 16))
    args = parser.parse_args(argv)

    scene = movi_like_scene(np.random.default_rng(0), args.frames, args.size)
    renderer = kb.renderer.Blender(scene, samples_per_pixel=args.samples, use_denoising=False)
    _, rgb_cpu, rgb_wall = timed(lambda: renderer.render(return_layers=("rgba",)))
    layers, ann_cpu, ann_wall = timed(lambda: renderer.render(
        return_layers=("depth", "segmentation")))
    objects = [a for a in scene.foreground_assets if isinstance(a, kb.PhysicalObject)]

    def make_tracks():
        rng = np.random.RandomState(0)
        out = tr.scene_tracks(scene, layers, objects, rng, num_tracks=args.tracks)
        with tempfile.TemporaryDirectory() as tmp:
            write_tracks(out, pathlib.Path(tmp) / "tracks.npz")
        return out

    out, trk_cpu, trk_wall = timed(make_tracks)
    assert out["target_points"].shape == (args.tracks, args.frames, 2)
    render_cpu, render_wall = rgb_cpu + ann_cpu, rgb_wall + ann_wall
    print(f"scene: {args.frames} frames {args.size}², 10 objects + floor; RGB at {args.samples} "
          f"spp, no denoising")
    print(f"render RGB          : {rgb_cpu:8.2f} CPU-s ({rgb_wall:.2f} s wall)")
    print(f"render depth + seg  : {ann_cpu:8.2f} CPU-s ({ann_wall:.2f} s wall)  [1-spp pass]")
    print(f"{args.tracks} tracks        : {trk_cpu:8.2f} CPU-s ({trk_wall:.2f} s wall)  "
          f"[{int(out['is_foreground'].sum())} on objects, occluded "
          f"{float(out['occluded'].mean()):.1%} of point-frames; sampling, poses, projection, "
          f"occlusion, visible fraction, tracks.npz]")
    print(f"ratio tracks / render (RGB + layers): {trk_cpu / render_cpu:.4f} CPU, "
          f"{trk_wall / render_wall:.4f} wall")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
