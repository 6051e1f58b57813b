"""Time ``write_image_dict`` for one 256×256, 24-frame scene with every layer.

The scene is synthetic but image-like: a textured floor and moving shaded spheres give piecewise
smooth depth / normals / coordinates, per-object flow and a little render noise in RGBA.
Run: ``.venv/bin/python benchmarks/bench_file_io.py [--sweep]``; ``--sweep`` also compares PNG
filters and zlib levels (sizes and times), the basis of the defaults in ``kubric/io/png_io.py``.
"""

from __future__ import annotations

import argparse
import pathlib
import tempfile
import time

import numpy as np

from kubric.io import layers, png_io


def synthetic_scene(rng: np.random.Generator, frames: int = 24, size: int = 256,
                    num_objects: int = 8) -> dict[str, np.ndarray]:
    """A (T, H, W, C) layer dict with realistic structure (see module docstring)."""
    t, h, w = frames, size, size
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    depth = np.broadcast_to(5.0 + rows / h * 10.0, (t, h, w)).copy()
    seg = np.zeros((t, h, w), np.uint32)
    normal = np.zeros((t, h, w, 3), np.float32)
    normal[..., 2] = 1.0
    coords = np.stack([cols / w, rows / h, np.zeros_like(rows)], -1)[None].repeat(t, 0)
    flow = np.zeros((t, h, w, 2), np.float32)
    shade = np.broadcast_to(0.4 + 0.2 * ((rows // 16 + cols // 16) % 2), (t, h, w)).copy()
    centres = rng.uniform(40, size - 40, (num_objects, 2))
    velocity = rng.uniform(-3, 3, (num_objects, 2))
    radii = rng.uniform(12, 30, num_objects)
    for k in range(num_objects):
        for f in range(t):
            cy, cx = centres[k] + f * velocity[k]
            dy, dx = (rows - cy) / radii[k], (cols - cx) / radii[k]
            inside = dy * dy + dx * dx < 1
            nz = np.sqrt(np.clip(1 - dy * dy - dx * dx, 0, 1))
            d = 4.0 + k * 0.3 - nz * radii[k] / 50
            hit = inside & (d < depth[f])
            depth[f][hit] = d[hit]
            seg[f][hit] = k + 1
            normal[f][hit] = np.stack([dx, -dy, nz], -1)[hit]
            coords[f][hit] = np.stack([(dx + 1) / 2, (dy + 1) / 2, nz], -1)[hit]
            flow[f][hit] = velocity[k]
            shade[f][hit] = 0.2 + 0.7 * nz[hit]
    rgb = shade[..., None] * np.array([0.9, 0.7, 0.5]) + rng.normal(0, 0.02, (t, h, w, 3))
    rgba = np.concatenate([np.clip(rgb, 0, 1) * 255, np.full((t, h, w, 1), 255)], -1)
    uv = coords.copy()
    uv[..., 2] = 0
    return {
        "rgba": rgba.round().astype(np.uint8), "depth": depth[..., None].astype(np.float32),
        "z": (depth[..., None] * 0.95).astype(np.float32), "segmentation": seg[..., None],
        "forward_flow": flow, "backward_flow": -flow, "normal": normal,
        "object_coordinates": coords.astype(np.float32), "uv": uv.astype(np.float32),
    }


def time_write(scene, repeats: int = 3, threads: int = 16) -> tuple[float, int]:
    best, size = float("inf"), 0
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            layers.write_image_dict(scene, tmp, max_write_threads=threads)
            best = min(best, time.perf_counter() - start)
            size = sum(p.stat().st_size for p in pathlib.Path(tmp).iterdir())
    return best, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sweep", action="store_true", help="compare PNG filters / zlib levels")
    args = parser.parse_args()
    scene = synthetic_scene(np.random.default_rng(0))
    files = sum(v.shape[0] for v in scene.values())
    elapsed, size = time_write(scene)
    print(f"defaults (filter={png_io.DEFAULT_FILTER}, level={png_io.DEFAULT_COMPRESS_LEVEL}): "
          f"{files} files in {elapsed:.3f} s, {size / 1e6:.2f} MB")
    elapsed, _ = time_write(scene, threads=1)
    print(f"  single thread: {elapsed:.3f} s")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        layers.write_image_dict(scene, tmp)
        start = time.perf_counter()
        layers.read_image_dict(tmp)
        print(f"read_image_dict: {time.perf_counter() - start:.3f} s")
    if not args.sweep:
        return
    defaults = png_io.encode_png.__kwdefaults__.copy()
    for level in (1, 2, 3, 6):
        for method in png_io.FILTERS:
            png_io.encode_png.__kwdefaults__.update(compress_level=level, filter_method=method)
            elapsed, size = time_write(scene, repeats=2)
            print(f"level={level} filter={method:5s}: {elapsed:.3f} s, {size / 1e6:.2f} MB")
    png_io.encode_png.__kwdefaults__.update(defaults)


if __name__ == "__main__":
    main()
