"""Pack and read throughput of a MOVi-A dataset (128², 24 frames), each next to reading the same
scenes from their scene directories in the same run.

Scenes are generated once (4 spp, no denoising: the render settings do not change what is read)
into ``$KUBRIC_CACHE_DIR/bench_datasets/movi_a_128`` and reused. Measured:

* pack: scenes/s of ``kubric.datasets.pack`` (1 and 2 workers) vs the baseline, reading every
  scene's features from its directory (:class:`~kubric.io.scene_reader.SceneReader`, what
  the packer reads before encoding);
* read, random order: examples/s of ``load(...)[i]`` with every feature and with the ``video``
  task, vs reading the same scenes' layers + JSON (``file_io.read_image_dict``) and only their
  ``rgba`` PNGs from the directories.

Run: ``.venv/bin/python benchmarks/bench_datasets.py [--scenes N]``. The default is 20 scenes:
generating one 128², 24-frame scene takes about 31 s on the shared 2-core machine (20 scenes:
10.5 min with 2 workers), so the datasets issue's 100 (``--scenes 100``) would add 40 min to
``make bench``; the ratios do not depend on the count.
"""

from __future__ import annotations

import argparse
import atexit
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import smoke_mode  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
OPTIONS = smoke_mode.size(["resolution=128", "samples=4", "denoise=false"],
                          ["resolution=16", "frame_end=2", "samples=1", "denoise=false"])


def cache_dir() -> pathlib.Path:
    """Where the scenes are generated: kept in the asset cache for full runs; a fresh temporary
    folder in a smoke run (scenes cached by an older recipe would be refused: other options)."""
    if smoke_mode.SMOKE:
        folder = tempfile.mkdtemp(prefix="bench_datasets_scenes_")
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
        return pathlib.Path(folder) / "movi_a_smoke"
    base = os.environ.get("KUBRIC_CACHE_DIR") or pathlib.Path.home() / ".cache" / "kubric"
    return pathlib.Path(base) / "bench_datasets" / "movi_a_128"


def ensure_scenes(count: int) -> pathlib.Path:
    scenes = cache_dir()
    cmd = [sys.executable, "-m", "kubric", "generate", "movi_a", "--out", str(scenes),
           "--scenes", str(count), "--workers", "2"]
    for option in OPTIONS:
        cmd += ["--set", option]
    start = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT)
    print(f"scenes ready in {time.perf_counter() - start:.1f} s: {scenes}")
    return scenes


def timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", type=int, default=smoke_mode.size(20, 2))
    args = parser.parse_args(argv)
    from kubric import file_io
    from kubric.datasets import load, pack
    from kubric.datasets.packer import find_scenes
    from kubric.io.scene_reader import SceneReader
    from kubric.pipeline.recipe import schema_of as get_schema

    scene_root = ensure_scenes(args.scenes)
    scenes = find_scenes(scene_root)[0][:args.scenes]
    n = len(scenes)
    schema = get_schema("movi_a")
    with tempfile.TemporaryDirectory(prefix="bench_datasets_") as tmp:
        subset = pathlib.Path(tmp) / "scenes"
        subset.mkdir()
        for scene in scenes:
            (subset / scene.name).symlink_to(scene)
        baseline = timed(lambda: [SceneReader(s, schema).example() for s in scenes])
        print(f"baseline: read {n} scene directories (every feature): {baseline:.2f} s, "
              f"{n / baseline:.2f} scenes/s")
        for workers in (1, 2):
            out = pathlib.Path(tmp) / f"ds{workers}"
            seconds = timed(lambda out=out, workers=workers: pack(
                subset, out, splits="train=1", workers=workers, progress=False))
            print(f"pack, {workers} worker(s): {seconds:.2f} s, {n / seconds:.2f} scenes/s; "
                  f"pack / read-directories time ratio {seconds / baseline:.2f}")
        size = sum(p.stat().st_size for p in out.iterdir())
        src_size = sum(p.stat().st_size for s in scenes for p in s.iterdir())
        print(f"dataset {size / 2**20:.1f} MiB vs scene directories {src_size / 2**20:.1f} MiB")

        order = np.random.default_rng(0).permutation(n)
        full, video = load(out, "train"), load(out, "train", task="video")
        by_name = {s.name: s for s in scenes}
        dirs = [by_name[name] for name in full.scenes]
        full[0]  # open the readers once, outside the timing
        video[0]
        read_dirs = timed(lambda: [(file_io.read_image_dict(dirs[i]),
                                    file_io.read_json(dirs[i] / "metadata.json"),
                                    file_io.read_json(dirs[i] / "events.json")) for i in order])
        read_full = timed(lambda: [full[int(i)] for i in order])
        read_rgba = timed(lambda: [file_io.read_layer(dirs[i], "rgba") for i in order])
        read_video = timed(lambda: [video[int(i)] for i in order])
        print(f"read, random order, every feature: dataset {n / read_full:.2f} examples/s, "
              f"scene directories {n / read_dirs:.2f} scenes/s (dataset speed-up "
              f"{read_dirs / read_full:.2f}x)")
        print(f"read, random order, video only: dataset {n / read_video:.2f} examples/s, "
              f"rgba PNGs from the directories {n / read_rgba:.2f} scenes/s (dataset speed-up "
              f"{read_rgba / read_video:.2f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
