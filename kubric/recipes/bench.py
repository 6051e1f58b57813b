"""``bench``: a complete scene directory without a renderer or a simulator, for scale measurements.

It writes what every recipe writes — ``rgba_{i:05d}.png`` and ``segmentation_{i:05d}.png`` per
frame, ``metadata.json`` (flags, resolution, frame count, seed, instances with their
positions), an empty ``events.json``, ``schema.json`` (no float layers, so no
``data_ranges.json``) — from the
seed alone (numpy's ``RandomState``), through the same writer
(:func:`kubric.io.scene_writer.write_scene`) and worker (atomic work directory, ``_SUCCESS``
last) as the rendering recipes, so it exercises runners, resume, object storage and packing at
sizes no rendering budget allows (``benchmarks/bench_scale.py``: 10⁴ scenes). The images are
random noise with random labels: packable (schema ``bench``), not a dataset to learn from. A
scene is 8 files, ~6 KB, at the defaults.
"""

from __future__ import annotations

import pathlib

import numpy as np

from kubric.io.scene_writer import write_scene
from kubric.io.schema import Feature, Schema, register_schema
from kubric.pipeline.options import Option, resolution
from kubric.pipeline.recipe import Recipe

BENCH = register_schema(Schema("bench", (
    Feature("metadata/video_name", "str", (), "scene_name", "text",
            doc="scene id (directory name)"),
    Feature("metadata/seed", "int64", (), "meta:seed", doc="the scene's seed"),
    Feature("metadata/num_frames", "int32", (), "meta:num_frames", doc="frames T"),
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png",
            doc="random RGB noise (alpha dropped)"),
    Feature("segmentations", "uint8", ("T", "H", "W", 1), "layer:segmentation", "png",
            doc="random instance labels 0..N"),
    Feature("instances/positions", "float32", ("T", 3), "instance:positions", unit="m",
            doc="random positions per frame"),
), description="bench: a no-render scene for scale measurements (random images and labels)."))


class Bench(Recipe, name="bench"):
    """No-render scene (random images, labels, positions) for scale measurements."""

    schema = BENCH
    internal = True  # listed last by `kubric recipes`
    resolution = Option((8, 8), "(width, height) of the random images", type=resolution, low=1)
    frames = Option(2, "number of frames written", low=1, high=1000)
    num_instances = Option(3, "instances (segmentation labels 1..N, one position track each)",
                           low=0, high=255)

    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        rng = np.random.RandomState(seed)
        (w, h), t, n = self.resolution, self.frames, self.num_instances
        rgba = rng.randint(0, 256, size=(t, h, w, 4)).astype(np.uint8)
        segmentation = rng.randint(0, n + 1, size=(t, h, w, 1)).astype(np.uint32)
        positions = rng.uniform(-1.0, 1.0, size=(n, t, 3)).astype(np.float32)
        metadata = {"flags": self.flags(seed),
                    "metadata": {"resolution": [w, h], "num_frames": t, "seed": int(seed),
                                 "num_instances": n},
                    "instances": [{"positions": p.tolist()} for p in positions]}
        write_scene(self.schema, out_dir, {"rgba": rgba, "segmentation": segmentation},
                    metadata)


__all__ = ["BENCH", "Bench"]
