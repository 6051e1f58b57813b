"""Export throughput and peak memory of ``kubric export hf`` / ``webdataset`` at 10² and 10³
bench-recipe scenes (64², 8 frames: no rendering), issue 38's benchmark.

Each export runs in a fresh process that first imports everything and exports a 2-scene dataset
(so the libraries' first-use allocations are done), then exports the measured dataset; reported:
scenes/s, and the peak resident memory (``VmHWM``) that the measured export added over the
process before it. Streaming means the 10³-scene peak stays within 1.2× (plus 8 MB of
allocator noise) of the 10²-scene one; a dataset held in memory would grow by ~0.13 MB a scene.

Run: ``.venv/bin/python benchmarks/bench_hub.py [--small 100] [--large 1000]`` (the scenes
and their packs go to a temporary folder; 10³ scenes take a few minutes to make and export).
``tests/test_hub_exports.py`` runs :func:`measure_export` at 12 and 48 scenes.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import time

import smoke_mode  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
OPTIONS = smoke_mode.size({"resolution": (64, 64), "frames": 8}, {"resolution": (16, 16), "frames": 2})
FORMATS = ("hf", "webdataset")

CHILD = r"""
import json, pathlib, sys, time
spec = json.loads(sys.argv[1])
from kubric.datasets.exports import exporter
export = exporter(spec["format"])

def hwm_mb():
    status = pathlib.Path("/proc/self/status").read_text().splitlines()
    return next(int(l.split()[1]) for l in status if l.startswith("VmHWM:")) / 1024

export(spec["warmup"], spec["out"] + "-warmup", progress=False)
before = hwm_mb()
start = time.perf_counter()
export(spec["dataset"], spec["out"], progress=False)
wall = time.perf_counter() - start
print("RESULT " + json.dumps({"wall": wall, "before_mb": before, "peak_mb": hwm_mb()}))
"""


def make_dataset(root: pathlib.Path, n: int, options=None) -> pathlib.Path:
    """``n`` bench scenes (seeds 0..n-1, ``options``: the recipe's) packed into one split."""
    from kubric.datasets import pack
    from kubric.pipeline.worker import run_scene
    from kubric.recipes.bench import Bench
    recipe = Bench(**(OPTIONS if options is None else options))
    scenes = root / f"scenes-{n}"
    for seed in range(n):
        run_scene(recipe, seed, scenes)
    pack(scenes, root / f"ds-{n}", splits="train=1", progress=False)
    return root / f"ds-{n}"


def measure_export(fmt: str, dataset: pathlib.Path, warmup: pathlib.Path, out: pathlib.Path,
                   timeout: float = 3600) -> dict:
    """{"wall": s, "before_mb", "peak_mb", "added_mb"} of one export in a fresh process."""
    spec = {"format": fmt, "dataset": str(dataset), "warmup": str(warmup), "out": str(out)}
    proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(spec)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode or not lines:
        raise RuntimeError(f"export {fmt} failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}")
    result = json.loads(lines[-1][7:])
    result["added_mb"] = result["peak_mb"] - result["before_mb"]
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--small", type=int, default=smoke_mode.size(100, 3))
    parser.add_argument("--large", type=int, default=smoke_mode.size(1000, 4))
    args = parser.parse_args(argv)
    failed = False
    with tempfile.TemporaryDirectory(prefix="bench_hub_") as tmp:
        root = pathlib.Path(tmp)
        start = time.perf_counter()
        warmup = make_dataset(root, 2)
        sets = {n: make_dataset(root, n) for n in (args.small, args.large)}
        print(f"datasets made in {time.perf_counter() - start:.1f} s")
        print(f"{'format':<11}{'scenes':>8}{'scenes/s':>10}{'peak MB':>9}{'added MB':>10}")
        for fmt in FORMATS:
            added = {}
            for n, dataset in sets.items():
                r = measure_export(fmt, dataset, warmup, root / f"{fmt}-{n}")
                added[n] = r["added_mb"]
                print(f"{fmt:<11}{n:>8}{n / r['wall']:>10.1f}{r['peak_mb']:>9.0f}"
                      f"{r['added_mb']:>10.1f}")
            ok = added[args.large] <= 1.2 * added[args.small] + 8
            failed |= not ok
            print(f"{fmt}: added peak {added[args.large]:.1f} MB at {args.large} scenes vs "
                  f"{added[args.small]:.1f} MB at {args.small}: "
                  f"{'within' if ok else 'NOT within'} 1.2x + 8 MB")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
