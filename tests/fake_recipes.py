"""A fast test-only recipe (no renderer): writes a tiny deterministic scene.

Options let tests make a scene slow (``sleep``), fail always (``fail``) or fail on its first
attempt only (``flaky``: counts attempts in a file next to the scene directories)."""

import json
import pathlib
import time

import numpy as np

from kubric import file_io
from kubric.pipeline import Option, Recipe, resolution


class Fake(Recipe, name="test_fake"):
    """Tiny random scene for pipeline tests."""

    resolution = Option((8, 6), "(width, height)", type=resolution, low=1)
    frames = Option(3, "number of frames", low=1, high=100)
    sleep = Option(0.0, "seconds to wait before writing", low=0.0)
    fail = Option(False, "always raise")
    flaky = Option(False, "raise on the first attempt of each seed")
    assets = Option(None, "an asset directory that must exist", type=pathlib.Path,
                    must_exist=True)

    def generate(self, seed, out_dir):
        if self.fail:
            raise RuntimeError(f"scene {seed} fails on purpose")
        if self.flaky:
            counter = out_dir.parent / f"attempts_{seed}"
            n = int(counter.read_text()) if counter.exists() else 0
            counter.write_text(str(n + 1))
            if n == 0:
                raise RuntimeError(f"scene {seed} fails on its first attempt")
        rng = np.random.RandomState(seed)
        w, h = self.resolution
        rgba = rng.randint(0, 255, size=(self.frames, h, w, 4)).astype(np.uint8)
        seg = rng.randint(0, 3, size=(self.frames, h, w, 1)).astype(np.uint32)
        if self.sleep:
            time.sleep(self.sleep)
        file_io.write_image_dict({"rgba": rgba, "segmentation": seg}, out_dir)
        meta = {"flags": self.flags(seed), "value": float(rng.rand())}
        (out_dir / "metadata.json").write_text(json.dumps(meta, sort_keys=True))
