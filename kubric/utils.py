"""Helpers for upstream-style worker scripts (``kb.ArgumentParser``, ``kb.setup``, ``kb.done``)
and re-exports of the metadata functions (``kb.get_scene_metadata``, ``kb.get_camera_info``,
``kb.get_instance_info``, ``kb.process_collisions``).

Fix over upstream: ``--seed 0`` means seed 0. Without ``--seed`` a fresh seed is drawn from the OS
entropy pool by :func:`setup`, stored back into the flags and into ``scene.metadata["seed"]``, so
every run records the seed that reproduces it.
"""

from __future__ import annotations

import argparse
import logging
import pathlib
import tempfile

import numpy as np

from kubric import randomness
from kubric.annotations.metadata import (
    get_camera_info,
    get_instance_info,
    get_scene_metadata,
    process_collisions,
)
from kubric.core.resolution import parse_resolution
from kubric.core.scene import Scene
from kubric.io.scene_dir import write_success

logger = logging.getLogger("kubric")

class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` with upstream Kubric's common worker flags:
    ``--frame_rate`` (24), ``--step_rate`` (240), ``--frame_start`` (1), ``--frame_end`` (24),
    ``--logging_level`` (INFO), ``--seed`` (None = draw one), ``--resolution`` (N, WxH or W,H; 512),
    ``--scratch_dir`` (None = a fresh temporary directory), ``--job-dir`` (output)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.add_argument("--frame_rate", type=int, default=24)
        self.add_argument("--step_rate", type=int, default=240)
        self.add_argument("--frame_start", type=int, default=1)
        self.add_argument("--frame_end", type=int, default=24)
        self.add_argument("--logging_level", type=str, default="INFO")
        self.add_argument("--seed", type=int, default=None)
        self.add_argument("--resolution", type=str, default="512x512")
        self.add_argument("--scratch_dir", type=str, default=None)
        self.add_argument("--job-dir", type=str, default="output")

    def parse_args(self, args=None, namespace=None):
        flags = super().parse_args(args, namespace)
        try:
            flags.resolution = parse_resolution(flags.resolution)
        except ValueError as err:
            self.error(str(err))
        return flags


def setup_logging(logging_level: str | int = "INFO") -> None:
    """Log to stderr at ``logging_level`` (a name such as "INFO" or a number)."""
    level = logging_level.upper() if isinstance(logging_level, str) else logging_level
    if isinstance(level, str) and level not in logging.getLevelNamesMapping():
        raise ValueError(f"unknown logging level {logging_level!r}; allowed: "
                         f"{sorted(logging.getLevelNamesMapping())}")
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    logger.setLevel(level)


def log_my_flags(flags) -> None:
    """Log every flag (name = value), one per line."""
    for name, value in sorted(vars(flags).items()):
        logger.info("flag %s = %r", name, value)


def setup_directories(flags) -> tuple[pathlib.Path, pathlib.Path]:
    """Create and return ``(scratch_dir, output_dir)`` from ``flags.scratch_dir`` (None = a new
    temporary directory) and ``flags.job_dir``."""
    scratch = getattr(flags, "scratch_dir", None)
    scratch_dir = pathlib.Path(scratch) if scratch else pathlib.Path(tempfile.mkdtemp())
    scratch_dir.mkdir(parents=True, exist_ok=True)
    output_dir = pathlib.Path(getattr(flags, "job_dir", "output"))
    output_dir.mkdir(parents=True, exist_ok=True)
    return scratch_dir, output_dir


def draw_seed() -> int:
    """A fresh seed in [0, 2³¹ − 1) from the OS entropy pool (used only when none was given)."""
    return int(np.random.SeedSequence().entropy % (2**31 - 1))


def setup(flags):
    """Upstream's worker preamble: logging, flags, seed, scene and directories.

    Returns ``(scene, rng, output_dir, scratch_dir)``: ``rng`` is a
    :class:`kubric.randomness.WorkerRandomState` (a ``numpy.random.RandomState(seed)``), also
    used by sampling functions called without ``rng`` and by :func:`done` for as long as the
    caller keeps it; ``scene`` has the flags' frame range, rates and resolution, and
    ``scene.metadata["seed"]``.
    """
    setup_logging(getattr(flags, "logging_level", "INFO"))
    if getattr(flags, "seed", None) is None:
        flags.seed = draw_seed()
    log_my_flags(flags)
    rng = randomness.WorkerRandomState(seed=flags.seed)
    scene = Scene.from_flags(flags)
    scene.metadata["seed"] = int(flags.seed)
    scratch_dir, output_dir = setup_directories(flags)
    rng.output_dir = output_dir
    randomness.bind_worker_rng(rng)  # upstream calls that omit rng= use this seeded one
    return scene, rng, output_dir, scratch_dir


def done(output_dir=None) -> pathlib.Path | None:
    """Mark the run complete: write ``_SUCCESS`` into ``output_dir`` (default: the one of the
    :func:`setup` whose rng is still held) with the same writer as the scene worker. Returns the
    marker's path (None when there is no output directory)."""
    worker = randomness.worker_rng()
    target = output_dir if output_dir is not None else getattr(worker, "output_dir", None)
    logger.info("done")
    if target is None:
        return None
    marker = write_success(pathlib.Path(target))
    if worker is not None and output_dir is None:
        worker.output_dir = None
    return marker


__all__ = [
    "ArgumentParser", "done", "draw_seed", "get_camera_info", "get_instance_info",
    "get_scene_metadata", "log_my_flags", "parse_resolution", "process_collisions", "setup",
    "setup_directories", "setup_logging",
]
