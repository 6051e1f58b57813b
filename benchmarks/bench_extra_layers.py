"""Cost of each opt-in scene-model layer (``extra_layers``) relative to a default MOVi-A raycast
scene, and the bytes of the amodal masks of 20 objects × 24 frames in several storages.

Part 1 (cost): a simulated MOVi scene (``--recipe``, default movi_a; ``--set KEY=VALUE`` adds
recipe options); the baseline is what a default ``renderer=raycast`` scene renders (every layer,
rgba included); then each extra layer alone (CPU-s of computing it, its annotations included)
and all of them together, as a ratio to the baseline, measured in the same run.

Part 2 (storage): 20 objects (10 cubes, 10 spheres, 0.3–0.6 m) moving over a floor for 24
frames, their amodal masks (``kubric.renderer.scene_model_layers.amodal_masks``) stored as
(a) our bit-plane PNGs (one 16-bit RGBA PNG per frame), (b) one 1-bit-per-pixel-as-8-bit grey
PNG per object and frame (what re-rendering per object gives), (c) COCO compressed RLE strings
(``kubric.datasets.exports.rle``, as COCO / KINS JSON hold them), (d) ``np.packbits`` in a
compressed npz. Bytes per scene.

Run: ``python benchmarks/bench_extra_layers.py [--recipe movi_a] [--size 64] [--frames 4]
[--set KEY=VALUE ...] [--baseline raycast|blender]`` (cost; ``--baseline blender`` divides by
the recipe's default Blender render of the same simulated scene, in the same process) and
``[--storage-size 256]`` (storage; 0 skips it).
"""

from __future__ import annotations

import argparse
import io
import json
import resource
import tempfile
import time

import numpy as np
import smoke_mode
from bench_raycast import simulated_scene

import kubric as kb
from kubric.datasets.exports import rle
from kubric.io import png_io
from kubric.io.bitmask import pack_masks
from kubric.io.encodings import layer_kind
from kubric.pipeline import get_recipe
from kubric.recipes import extra_layers as extra
from kubric.renderer import create
from kubric.renderer.base import ALL_LAYERS
from kubric.renderer.scene_model_layers import amodal_masks


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(fn):
    c = cpu_seconds()
    value = fn()
    return value, cpu_seconds() - c


def cost(recipe: str, size: int, frames: int, seed: int, options=(), baseline="raycast") -> None:
    options = [f"renderer={baseline}", *options]
    scene = simulated_scene(recipe, size, frames, seed, *options)
    if baseline == "raycast":
        layers, base = timed(lambda: create("raycast", scene).render(return_layers=ALL_LAYERS))
    else:  # the recipe's default quality setting, as its worker renders
        settings = get_recipe(recipe).from_assignments(options).renderer_settings()
        with tempfile.TemporaryDirectory() as scratch:
            layers, base = timed(lambda: create(baseline, scene, scratch, **settings).render())
    instances = [a for a in scene.foreground_assets if isinstance(a, kb.PhysicalObject)]
    print(f"{recipe} seed {seed}, {size}², {frames} frames, {len(instances)} objects: default "
          f"{baseline} scene (every layer it writes) {base:.2f} CPU-s")
    print("| extra_layers | CPU-s | × default scene |")
    print("|---|---|---|")
    for names in [(n,) for n in extra.EXTRA_LAYERS] + [extra.EXTRA_LAYERS]:
        work = dict(layers)

        def run(names=names, work=work):
            extra.add_before_relabel(scene, work, names)
            extra.add_after_relabel(scene, work, names, instances)
        _, spent = timed(run)
        print(f"| {','.join(names)} | {spent:.2f} | {spent / base:.2f} |")


def storage_scene(size: int, frames: int = 24, count: int = 20) -> tuple:
    rng = np.random.RandomState(0)
    scene = kb.Scene(resolution=(size, size), frame_start=0, frame_end=frames - 1)
    scene += kb.Cube(name="floor", scale=(8, 8, 0.1), position=(0, 0, -0.1), static=True)
    scene.camera = kb.PerspectiveCamera(position=(0, -9, 5), look_at=(0, 0, 0.3))
    objects = []
    for k in range(count):
        cls = kb.Cube if k % 2 else kb.Sphere
        obj = cls(name=f"o{k}", scale=rng.uniform(0.3, 0.6))
        start, velocity = rng.uniform(-3, 3, 2), rng.uniform(-0.1, 0.1, 2)
        for f in scene.frames:
            obj.position = (*(start + velocity * f), 0.5)
            obj.keyframe_insert("position", f)
        scene += obj
        objects.append(obj)
    return scene, objects


def storage(size: int) -> None:
    scene, objects = storage_scene(size)
    masks, spent = timed(lambda: amodal_masks(scene, objects))    # (T, N, H, W)
    t, n = masks.shape[:2]
    planes = pack_masks(masks)
    encode, _ = layer_kind("bitmask").encoder(planes, "amodal")
    ours = sum(len(encode(planes[i])) for i in range(t))
    per_object = sum(len(png_io.encode_png(masks[i, k, ..., None].astype(np.uint8)))
                     for i in range(t) for k in range(n))
    coco = sum(len(json.dumps(rle.encode(masks[i, k]))) for i in range(t) for k in range(n))
    buf = io.BytesIO()
    np.savez_compressed(buf, bits=np.packbits(masks, axis=-1))
    print(f"\n{n} objects × {t} frames at {size}², amodal masks in {spent:.2f} CPU-s "
          f"(mean amodal area {masks.sum(axis=(2, 3)).mean():.0f} px)")
    print("| storage | bytes per scene | files |")
    print("|---|---|---|")
    print(f"| bit-plane PNGs (ours: 16-bit RGBA, bit k = instance k + 1) | {ours} | {t} |")
    print(f"| one 8-bit PNG per object and frame | {per_object} | {t * n} |")
    print(f"| COCO compressed RLE strings (JSON) | {coco} | — |")
    print(f"| np.packbits in a compressed npz | {len(buf.getvalue())} | 1 |")
    print(f"| raw bits (T·N·H·W / 8) | {masks.size // 8} | — |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="movi_a")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--size", type=int, default=smoke_mode.size(64, 16))
    ap.add_argument("--frames", type=int, default=smoke_mode.size(4, 2))
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--storage-size", type=int, default=smoke_mode.size(256, 16))
    ap.add_argument("--baseline", choices=("raycast", "blender"), default="raycast",
                    help="the default scene the layers' cost is divided by: raycast (all "
                    "layers) or blender (the recipe's default quality, rendered in this process)")
    args = ap.parse_args()
    start = time.perf_counter()
    cost(args.recipe, args.size, args.frames, args.seed, args.set, args.baseline)
    if args.storage_size:
        storage(args.storage_size)
    print(f"\n({time.perf_counter() - start:.1f} s wall)")


if __name__ == "__main__":
    main()
