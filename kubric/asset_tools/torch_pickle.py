"""Read tensors from a PyTorch checkpoint (``torch.save``'s zip format) **without torch**.

A ``.pth`` written by ``torch.save`` is a zip holding ``<prefix>/data.pkl`` (a pickle whose
tensors are persistent references), ``<prefix>/data/<key>`` (each storage's raw bytes) and
``<prefix>/byteorder``. Unpickling arbitrary globals runs arbitrary code, so this reader allows
exactly four globals — ``torch._utils._rebuild_tensor_v2``, ``collections.OrderedDict`` and the
typed storages ``torch.{Float,Double,Long,Int}Storage`` — each mapped to a small numpy
equivalent; anything else raises :class:`UnsafeCheckpointError` naming it. Tensors come back as
numpy arrays (copies, in native byte order).
"""

from __future__ import annotations

import collections
import io
import pickle
import zipfile
from pathlib import Path

import numpy as np

from kubric.errors import InputError

#: storage class name → numpy dtype (the storages this reader accepts)
STORAGE_DTYPES = {"FloatStorage": np.float32, "DoubleStorage": np.float64,
                  "LongStorage": np.int64, "IntStorage": np.int32,
                  "HalfStorage": np.float16, "BoolStorage": np.bool_}


class UnsafeCheckpointError(InputError):
    """A checkpoint whose pickle names a global this reader does not allow."""


class _StorageType:
    def __init__(self, name: str):
        self.name = name
        self.dtype = np.dtype(STORAGE_DTYPES[name])


def _rebuild_tensor_v2(storage, storage_offset, size, stride, requires_grad=False,
                       backward_hooks=None, metadata=None):
    """numpy version of torch's tensor rebuild: a strided view of the storage, copied."""
    flat, dtype = storage
    item = dtype.itemsize
    size = tuple(int(s) for s in size)
    if not size:
        return flat[int(storage_offset)].copy()
    view = np.lib.stride_tricks.as_strided(
        flat[int(storage_offset):], shape=size, strides=tuple(int(s) * item for s in stride))
    return np.array(view)


class _Unpickler(pickle.Unpickler):
    def __init__(self, fh, zf: zipfile.ZipFile, prefix: str, byteorder: str, where: str):
        super().__init__(fh)
        self.zf, self.prefix, self.byteorder, self.where = zf, prefix, byteorder, where

    def find_class(self, module, name):
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return _rebuild_tensor_v2
        if (module, name) == ("collections", "OrderedDict"):
            return collections.OrderedDict
        if module == "torch" and name in STORAGE_DTYPES:
            return _StorageType(name)
        raise UnsafeCheckpointError(f"{self.where}: the checkpoint's pickle names the global "
                                    f"{module}.{name}; only tensors, storages and OrderedDict "
                                    f"are read")

    def persistent_load(self, pid):
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"
                and isinstance(pid[1], _StorageType)):
            raise UnsafeCheckpointError(f"{self.where}: unexpected persistent id {pid!r}")
        storage_type, key = pid[1], str(pid[2])
        raw = self.zf.read(f"{self.prefix}/data/{key}")
        dtype = storage_type.dtype.newbyteorder("<" if self.byteorder == "little" else ">")
        return np.frombuffer(raw, dtype=dtype).astype(storage_type.dtype), storage_type.dtype


def load_checkpoint(source, where: str | None = None):
    """The object stored in a ``torch.save`` zip (path or bytes), tensors as numpy arrays."""
    where = where or (str(source) if isinstance(source, (str, Path)) else "checkpoint")
    data = source if isinstance(source, (bytes, bytearray)) else Path(source).read_bytes()
    try:
        zf = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise InputError(f"{where}: not a torch zip checkpoint (legacy torch.save format "
                         f"is not supported)") from None
    pkls = [n for n in zf.namelist() if n.endswith("/data.pkl")]
    if len(pkls) != 1:
        raise InputError(f"{where}: expected one <prefix>/data.pkl in the zip, found {pkls}")
    prefix = pkls[0][:-len("/data.pkl")]
    names = set(zf.namelist())
    byteorder = (zf.read(f"{prefix}/byteorder").decode().strip()
                 if f"{prefix}/byteorder" in names else "little")
    with zf.open(pkls[0]) as fh:
        return _Unpickler(io.BytesIO(fh.read()), zf, prefix, byteorder, where).load()
