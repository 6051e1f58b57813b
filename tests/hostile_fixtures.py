"""Tiny scenes of a toy schema (no rendering) for the round-two hostile tests and
benchmarks/bench_pack_signals.py, and ``kubric`` run in a subprocess that knows the toy recipe.

``python tests/hostile_fixtures.py pack ...`` is the ``kubric`` command with the toy recipe
registered (so ``kubric pack`` finds its schema in a fresh process)."""

import os
import pathlib
import subprocess
import sys

if __name__ == "__main__":  # the kubric command, with this module (and its recipe) imported
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import hostile_fixtures  # noqa: F401

    from kubric.cli import main
    sys.exit(main(sys.argv[1:]))

import numpy as np  # noqa: E402

from kubric.io.scene_writer import write_scene  # noqa: E402
from kubric.io.schema import Feature, Schema, register_schema  # noqa: E402
from kubric.pipeline import Recipe  # noqa: E402
from kubric.pipeline.worker import run_scene  # noqa: E402

T, H, W = 2, 4, 5
NAME = "test_hostile"
SCHEMA = register_schema(Schema(NAME, (
    Feature("metadata/video_name", "str", (), "scene_name", "text"),
    Feature("metadata/seed", "int64", (), "meta:seed"),
    Feature("video", "uint8", ("T", "H", "W", 3), "layer:rgba[:3]", "png"),
    Feature("target_points", "float32", ("P", "T", 2), "npz:toy_points.npz:target_points",
            doc="a per-scene .npz (as tracks.npz)"),
)))
HERE = pathlib.Path(__file__).resolve()
ROOT = HERE.parents[1]


class Tiny(Recipe, name=NAME):
    """Random RGB frames."""

    schema = SCHEMA

    def generate(self, seed, out_dir):
        rng = np.random.RandomState(seed)
        rgba = rng.randint(0, 256, size=(T, H, W, 4)).astype(np.uint8)
        points = {"target_points": rng.rand(3, T, 2).astype(np.float32)}
        metadata = {"flags": self.flags(seed),
                    "metadata": {"resolution": [W, H], "num_frames": T, "seed": seed}}
        write_scene(self.schema, out_dir, {"rgba": rgba}, metadata,
                    files={"toy_points.npz": points})


def make_scenes(root, count: int = 6) -> pathlib.Path:
    root = pathlib.Path(root)
    for seed in range(count):
        run_scene(Tiny(), seed, root)
    return root


def tree(folder) -> dict:
    folder = pathlib.Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def kubric(*args, env=None, timeout=120, **kwargs) -> subprocess.CompletedProcess:
    """``kubric ARGS`` in a fresh process that has the toy recipe registered."""
    full_env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])), **(env or {}))
    return subprocess.run([sys.executable, str(HERE), *map(str, args)], env=full_env,
                          capture_output=True, text=True, timeout=timeout, **kwargs)


def popen(*args, env=None, **kwargs) -> subprocess.Popen:
    full_env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])), **(env or {}))
    return subprocess.Popen([sys.executable, str(HERE), *map(str, args)], env=full_env,
                            **kwargs)
