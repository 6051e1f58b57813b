"""Adapters from a :class:`~kubric.datasets.source.DataSource` to training frameworks.

* :func:`to_torch` — a ``torch.utils.data.Dataset`` (works in ``DataLoader(num_workers=...)``);
  :func:`torch_collate` batches items whose arrays agree in shape and keeps the rest as lists;
* :func:`to_grain` — a Grain ``MapDataset`` (random access, shuffling, batching for JAX);
* :func:`to_tf` — a ``tf.data.Dataset`` decoded by TFDS's feature connectors in TensorFlow (needs
  TensorFlow: the ``tf`` extra).

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


def to_tf(dataset_dir, split: str = "train"):
    """``split`` as a ``tf.data.Dataset`` of examples decoded in TensorFlow by the dataset's own
    TFDS feature connectors (``FeaturesDict.deserialize_example``), as ``tfds.load`` gives them:
    nested dicts of tensors; text is ``tf.string``; the per-instance ragged features
    (``instances/bboxes``, ``instances/bbox_frames``) are ``tf.RaggedTensor`` (N, None, ...).
    The values are those of :func:`kubric.datasets.load` (tested example by example).

    TFDS 4.9.10's ``builder.as_dataset`` refuses ArrayRecord shards, so the serialised records
    are read with the loader's shard reader (a fresh one per pass over the data, in the thread
    tf.data asks from) and decoded in the graph. Needs TensorFlow, which kubric's core does not
    depend on (``pip install 'kubric[tf]'``): without it, a one-line :class:`DatasetError`."""
    if importlib.util.find_spec("tensorflow") is None:
        raise DatasetError("tf.data needs TensorFlow, which is not installed (pip install "
                           "'kubric[tf]' or tensorflow); kubric.datasets.load, to_torch and "
                           "to_grain need none")
    import tensorflow as tf

    from kubric.datasets.source import load
    source = load(dataset_dir, split)  # checks the directory and split now (one-line errors)
    source._open()
    features, count = source._features, len(source.scenes)

    def records():
        reader = load(source.dataset_dir, split)  # its own shard readers, opened in this thread
        for index in range(count):
            yield reader._records([index])[0]

    data = tf.data.Dataset.from_generator(records,
                                          output_signature=tf.TensorSpec((), tf.string))
    data = data.apply(tf.data.experimental.assert_cardinality(count))
    return data.map(features.deserialize_example, num_parallel_calls=tf.data.AUTOTUNE)
