"""Time the Blender renderer on a 24-frame 256² MOVi-like scene: CPU seconds per frame for the RGB
render and for the exact annotation layers, measured separately in the same run.

Scene: a floor, 10 moving cubes and spheres with random Principled materials, a sun, a point light
and a grey ambient light; objects are keyframed every frame (as the simulator does).
Baseline (same run): a plain 1-spp RGB render of the same frames — the annotation render should
cost about that, and its cost must not grow with ``--samples``.

Run: ``.venv/bin/python benchmarks/bench_render.py [--samples 64] [--frames 24] [--size 256]``.
"""

from __future__ import annotations

import argparse
import resource
import time

import numpy as np
import smoke_mode

import kubric as kb
from kubric.renderer.base import ANNOTATION_LAYERS


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def movi_like_scene(rng: np.random.Generator, frames: int, size: int) -> kb.Scene:
    scene = kb.Scene(resolution=(size, size), frame_start=1, frame_end=frames)
    scene.ambient_illumination = kb.Color(0.05, 0.05, 0.05)
    scene += kb.Cube(name="floor", scale=(20, 20, 0.5), position=(0, 0, -0.5), static=True,
                     background=True)
    scene += kb.DirectionalLight(position=(3, -2, 6), look_at=(0, 0, 0), intensity=2.0)
    scene += kb.PointLight(position=(-3, 3, 4), intensity=300)
    scene += kb.PerspectiveCamera(position=(7, -7, 6), look_at=(0, 0, 0.5), focal_length=35)
    for k in range(10):
        cls = kb.Cube if k % 2 else kb.Sphere
        mat = kb.PrincipledBSDFMaterial(color=kb.Color(*rng.uniform(0.1, 1.0, 3)),
                                        metallic=float(rng.integers(0, 2)),
                                        roughness=float(rng.uniform(0.2, 0.8)))
        obj = cls(scale=float(rng.uniform(0.3, 0.7)), material=mat,
                  position=(*rng.uniform(-3, 3, 2), 0.7))
        scene += obj
        start = np.asarray(obj.position, float)
        vel = np.append(rng.uniform(-0.1, 0.1, 2), 0.0)
        spin = rng.uniform(-0.1, 0.1, 3)
        for f in scene.frames:
            obj.position = start + vel * (f - 1)
            obj.quaternion = kb.Quaternion.from_euler(spin * (f - 1))
            obj.keyframe_insert("position", f)
            obj.keyframe_insert("quaternion", f)
    return scene


def timed(fn):
    c0, w0 = cpu_seconds(), time.perf_counter()
    result = fn()
    return result, cpu_seconds() - c0, time.perf_counter() - w0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=smoke_mode.size(64, 1))
    parser.add_argument("--frames", type=int, default=smoke_mode.size(24, 2))
    parser.add_argument("--size", type=int, default=smoke_mode.size(256, 32))
    parser.add_argument("--denoise", action="store_true", help="OIDN on the RGB render")
    args = parser.parse_args(argv)

    _, setup_cpu, setup_wall = timed(lambda: __import__("bpy"))
    scene = movi_like_scene(np.random.default_rng(0), args.frames, args.size)
    renderer, build_cpu, _ = timed(lambda: kb.renderer.Blender(
        scene, samples_per_pixel=args.samples, use_denoising=args.denoise))
    n = args.frames
    rgb, rgb_cpu, rgb_wall = timed(lambda: renderer.render(return_layers=("rgba",)))
    ann, ann_cpu, ann_wall = timed(lambda: renderer.render(return_layers=ANNOTATION_LAYERS))
    renderer.samples_per_pixel = 1
    _, base_cpu, base_wall = timed(lambda: renderer.render(return_layers=("rgba",)))
    assert rgb["rgba"].shape == (n, args.size, args.size, 4)
    assert ann["segmentation"].max() >= 5

    print(f"scene: {n} frames {args.size}², 10 objects + floor, RGB at {args.samples} spp, "
          f"denoise={args.denoise}")
    print(f"import bpy: {setup_wall:.2f} s wall; build scene in Blender: {build_cpu:.2f} CPU-s")
    print(f"RGB         : {rgb_cpu / n:7.3f} CPU-s/frame ({rgb_wall / n:.3f} s wall/frame)")
    print(f"annotations : {ann_cpu / n:7.3f} CPU-s/frame ({ann_wall / n:.3f} s wall/frame)  "
          f"[depth, z, segmentation, flow ×2, normal, object_coordinates, uv; 1 spp exact]")
    print(f"baseline RGB at 1 spp: {base_cpu / n:7.3f} CPU-s/frame ({base_wall / n:.3f} s wall)")
    print(f"ratio annotations / RGB@{args.samples}: {ann_cpu / rgb_cpu:.3f}; "
          f"annotations / RGB@1 baseline: {ann_cpu / base_cpu:.2f}")
    print(f"total per frame: {(rgb_cpu + ann_cpu) / n:.3f} CPU-s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
