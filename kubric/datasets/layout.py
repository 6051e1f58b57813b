"""The on-disk layout of a packed dataset and its format marker.

A dataset directory is TFDS's layout (``dataset_info.json``, ``features.json``, label files and
``NAME-SPLIT.array_record-0000k-of-0000n`` shards) plus ``kubric_dataset.json``: the format
version, the recipe schema, the frame count / resolution, the split fractions, the scenes of
every split (in example order), the SHA-256 of every shard (``shard_sha256``) and its size in
bytes (``shard_bytes``; each absent in datasets packed before it existed). Readers refuse a
format version newer than :data:`FORMAT_VERSION`.
"""

from __future__ import annotations

import pathlib
import re

from kubric.errors import KubricError
from kubric.io.json_io import read_json

FORMAT = "kubric-dataset"
FORMAT_VERSION = 1
INFO_FILE = "kubric_dataset.json"
FILE_FORMAT = "array_record"
NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]*$")
#: ArrayRecord writer options of every shard: one record per chunk (random access), chunks stored
#: uncompressed. The payload is PNG / zlib bytes already; a zstd chunk's decoder pool schedules
#: riegeli's background cleaner thread, which a forked child (a DataLoader worker) does not have:
#: reading zstd shards there after the parent read hangs or segfaults. Recorded in the marker.
SHARD_WRITER_OPTIONS = "group_size:1,uncompressed"


class DatasetError(KubricError, ValueError):
    """Bad input to packing / loading (one-line message)."""


class DatasetUsageError(DatasetError):
    """A bad option or output of ``kubric pack`` (exit status 2; bad input data is 1)."""

    exit_code = 2


def file_sha256(path) -> str:
    """The hex SHA-256 of a file's bytes (read in 1 MiB blocks): a shard's checksum in the
    marker (``shard_sha256``), checked by the cache of a dataset URL."""
    import hashlib

    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def shard_name(name: str, split: str, index: int, count: int) -> str:
    """TFDS's shard file name ``NAME-SPLIT.array_record-0000k-of-0000n``."""
    return f"{name}-{split}.{FILE_FORMAT}-{index:05d}-of-{count:05d}"


#: TFDS metadata files a dataset holds besides its shards and marker (and ``*.labels.txt``)
METADATA_FILES = ("dataset_info.json", "features.json")


def dataset_files(info: dict) -> list[str]:
    """The shard names a dataset's marker (``kubric_dataset.json``) promises, in split order."""
    return [shard_name(info["name"], split, i, len(lengths))
            for split, lengths in info["shard_lengths"].items() for i in range(len(lengths))]


def is_dataset(path: pathlib.Path) -> bool:
    return (pathlib.Path(path) / INFO_FILE).is_file()


def read_info(dataset_dir) -> dict:
    """``kubric_dataset.json`` of ``dataset_dir``, checked (format and version)."""
    path = pathlib.Path(dataset_dir)
    if not path.is_dir():
        raise DatasetError(f"{str(path)!r} is not a directory")
    if not is_dataset(path):
        raise DatasetError(f"{str(path)!r} is not a kubric dataset (no {INFO_FILE}; make one with "
                           "`kubric pack`)")
    info = read_json(path / INFO_FILE)
    if not isinstance(info, dict) or info.get("format") != FORMAT:
        raise DatasetError(f"{str(path / INFO_FILE)!r} is not a {FORMAT} marker")
    version = info.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise DatasetError(f"{str(path)!r} has dataset format version {version!r}; this kubric "
                           f"reads versions ≤ {FORMAT_VERSION} (upgrade kubric)")
    for key, kind in REQUIRED_INFO.items():
        if not isinstance(info.get(key), kind):
            raise DatasetError(f"{str(path / INFO_FILE)!r} lacks {key!r} (or it is not "
                               f"{'an object' if kind is dict else 'text'}): not a complete "
                               f"marker; pack the dataset again")
    for split, count in info["counts"].items():
        lengths = info["shard_lengths"].get(split)
        if not isinstance(lengths, list) or sum(lengths) != count:
            raise DatasetError(f"{str(path / INFO_FILE)!r}: split {split!r} has {count!r} "
                               f"examples but shard lengths {lengths!r}")
    return info


#: the marker's keys every reader relies on, with their JSON types
REQUIRED_INFO = {"name": str, "dims": dict, "splits": dict, "counts": dict,
                 "shard_lengths": dict, "scenes": dict, "schema_json": dict}


def parse_splits(spec) -> dict[str, float]:
    """``"train=0.9,validation=0.1"`` (or a dict) → ``{"train": 0.9, "validation": 0.1}``;
    names are lower-case identifiers, fractions positive and summing to 1."""
    if isinstance(spec, str):
        pairs = {}
        for part in (p.strip() for p in spec.split(",") if p.strip()):
            name, sep, value = part.partition("=")
            try:
                fraction = float(value)
            except ValueError:
                fraction = None
            if not sep or fraction is None:
                raise DatasetError(f"--splits: {part!r} is not NAME=FRACTION "
                                   "(e.g. train=0.9,validation=0.1)")
            if name.strip() in pairs:
                raise DatasetError(f"--splits: split {name.strip()!r} given twice")
            pairs[name.strip()] = fraction
    else:
        pairs = {str(k): float(v) for k, v in dict(spec).items()}
    if not pairs:
        raise DatasetError("--splits: no split given (e.g. train=0.9,validation=0.1)")
    for name, fraction in pairs.items():
        if not NAME_PATTERN.match(name):
            raise DatasetError(f"--splits: split name {name!r} must be a lower-case identifier")
        if not fraction > 0:
            raise DatasetError(f"--splits: fraction of {name!r} must be > 0, got {fraction}")
    total = sum(pairs.values())
    if abs(total - 1.0) > 1e-6:
        raise DatasetError(f"--splits: fractions must sum to 1, got {total:g} "
                           f"({', '.join(f'{k}={v:g}' for k, v in pairs.items())})")
    return pairs


def _mix64(x: int) -> int:
    """SplitMix64's finaliser: a fixed, well-mixed 64-bit hash of ``x``."""
    mask = (1 << 64) - 1
    x = (x + 0x9E3779B97F4A7C15) & mask
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & mask
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & mask
    return x ^ (x >> 31)


def split_of(seed: int, splits: dict[str, float]) -> str:
    """The split of the scene with ``seed``: a fixed hash of the seed mapped to [0, 1) and cut
    at the cumulative fractions (in the order given). Independent of the other scenes, so adding
    scenes never moves one."""
    u = _mix64(int(seed)) / 2.0 ** 64
    edge = 0.0
    names = list(splits)
    for name in names:
        edge += splits[name]
        if u < edge:
            return name
    return names[-1]
