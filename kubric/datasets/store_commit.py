"""A packed dataset written to object storage: ``kubric pack SCENES --out s3://bucket/ds``.

Object stores cannot rename a directory, so the local packer's "work directory renamed into
place" becomes a commit protocol whose last write is the dataset's marker
(``kubric_dataset.json``): a reader (:func:`kubric.datasets.load`, ``kubric datasets info``)
trusts a prefix only once that object exists and names every shard.

0. **Lease**: one pack of an output at a time (:mod:`kubric.datasets.store_lease`); a second
   pack of the same URL refuses at once and removes nothing.
1. **Probe** (before anything is planned): the output can be written — a probe object is
   written and deleted (:func:`kubric.io.storage.check_writable`); an unreachable store, a
   missing bucket or a read-only store is one line.
2. **Refuse** an output that holds a dataset (unless ``--overwrite``) or objects that are
   neither a dataset's nor this protocol's.
3. **Stage** under the work prefix ``OUT/.kubric-pack/``: ``plan.json`` (a hash of the whole
   plan), and for every chunk its ArrayRecord file (written in local scratch, uploaded) and then
   its record ``.FILE.json`` — the chunk's completion mark. A rerun of the same plan skips every
   recorded chunk, so a killed pack resumes; a different plan clears the prefix first. Chunk and
   re-cut tasks are those of :mod:`kubric.datasets.dask_pack`, run by local processes or on a
   Dask cluster whose workers share nothing but the store.
4. **Commit**: the client builds the metadata files exactly as the local packer does (from the
   chunk records alone), writes ``.kubric-pack/commit.json`` (the files it is about to
   publish), removes an overwritten dataset's marker and then its files, copies each staged
   shard to its final name (a server-side copy: no shard bytes pass through the client),
   uploads ``dataset_info.json``, ``features.json`` and the label files, **then
   ``kubric_dataset.json``**, and finally deletes the work prefix. A kill anywhere before the
   marker leaves no dataset (readers refuse the prefix); the rerun finishes the commit from the
   staged shards. A kill after it leaves a complete dataset and a stale work prefix, which the
   next pack of that output removes.

The published files are byte for byte those of the local ``kubric pack`` of the same scenes.
"""

from __future__ import annotations

import json
import pathlib
import re
import tempfile
import time

from kubric.datasets import dask_pack, layout, packer, tfds_io
from kubric.datasets.layout import METADATA_FILES, DatasetError, DatasetUsageError, dataset_files
from kubric.datasets.store_lease import LEASES, StoreLease
from kubric.io import storage
from kubric.io.json_io import write_json

#: the work prefix inside the output
WORK = ".kubric-pack"
COMMIT_FILE = "commit.json"
def _is_dataset_file(name: str) -> bool:
    return (name in METADATA_FILES or name == layout.INFO_FILE or name.endswith(".labels.txt")
            or re.search(rf"-[a-z0-9_]+\.{layout.FILE_FORMAT}-\d{{5}}-of-\d{{5}}$", name)
            is not None)


def _read_json(location: str) -> dict | None:
    try:
        value = json.loads(storage.read_bytes(location))
    except (FileNotFoundError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def check_output(out: str, overwrite: bool) -> None:
    """Raise DatasetError (one line) unless ``out`` may receive a dataset (step 2): empty,
    holding only this protocol's leftovers, or a dataset to be overwritten."""
    names = [n for n in storage.listdir(out) if n not in (WORK, LEASES)
             and not n.startswith(storage.WRITE_PROBE_PREFIX)]  # a concurrent run's probe
    if not names:
        return
    if layout.INFO_FILE in names:
        if not overwrite:
            raise DatasetUsageError(f"--out {out!r} is already a dataset; pass --overwrite "
                                    "to replace it")
        foreign = [n for n in names if not _is_dataset_file(n)]
    else:  # a commit cut short: its files, and those of the dataset it was replacing
        record = _read_json(storage.join(out, WORK, COMMIT_FILE))
        foreign = names if record is None else \
            [n for n in names if n not in record.get("files", []) and not _is_dataset_file(n)]
    if foreign:
        raise DatasetUsageError(f"--out {out!r} holds {foreign[0]!r}, which is not part of a "
                                "kubric dataset (refusing to write into it)")


def _open_work(out: str, plan_key: str) -> str:
    """The work prefix for ``plan_key`` (kept when it was made for the same plan)."""
    work = storage.join(out, WORK)
    state = _read_json(storage.join(work, dask_pack.PLAN_FILE))
    if state is not None and state.get("plan") == plan_key:
        return work
    commit = _read_json(storage.join(work, COMMIT_FILE))
    if commit is not None and not storage.isfile(storage.join(out, layout.INFO_FILE)):
        for name in commit.get("files", []):  # an older plan's half-made commit
            storage.remove(storage.join(out, name))
    storage.remove(work)
    storage.write_bytes(storage.join(work, dask_pack.PLAN_FILE),
                        json.dumps({"plan": plan_key}).encode())
    return work


def _metadata(plan, state: dict, scratch: pathlib.Path) -> tuple[dict, dict[str, str], list]:
    """(counts, {final shard name: staged file}, metadata files in ``scratch``) — the local
    packer's own finaliser run on empty stand-ins for the shards (it reads only the records)."""
    meta = scratch / "meta"
    meta.mkdir()
    renames: dict[str, str] = {}
    for split in plan.split_fractions:
        shards = [sh for sh in state["shards"].get(split, []) if sh["scenes"]]
        for i, shard in enumerate(shards):
            (meta / shard["file"]).write_bytes(b"")
            renames[layout.shard_name(plan.name, split, i, len(shards))] = shard["file"]
    write_json(state, meta / packer.PROGRESS_FILE)
    features = tfds_io.tfds_features(plan.schema, plan.dims)
    counts = packer.finalise(meta, state, plan.schema, plan.name, plan.dims,
                              plan.split_fractions, plan.incomplete, features, hash_files=False)
    files = sorted(p for p in meta.iterdir() if p.name not in renames)
    return counts, renames, files


def commit(out: str, work: str, renames: dict[str, str], files: list[pathlib.Path]) -> None:
    """Step 4 of the module doc: publish the staged shards and the metadata, marker last."""
    marker = next(f for f in files if f.name == layout.INFO_FILE)
    published = sorted([*renames, *(f.name for f in files)])
    storage.write_bytes(storage.join(work, COMMIT_FILE),
                        json.dumps({"files": published}).encode())
    # overwrite (or a cut commit of one): the old dataset disappears first, then its files
    storage.remove(storage.join(out, layout.INFO_FILE))
    for name in storage.listdir(out):
        if name != WORK and _is_dataset_file(name) and name not in published:
            storage.remove(storage.join(out, name))
    for final, staged in renames.items():
        storage.copy(storage.join(work, staged), storage.join(out, final))
    for f in files:
        if f is not marker:
            storage.upload_file(f, storage.join(out, f.name))
    storage.upload_file(marker, storage.join(out, marker.name))
    storage.remove(work)


def pack_to_store(scenes_dir, out, executor=None, name=None, splits=packer.DEFAULT_SPLITS,
                  workers: int = 1, schema=None, examples_per_shard: int = 256,
                  progress: bool = True, verify: bool = False, overwrite: bool = False,
                  class_names=None) -> packer.PackResult:
    """:func:`kubric.datasets.dask_pack.pack_sharded` into the URL ``out`` (module doc)."""
    start = time.perf_counter()
    split_fractions = layout.parse_splits(splits)
    if workers < 1:
        raise DatasetError(f"--workers must be ≥ 1, got {workers}")
    if examples_per_shard < 1:
        raise DatasetError(f"examples per shard must be ≥ 1, got {examples_per_shard}")
    if verify:
        raise DatasetError("--verify reads the dataset from a local directory; pack to one, or "
                           "load the URL and compare (kubric.datasets.load)")
    packer.check_pack_output(out, scenes_dir)
    try:
        out = storage.normalise(str(out))
        if out.startswith("memory://"):
            raise storage.StorageError(f"--out {out!r}: an in-memory filesystem is private to "
                                       "one process; use an object store URL")
        storage.check_writable(out)
    except storage.StorageError as err:  # a bad --out: a usage error, as for a local output
        raise DatasetUsageError(str(err)) from None
    plan = dask_pack.make_plan(scenes_dir, name, split_fractions, schema, examples_per_shard,
                               class_names, verify)
    try:
        with StoreLease(out):  # one pack of ``out`` at a time: nothing below touches another's
            check_output(out, overwrite)
            work = _open_work(out, plan.key)
            state, corrupt, resumed = dask_pack.run_plan(plan, work, executor, workers, progress)
            with tempfile.TemporaryDirectory(prefix="kubric-commit-") as scratch:
                counts, renames, files = _metadata(plan, state, pathlib.Path(scratch))
                commit(out, work, renames, files)
    except storage.backend_errors() as err:  # a store that failed or stalled past its deadline
        raise storage.StorageError(f"--out {out!r}: the object store failed during the pack "
                                   f"({storage.failure(err)}); nothing was published "
                                   "unless kubric_dataset.json exists: rerun the same command "
                                   "to resume") from None
    return packer.PackResult(out, counts, plan.incomplete, corrupt,
                             time.perf_counter() - start, resumed, plan.schema_origin)


__all__ = ["COMMIT_FILE", "WORK", "check_output", "commit", "dataset_files", "pack_into",
           "pack_to_store"]


def pack_into(scenes_dir, out, executor=None, **options) -> packer.PackResult:
    """The sharded pack into ``out``: :func:`pack_to_store` for a URL, else
    :func:`kubric.datasets.dask_pack.pack_sharded` (a directory)."""
    if storage.is_url(str(out)):
        return pack_to_store(scenes_dir, out, executor, **options)
    return dask_pack.pack_sharded(scenes_dir, out, executor, **options)
