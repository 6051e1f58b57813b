"""Datasets at a URL (``kubric.datasets.load("s3://bucket/ds")``): read through a local cache.

:func:`fetch` reads the dataset's marker ``kubric_dataset.json`` (absent: the URL is not a
dataset, or its pack has not committed — :mod:`kubric.datasets.store_commit` writes it last),
lists the prefix once, checks that every shard of the split the marker promises is there (a
missing one is a one-line :class:`DatasetError` naming it), and copies the metadata and that
split's shards into ``$KUBRIC_CACHE_DIR/datasets/<hash>/`` (default ``~/.cache/kubric``).
The hash covers the URL and the marker's bytes, so a dataset packed again under the same URL
gets a new cache folder. A cached shard is kept only with the listed size and the SHA-256 the
marker records (``shard_sha256``; checked once, then remembered by a stamp of its size and
mtime): a damaged or truncated cached file is fetched again, and a fetched file that does not
match is a one-line error naming its URL. Files
arrive under a temporary name and are renamed when complete (two processes fetching the same
file both end with the whole file). The reader then works on the local folder exactly as on a
local dataset: ArrayRecord's random access stays local-disk fast after the first open.
"""

from __future__ import annotations

import hashlib
import os
import pathlib

from kubric.datasets import layout
from kubric.datasets.layout import DatasetError
from kubric.io import storage


def cache_root() -> pathlib.Path:
    env = os.environ.get("KUBRIC_CACHE_DIR")
    base = pathlib.Path(env).expanduser() if env else pathlib.Path.home() / ".cache" / "kubric"
    return base / "datasets"


def _marker(url: str) -> bytes:
    try:
        return storage.read_bytes(storage.join(url, layout.INFO_FILE))
    except FileNotFoundError:
        raise DatasetError(f"{url!r} is not a kubric dataset (no {layout.INFO_FILE}: not packed, "
                           "or its pack has not finished)") from None
    except storage.StorageError as err:  # unknown protocol, missing package
        raise DatasetError(str(err)) from None
    except Exception as err:  # each backend raises its own types
        detail = " ".join(str(err).split())[:200] or type(err).__name__
        raise DatasetError(f"{url!r}: cannot read {layout.INFO_FILE} ({detail})") from None


def fetch(url: str, split: str | None = None) -> pathlib.Path:
    """A local folder holding the dataset at ``url``'s metadata and the shards of ``split``
    (all splits when None); see the module doc."""
    url = storage.normalise(url)
    marker = _marker(url)
    local = cache_root() / hashlib.sha256(url.encode() + b"\0" + marker).hexdigest()[:20]
    local.mkdir(parents=True, exist_ok=True)
    storage.write_bytes(str(local / layout.INFO_FILE), marker)
    info = layout.read_info(local)
    listed = storage.sizes(url)
    splits = [split] if split is not None else list(info["shard_lengths"])
    shards = []
    for name in splits:
        lengths = info["shard_lengths"].get(name, [])
        shards += [layout.shard_name(info["name"], name, i, len(lengths))
                   for i in range(len(lengths))]
    missing = [s for s in shards if s not in listed]
    if missing:
        raise DatasetError(f"{url!r} is damaged: shard {missing[0]!r} is missing ({len(missing)} "
                           f"of {len(shards)} shards{f' of split {split!r}' if split else ''}); "
                           "pack it again")
    metadata = [n for n in listed if n != layout.INFO_FILE and
                (n.endswith(".json") or n.endswith(".labels.txt")) and not n.startswith(".")]
    digests = info.get("shard_sha256") if isinstance(info.get("shard_sha256"), dict) else {}
    for name in (*metadata, *shards):
        target = local / name
        if _cached(target, listed[name], digests.get(name)):
            continue
        location = storage.join(url, name)
        storage.download_file(location, target)
        if target.stat().st_size != listed[name]:
            target.unlink()
            raise DatasetError(f"{location!r}: got {target.stat().st_size} bytes, the store "
                               f"lists {listed[name]}")
        if digests.get(name) and not _verified(target, digests[name]):
            target.unlink()
            raise DatasetError(f"{location!r} is damaged: its content does not match the "
                               f"SHA-256 its {layout.INFO_FILE} records; pack it again")
    return local


def _stamp(target: pathlib.Path) -> pathlib.Path:
    return target.with_name(f".{target.name}.sha256")


def _verified(target: pathlib.Path, digest: str) -> bool:
    """Whether ``target`` hashes to ``digest``; a match is stamped (size, mtime, digest) so the
    next fetch does not read the file again."""
    if layout.file_sha256(target) != digest:
        return False
    st = target.stat()
    _stamp(target).write_text(f"{st.st_size} {st.st_mtime_ns} {digest}\n")
    return True


def _cached(target: pathlib.Path, size: int, digest: str | None) -> bool:
    """A cached file to keep: the listed size and, when the marker records one, its checksum
    (a stamp of an earlier check when the file has not changed since)."""
    if not target.is_file() or target.stat().st_size != size:
        return False
    if not digest:
        return True
    st = target.stat()
    stamp = _stamp(target)
    expected = f"{st.st_size} {st.st_mtime_ns} {digest}\n".encode()
    if stamp.is_file() and stamp.read_bytes() == expected:
        return True
    return _verified(target, digest)


def remote_info(url: str) -> dict:
    """The checked marker (``kubric_dataset.json``) of the dataset at ``url``; nothing is
    cached."""
    import tempfile
    with tempfile.TemporaryDirectory(prefix="kubric-marker-") as tmp:
        (pathlib.Path(tmp) / layout.INFO_FILE).write_bytes(_marker(storage.normalise(url)))
        return layout.read_info(tmp)


__all__ = ["cache_root", "fetch", "remote_info"]
