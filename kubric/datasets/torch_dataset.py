"""The PyTorch adapter (imports torch; use :func:`kubric.datasets.adapters.to_torch`)."""

from __future__ import annotations

import torch.utils.data


class TorchDataset(torch.utils.data.Dataset):
    """A map-style ``torch.utils.data.Dataset`` over a :class:`DataSource` (numpy items)."""

    def __init__(self, source):
        self.source = source

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index):
        return self.source[index]

    def __getitems__(self, indices):
        return self.source.__getitems__(list(indices))
