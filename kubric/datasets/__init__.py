"""Packed datasets: scene directories → TFDS-layout ArrayRecord shards, read without TensorFlow.

* :func:`pack` (``kubric pack``) writes a dataset directory from scene directories;
* :func:`load` gives a map-style source of numpy dicts (``len``, ``[i]``, ``__getitems__``);
* :mod:`kubric.datasets.tasks` — what a loader decodes and returns (``video``, ``frames``,
  ``nerf_rays``, ``point_tracks``, the multi-view ``multiview`` and ``svr``
  (:mod:`kubric.datasets.multiview_tasks`), your own with :func:`register_task`);
* :mod:`kubric.datasets.adapters` — ``torch.utils.data.Dataset``, Grain, ``tf.data`` (only
  when TensorFlow is installed);
* the output contract: :mod:`kubric.io.schema` (one schema per recipe).

TFDS, array_record, torch and Grain are imported only when used, and the names below only on
first use, so :mod:`kubric.datasets.exports` (which recipes may import) stays below the packer
and the pipeline.
"""

import importlib

#: public name → the module that defines it (imported on first access)
_LAZY = {
    "to_grain": "adapters", "to_tf": "adapters", "to_torch": "adapters",
    "torch_collate": "adapters", "dataset_info": "info", "DatasetError": "layout",
    "pack": "packer", "DataSource": "source", "load": "source", "TASKS": "tasks",
    "register_task": "tasks", "verify_dataset": "verify",
}


def __getattr__(name):
    if name not in _LAZY:
        raise AttributeError(f"module 'kubric.datasets' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"kubric.datasets.{_LAZY[name]}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = sorted(_LAZY)
