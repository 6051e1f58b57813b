"""``kubric datasets info DATASET_DIR``: splits, counts, shards, features with shapes, size
(DATASET_DIR may be a URL: its marker is read and its objects listed, no shard is fetched)."""

from __future__ import annotations

import json
import pathlib

from kubric.datasets.layout import (
    METADATA_FILES,
    DatasetError,
    dataset_files,
    read_info,
    shard_name,
)
from kubric.datasets.tasks import servable_tasks
from kubric.io import storage
from kubric.io.schema import Schema, shape_text


def _size(num_bytes: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if num_bytes < 1024 or unit == "GiB":
            return f"{num_bytes:.1f} {unit}" if unit != "B" else f"{num_bytes} B"
        num_bytes /= 1024
    return ""


def dataset_info(dataset_dir) -> str:
    """The text ``kubric datasets info`` prints."""
    if storage.is_url(str(dataset_dir)):  # the marker and one listing; no shard is fetched
        from kubric.datasets.dataset_cache import remote_info
        path = storage.normalise(str(dataset_dir))
        info = remote_info(path)
        listed = storage.sizes(path)
        size = sum(listed.values())
        problems = remote_shard_problems(path, info, listed)
    else:
        path = pathlib.Path(dataset_dir)
        info = read_info(path)
        size = sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        problems = check_shards(path, info)  # a URL's shards are checked when a split is loaded
    problems = check_metadata(path) + problems
    schema = Schema.from_json(info["schema_json"])
    dims = dict(info["dims"])
    lines = [f"dataset {info['name']} at {path}",
             f"  schema {schema.name} (version {schema.version}), format version "
             f"{info['format_version']}, kubric {info.get('kubric_version')}",
             f"  {'views' if 'metadata/num_views' in schema else 'frames'} T={dims['T']}, "
             f"resolution H×W={dims['H']}×{dims['W']}, size on disk "
             f"{_size(size)}",
             "  splits:"]
    for split, count in info["counts"].items():
        shards = info["shard_lengths"].get(split, [])
        lines.append(f"    {split:<12} {count:>7} examples in {len(shards)} shards "
                     f"(fraction {info['splits'].get(split, 0):g})"
                     + ("; no scene fell into it: it loads as an empty split" if not count
                        else ""))
    if info.get("incomplete_skipped"):
        lines.append(f"  incomplete scenes skipped when packing: {info['incomplete_skipped']}")
    lines.append(f"  loader tasks: {', '.join(servable_tasks(schema))}")
    lines.append(f"  features ({len(schema.features)}):")
    width = max(len(f.name) for f in schema.features)
    for f in schema.features:
        shape = shape_text(f, dims)
        dtype = f"class label[{len(f.names)}]" if f.names else f.dtype
        lines.append(f"    {f.name:<{width}}  {dtype:<15} {shape:<20} {f.encoding:<11} "
                     f"{f.unit}")
    if problems:
        raise DatasetError(f"{problems[0]}" + (f" (and {len(problems) - 1} more shard problems)"
                                               if len(problems) > 1 else ""))
    return "\n".join(lines)


def remote_shard_problems(url: str, info: dict, listed: dict[str, int]) -> list[str]:
    """One line per shard of the dataset at ``url`` that is missing from its listing
    (``{name: bytes}``) or whose size differs from the marker's ``shard_bytes`` (truncated,
    grown or replaced). Same-size damage shows when a split is loaded: the cache checks every
    shard's SHA-256 before it reads it."""
    recorded = info.get("shard_bytes") if isinstance(info.get("shard_bytes"), dict) else {}
    problems = []
    for name in dataset_files(info):
        where = storage.join(url, name)
        if name not in listed:
            problems.append(f"{where!r}: shard missing")
        elif name in recorded and listed[name] != recorded[name]:
            problems.append(f"{where!r}: {listed[name]} bytes, the marker says "
                            f"{recorded[name]} (truncated or replaced)")
    return problems


def check_metadata(path) -> list[str]:
    """One line per TFDS metadata file (``features.json``, ``dataset_info.json``) of the dataset
    at ``path`` (a folder or URL) that is missing or not a JSON object."""
    problems = []
    for name in METADATA_FILES:
        location = storage.join(str(path), name)
        try:
            value = json.loads(storage.read_bytes(location))
        except FileNotFoundError:
            problems.append(f"{location!r}: missing")
            continue
        except (ValueError, UnicodeDecodeError) as err:
            problems.append(f"{location!r}: not valid JSON ({' '.join(str(err).split())[:120]})")
            continue
        if not isinstance(value, dict):
            problems.append(f"{location!r}: not a JSON object")
    return problems


def check_shards(path: pathlib.Path, info: dict) -> list[str]:
    """One line per shard that is missing, unreadable or holds another number of records than
    the marker says (a truncated file loses its footer: ArrayRecord cannot open it)."""
    from array_record.python import array_record_module
    problems = []
    for split, lengths in info["shard_lengths"].items():
        for i, expected in enumerate(lengths):
            shard = path / shard_name(info["name"], split, i, len(lengths))
            if not shard.is_file():
                problems.append(f"{str(shard)!r}: shard missing")
                continue
            try:
                reader = array_record_module.ArrayRecordReader(str(shard),
                                                               "readahead_buffer_size:0")
                got = reader.num_records()
                reader.close()
            except (RuntimeError, ValueError, OSError) as err:
                problems.append(f"{str(shard)!r}: unreadable (truncated or corrupt): "
                                f"{' '.join(str(err).split())[:200]}")
                continue
            if got != expected:
                problems.append(f"{str(shard)!r}: {got} records, the marker says {expected}")
    return problems
