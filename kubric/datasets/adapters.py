"""Adapters from a :class:`~kubric.datasets.source.DataSource` to training frameworks.

* :func:`to_torch` — a ``torch.utils.data.Dataset`` (works in ``DataLoader(num_workers=...)``);
  :func:`torch_collate` batches items whose arrays agree in shape and keeps the rest as lists;
* :func:`to_grain` — a Grain ``MapDataset`` (random access, shuffling, batching for JAX);
* :func:`to_tf` — a ``tf.data.Dataset`` through TFDS, only when TensorFlow is installed.

Each imports its framework only when called.
"""

from __future__ import annotations

import importlib.util

import numpy as np

from kubric.datasets.layout import DatasetError


def to_torch(source):
    """``source`` as a ``torch.utils.data.Dataset`` (items stay numpy dicts; collate them with
    :func:`torch_collate` or torch's default collate).

    Known issue: once a process with torch imported has read from any dataset, DataLoader
    workers *forked* from it crash when they open a shard (a segfault in array_record's reader).
    Either read only inside the workers, or pass ``multiprocessing_context="spawn"`` (or
    ``"forkserver"``) to the DataLoader; the source pickles for that."""
    from kubric.datasets.torch_dataset import TorchDataset
    return TorchDataset(source)


def torch_collate(items: list):
    """Batch a list of items: arrays of equal shape and dtype → one stacked tensor; anything else
    (text, ragged per-instance lists, arrays of differing shapes) → a list."""
    import torch
    first = items[0]
    if isinstance(first, dict):
        return {k: torch_collate([it[k] for it in items]) for k in first}
    arrays = [np.asarray(it) if isinstance(it, np.ndarray | np.generic) else None for it in items]
    if all(a is not None and a.dtype.kind in "biuf" for a in arrays) and \
            len({(a.shape, a.dtype) for a in arrays}) == 1:
        stacked = np.stack(arrays)
        if stacked.dtype == np.uint16:  # torch has no general uint16: widen losslessly
            stacked = stacked.astype(np.int32)
        return torch.from_numpy(stacked)
    return list(items)


def to_grain(source, shuffle_seed: int | None = None, batch_size: int | None = None):
    """``source`` as a ``grain.MapDataset``: optionally shuffled with ``shuffle_seed`` and
    batched (numpy arrays stacked along a new first axis)."""
    import grain
    dataset = grain.MapDataset.source(source)
    if shuffle_seed is not None:
        dataset = dataset.shuffle(seed=int(shuffle_seed))
    if batch_size is not None:
        dataset = dataset.batch(int(batch_size))
    return dataset


def to_tf(dataset_dir, split: str):
    """``split`` as a ``tf.data.Dataset`` (TFDS's reader). Needs TensorFlow, which kubric does
    not depend on: without it, a one-line :class:`DatasetError`."""
    if importlib.util.find_spec("tensorflow") is None:
        raise DatasetError("tf.data needs TensorFlow, which is not installed (pip install "
                           "tensorflow); kubric.datasets.load, to_torch and to_grain need none")
    import tensorflow_datasets as tfds
    return tfds.builder_from_directory(str(dataset_dir)).as_dataset(split=split)
