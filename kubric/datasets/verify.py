"""``kubric pack --verify``: re-read every packed example and compare it with its scene directory.

Each example is decoded by the loader (:func:`kubric.datasets.load`) and compared with what the
packer reads from the scene (:class:`~kubric.io.scene_reader.SceneReader`): every feature
must be equal, bit for bit (integers, the stored uint16 samples, float32 metadata, text).
"""

from __future__ import annotations

import pathlib

import numpy as np

from kubric.datasets.layout import DatasetError, read_info
from kubric.datasets.source import load
from kubric.datasets.tfds_io import flatten
from kubric.io.scene_reader import SceneReader


def values_equal(a, b) -> bool:
    """Exact equality of two feature values (arrays incl. dtype, lists of them, scalars, str)."""
    if isinstance(a, list) or isinstance(b, list):
        return (isinstance(a, list) and isinstance(b, list) and len(a) == len(b)
                and all(values_equal(x, y) for x, y in zip(a, b, strict=True)))
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)


def verify_dataset(dataset_dir, scenes_dir, progress: bool = True) -> int:
    """Compare every example of every split with its scene; returns the number checked.
    Raises :class:`DatasetError` naming the first scene and feature that differ."""
    from tqdm import tqdm
    dataset_dir, scenes_dir = pathlib.Path(dataset_dir), pathlib.Path(scenes_dir)
    checked = 0
    counts = read_info(dataset_dir)["counts"]
    splits = [s for s, n in counts.items() if n]
    total = sum(counts.values())
    with tqdm(total=total, unit="example", desc="verify", disable=not progress) as bar:
        for split in splits:
            source = load(dataset_dir, split)
            for index, scene in enumerate(source.scenes):
                got = flatten(source[index])
                expected = SceneReader(scenes_dir / scene, source.schema).example()
                for name, value in expected.items():
                    if name not in got or not values_equal(got[name], value):
                        raise DatasetError(f"verify: {split}[{index}] ({scene}) feature {name!r} "
                                           "differs from the scene directory")
                checked += 1
                bar.update(1)
    return checked

