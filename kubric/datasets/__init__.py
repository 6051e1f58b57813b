"""Packed datasets: scene directories → TFDS-layout ArrayRecord shards, read without TensorFlow.

* :func:`pack` (``kubric pack``) writes a dataset directory from scene directories;
* :func:`load` gives a map-style source of numpy dicts (``len``, ``[i]``, ``__getitems__``);
* :mod:`kubric.datasets.tasks` — what a loader decodes and returns (``video``, ``frames``,
  ``nerf_rays``, ``point_tracks``, the multi-view ``multiview`` and ``svr``
  (:mod:`kubric.datasets.multiview_tasks`), your own with :func:`register_task`);
* :mod:`kubric.datasets.adapters` — ``torch.utils.data.Dataset``, Grain, ``tf.data`` (only
  when TensorFlow is installed);
* the output contract: :mod:`kubric.io.schema` (one schema per recipe).

TFDS, array_record, torch and Grain are imported only when used.
"""

from kubric.datasets.adapters import to_grain, to_tf, to_torch, torch_collate
from kubric.datasets.info import dataset_info
from kubric.datasets.layout import DatasetError
from kubric.datasets.packer import pack
from kubric.datasets.source import DataSource, load
from kubric.datasets.tasks import TASKS, register_task
from kubric.datasets.verify import verify_dataset

__all__ = ["DataSource", "DatasetError", "TASKS", "dataset_info", "load", "pack",
           "register_task", "to_grain", "to_tf", "to_torch", "torch_collate", "verify_dataset"]
