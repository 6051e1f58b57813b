"""Time ``write_image_dict`` for one 256×256, 24-frame scene with every layer.

The scene is synthetic but image-like: a textured floor and moving shaded spheres give piecewise
smooth depth / normals / coordinates, per-object flow and a little render noise in RGBA.
Baseline in the same run: the hand-written codecs the package had before ``bench_codecs.py``
(``handwritten_codecs.py``); times are the best of 12 (wall, and CPU seconds of all threads), the
two codec sets alternating in 4 rounds of 3.
Run: ``.venv/bin/python benchmarks/bench_file_io.py [--sweep]``; ``--sweep`` also compares PNG
filters and zlib levels (sizes and times), the basis of the defaults in ``kubric/io/png_io.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import pathlib
import tempfile
import time

import numpy as np
import smoke_mode

from kubric.io import layers, png_io, tiff_io


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


def time_write(scene, repeats: int = 3, threads: int = 16) -> tuple[float, int, float]:
    """Best wall seconds, bytes written, best CPU seconds (all threads; what a shared, noisy
    machine does not inflate) of ``write_image_dict`` over ``repeats``."""
    best, cpu, size = float("inf"), float("inf"), 0
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            start, start_cpu = time.perf_counter(), time.process_time()
            layers.write_image_dict(scene, tmp, max_write_threads=threads)
            best = min(best, time.perf_counter() - start)
            cpu = min(cpu, time.process_time() - start_cpu)
            size = sum(p.stat().st_size for p in pathlib.Path(tmp).iterdir())
    return best, size, cpu


@contextlib.contextmanager
def handwritten_codecs():
    """Swap in the codecs ``kubric/io`` had before ``bench_codecs.py`` (the baseline)."""
    import handwritten_codecs as hw

    saved = (png_io.decode_png, tiff_io.decode_tiff, png_io.encode_png.__kwdefaults__.copy())
    png_io.decode_png, tiff_io.decode_tiff = hw.decode_png, hw.decode_tiff
    png_io.encode_png.__kwdefaults__["strategy"] = "default"
    try:
        yield
    finally:
        png_io.decode_png, tiff_io.decode_tiff = saved[:2]
        png_io.encode_png.__kwdefaults__.update(saved[2])


def time_read(directory, repeats: int = 3) -> tuple[float, float]:
    """Best wall and best CPU seconds of ``read_image_dict`` over ``repeats``."""
    best, cpu = float("inf"), float("inf")
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        layers.read_image_dict(directory)
        best = min(best, time.perf_counter() - start)
        cpu = min(cpu, time.process_time() - start_cpu)
    return best, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sweep", action="store_true", help="compare PNG filters / zlib levels")
    args = parser.parse_args()
    scene = synthetic_scene(np.random.default_rng(0), frames=smoke_mode.size(24, 2),
                            size=smoke_mode.size(256, 96))
    files = sum(v.shape[0] for v in scene.values())
    results: dict[str, dict[str, float]] = {}
    # alternate the two codec sets: slow drifts of a shared machine hit both
    for _ in range(smoke_mode.size(4, 1)):
        for name in ("handwritten", "kubric"):
            with handwritten_codecs() if name == "handwritten" else contextlib.nullcontext():
                write, size, _ = time_write(scene)
                _, _, write_cpu = time_write(scene, threads=1)  # CPU-s without thread contention
                with tempfile.TemporaryDirectory() as tmp:
                    layers.write_image_dict(scene, tmp)
                    read, read_cpu = time_read(tmp)
            new = {"write": write, "write_cpu": write_cpu, "read": read, "read_cpu": read_cpu}
            old = results.get(name, {})
            results[name] = {k: min(v, old.get(k, v)) for k, v in new.items()} | {"size": size}
    base = results["handwritten"]
    for name, r in results.items():
        ratio = {k: r[k] / base[k] for k in r}
        print(f"{name:12s}: {files} files, {r['size'] / 1e6:.2f} MB ({ratio['size']:.2f}×); "
              f"write_image_dict {r['write']:.3f} s wall ({ratio['write']:.2f}×), single thread "
              f"{r['write_cpu']:.3f} CPU-s ({ratio['write_cpu']:.2f}×); read_image_dict "
              f"{r['read']:.3f} s wall ({ratio['read']:.2f}×), {r['read_cpu']:.3f} CPU-s "
              f"({ratio['read_cpu']:.2f}×)")
    if not args.sweep:
        return
    defaults = png_io.encode_png.__kwdefaults__.copy()
    for level in (1, 2, 3, 6):
        for method in png_io.FILTERS:
            png_io.encode_png.__kwdefaults__.update(compress_level=level, filter_method=method)
            elapsed, size, _ = time_write(scene, repeats=2)
            print(f"level={level} filter={method:5s}: {elapsed:.3f} s, {size / 1e6:.2f} MB")
    png_io.encode_png.__kwdefaults__.update(defaults)


if __name__ == "__main__":
    main()
