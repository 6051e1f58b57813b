"""Packing sharded over workers: ``kubric pack SCENES --out DIR --cluster local|tcp://…|slurm``, and
``kubric pack URL --out DIR`` (scenes on object storage, any fsspec URL).

The output is that of :func:`kubric.datasets.packer.pack` for the same scenes — **bit-identical
files** (shards, ``dataset_info.json``, ``features.json``, ``kubric_dataset.json``): the same
split of every scene (a function of its seed), the same example order, the same serialisation.

* The client lists the complete scenes (``_SUCCESS``; an URL's through
  :func:`kubric.io.storage.complete_scenes`), reads every ``metadata.json`` (seed → split, the
  schema, the frame count and resolution) and cuts each split, in scene-name order, into chunks of
  ``examples_per_shard`` scenes.
* One task per chunk (a Dask task asking for the resource ``scene=1``, or a local process): it
  reads its scenes (downloading a URL's scene into local scratch first), encodes them and writes
  one ArrayRecord file into the work directory ``.DIR.incomplete`` next to ``DIR``, then a small
  ``.json`` record of it (scenes, corrupt scenes, bytes) — the chunk's completion mark. A rerun of
  the same plan skips chunks that have their record, so an interrupted pack resumes.
* A corrupt scene is skipped and reported as locally. Since the local packer fills every shard
  with ``examples_per_shard`` *good* examples, a split with a corrupt scene is re-cut: one more
  task per final shard copies its records out of the chunk files. Without corrupt scenes the
  chunks are the shards.
* The client writes the final metadata and renames the work directory to ``DIR``.

``DIR`` must be on a filesystem that every worker can write (a shared filesystem for a real
cluster; each task checks and fails in one line otherwise). Scenes may be local (shared) paths or
URLs.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import hashlib
import json
import multiprocessing
import os
import pathlib
import shutil
import socket
import tempfile
import time
from collections.abc import Mapping, Sequence

from kubric.datasets import layout, packer, tfds_io
from kubric.datasets.layout import DatasetError, DatasetUsageError
from kubric.datasets.pack_schema import schema_origin_and_dims
from kubric.io import scene_dir, storage
from kubric.io.json_io import read_json, write_json
from kubric.pipeline.dask_slots import RESOURCE, uses_resource

PLAN_FILE = "plan.json"


# ------------------------------------------------------------------------ on a worker
def _require_work(work: str) -> None:
    """Fail in one line unless this worker sees the work area (a shared directory or a URL)."""
    if storage.is_url(work):
        if not storage.isfile(storage.join(work, PLAN_FILE)):
            raise DatasetError(f"the pack worker on {socket.gethostname()} cannot read "
                               f"{storage.join(work, PLAN_FILE)!r} (check its storage settings)")
        return
    if not (pathlib.Path(work) / PLAN_FILE).is_file():
        raise DatasetError(f"the pack worker on {socket.gethostname()} cannot see {work!r}: "
                           "--out must be on a filesystem shared with the workers")


@contextlib.contextmanager
def _staged(work: str, file: str):
    """A local path to write ``file`` to, published as ``work/file`` when the block ends without
    an error: renamed within a shared work directory, uploaded to a URL."""
    if storage.is_url(work):
        with tempfile.TemporaryDirectory(prefix="kubric-pack-") as scratch:
            tmp = pathlib.Path(scratch) / file
            yield tmp
            storage.upload_file(tmp, storage.join(work, file))
        return
    tmp = pathlib.Path(work) / f".{file}.tmp-{os.getpid()}"
    try:
        yield tmp
        os.replace(tmp, pathlib.Path(work) / file)
    finally:
        tmp.unlink(missing_ok=True)


def _encode_location(location: str) -> tuple[str, bytes | None, str | None]:
    """:func:`packer.encode_scene` for a path or URL (a URL's scene is downloaded first)."""
    if not storage.is_url(location):
        return packer.encode_scene(location)
    name = location.rstrip("/").rsplit("/", 1)[-1]
    with tempfile.TemporaryDirectory(prefix="kubric-pack-") as tmp:
        local = pathlib.Path(tmp) / name
        try:
            storage.download_dir(location, local)
        except Exception as err:  # each backend raises its own types
            return name, None, f"cannot read {location}: {' '.join(str(err).split())[:300]}"
        got = packer.encode_scene(str(local))
    error = got[2].replace(str(local), location) if got[2] else None
    return got[0], got[1], error


def encode_chunk(work: str, file: str, scenes: list[str], schema, dims: dict) -> dict:
    """Encode ``scenes`` (paths or URLs) into the ArrayRecord file ``work/file``; then write its
    record ``work/.file.json`` (the completion mark) and return it. ``work`` is a shared
    directory or a URL (the file is written in local scratch and uploaded)."""
    from array_record.python import array_record_module
    _require_work(work)
    packer.init_worker(schema, dims)
    record = {"file": file, "scenes": [], "corrupt": [], "num_bytes": 0}
    with _staged(work, file) as tmp:
        writer = array_record_module.ArrayRecordWriter(str(tmp), layout.SHARD_WRITER_OPTIONS)
        for location in scenes:
            name, data, error = _encode_location(location)
            if error is not None:
                record["corrupt"].append((location, error))
                continue
            writer.write(data)
            record["scenes"].append(name)
            record["num_bytes"] += len(data)
        writer.close()
        record["sha256"], record["file_bytes"] = layout.file_sha256(tmp), tmp.stat().st_size
    storage.write_bytes(storage.join(work, f".{file}.json"),
                        json.dumps(record, indent=2).encode())
    return record


def recut_shard(work: str, file: str, pieces: list[tuple[str, list[int]]]) -> dict:
    """Write ``work/file`` from records of chunk files: ``pieces`` = [(chunk file, [record
    indices])] in order; returns ``{"file", "num_bytes", "sha256", "file_bytes"}``."""
    from array_record.python import array_record_module
    _require_work(work)
    num_bytes = 0
    with tempfile.TemporaryDirectory(prefix="kubric-recut-") as scratch, \
            _staged(work, file) as tmp:
        writer = array_record_module.ArrayRecordWriter(str(tmp), layout.SHARD_WRITER_OPTIONS)
        for chunk, indices in pieces:
            path = storage.join(work, chunk)
            if storage.is_url(work):  # chunks are read whole: fetch them once
                path = str(storage.download_file(path, pathlib.Path(scratch) / chunk))
            reader = array_record_module.ArrayRecordReader(path)
            try:
                for data in reader.read(indices):
                    writer.write(data)
                    num_bytes += len(data)
            finally:
                reader.close()
        writer.close()
        digest, file_bytes = layout.file_sha256(tmp), tmp.stat().st_size
    return {"file": file, "num_bytes": num_bytes, "sha256": digest, "file_bytes": file_bytes}


# ------------------------------------------------------------------------ executors
class _LocalExecutor:
    """Tasks in this process (``workers == 1``) or a pool of spawned processes."""

    def __init__(self, workers: int):
        self.pool = concurrent.futures.ThreadPoolExecutor(1) if workers == 1 else \
            concurrent.futures.ProcessPoolExecutor(workers,
                                                   mp_context=multiprocessing.get_context("spawn"))

    def submit(self, fn, *args):
        return self.pool.submit(fn, *args)

    def as_completed(self, futures):
        return concurrent.futures.as_completed(futures)

    def close(self):
        self.pool.shutdown(cancel_futures=True)


class DaskExecutor:
    """Tasks on a Dask client; each asks for one ``scene`` slot (as a scene render does) where
    workers offer that resource, else takes one worker thread (a cluster of plain workers)."""

    def __init__(self, client):
        self.client = client
        self.resources = {RESOURCE: 1} if uses_resource(client) else None

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, resources=self.resources, pure=False)

    def as_completed(self, futures):
        from distributed import as_completed
        return as_completed(futures)

    def close(self):
        pass


def _run(executor, calls: list[tuple], on_done) -> None:
    """Submit ``calls`` (fn, *args); ``on_done(call index, result)`` as each finishes. The
    first failure cancels the rest and is raised."""
    futures = {executor.submit(*call): k for k, call in enumerate(calls)}
    try:
        for future in executor.as_completed(list(futures)):
            on_done(futures[future], future.result())
    except BaseException:
        for future in futures:
            future.cancel()
        raise


# ------------------------------------------------------------------------ on the client
def _list_scenes(scenes_dir: str, mirror: pathlib.Path) -> tuple[list[str], list[pathlib.Path],
                                                                  int]:
    """(complete scene locations, their local metadata folders, incomplete count) in name order.
    A URL's scenes get a local mirror holding only ``metadata.json``."""
    if not storage.is_url(scenes_dir):
        complete, incomplete = packer.find_scenes(pathlib.Path(scenes_dir))
        return [str(p) for p in complete], complete, incomplete
    names = storage.listdir(scenes_dir)
    complete = scene_dir.complete_scenes(scenes_dir)
    incomplete = sum(1 for n in names if scene_dir.is_scene_name(n) and n not in complete)
    locations, folders = [], []
    for name in sorted(complete):
        location = storage.join(scenes_dir, name)
        folder = mirror / name
        folder.mkdir(parents=True)
        try:
            (folder / scene_dir.METADATA_FILE).write_bytes(
                storage.read_bytes(storage.join(location, scene_dir.METADATA_FILE)))
        except FileNotFoundError:
            pass  # no seed / schema from it: reported as the local packer does
        locations.append(location)
        folders.append(folder)
    return locations, folders, incomplete


def _chunks(scenes: list, size: int) -> list[list]:
    return [scenes[i:i + size] for i in range(0, len(scenes), size)]


@dataclasses.dataclass
class PackPlan:
    """What a sharded pack writes: the scenes of every split (locations, in example order), the
    resolved schema, the dataset's name and dims, and the plan's key (a hash of all of it: a
    work area made for another plan is never resumed)."""

    scenes_dir: str
    name: str
    schema: object
    dims: dict
    split_fractions: dict
    examples_per_shard: int
    assignment: dict
    corrupt: list
    incomplete: int
    key: str = ""
    schema_origin: str = ""  # where the schema came from (the pack's summary says it)

    def chunk_files(self) -> dict:
        """``{(split, k): chunk file name}`` with the scenes of each chunk."""
        return {(split, k): (f"{self.name}-{split}.chunk-{k:05d}", chunk)
                for split, scenes in self.assignment.items()
                for k, chunk in enumerate(_chunks(scenes, self.examples_per_shard))}


def make_plan(scenes_dir, name, split_fractions: dict, schema, examples_per_shard: int,
              class_names, verify: bool) -> PackPlan:
    """List and read the scenes (module doc) into a :class:`PackPlan`; raises DatasetError (one
    line) on bad input before anything is written."""
    scenes_dir = storage.normalise(str(scenes_dir)) if storage.is_url(str(scenes_dir)) \
        else str(pathlib.Path(scenes_dir))
    if storage.is_url(scenes_dir):
        try:
            if not storage.exists(scenes_dir):
                raise DatasetError(f"SCENES_DIR {scenes_dir!r} does not exist")
        except storage.StorageError as err:
            raise DatasetError(str(err)) from None
        if verify:
            raise DatasetError("--verify compares with local scene directories; pack the URL "
                               "without it and verify a local copy")
    elif not pathlib.Path(scenes_dir).is_dir():
        raise DatasetError(f"SCENES_DIR {scenes_dir!r} is not a directory")
    with tempfile.TemporaryDirectory(prefix="kubric-pack-meta-") as mirror:
        locations, folders, incomplete = _list_scenes(scenes_dir, pathlib.Path(mirror))
        if not locations:
            raise DatasetError(f"{scenes_dir!r} holds no complete scene directory (with "
                               f"_SUCCESS); {incomplete} incomplete")
        schema, dims, origin = schema_origin_and_dims(folders, schema)
        schema = packer.resolve_names(schema, folders, class_names)
        name = name or schema.name
        if not layout.NAME_PATTERN.match(name):
            raise DatasetError(f"--name {name!r} must be a lower-case identifier (letters, "
                               "digits, _)")
        assignment: dict[str, list[str]] = {s: [] for s in split_fractions}
        corrupt: list[tuple[str, str]] = []
        seeds = []
        for location, folder in zip(locations, folders, strict=True):
            try:
                seeds.append((packer.scene_seed(folder), location))
                assignment[layout.split_of(seeds[-1][0], split_fractions)].append(location)
            except (packer.SceneError, ValueError) as err:
                corrupt.append((location, str(err).replace(str(folder), location)))
        scene_dir.check_unique_seeds(seeds)
    plan = PackPlan(scenes_dir, name, schema, dims, split_fractions, examples_per_shard,
                    assignment, corrupt, incomplete, schema_origin=origin)
    described = {"engine": "sharded", "schema": schema.name, "name": name,
                 "splits": split_fractions, "dims": dims,
                 "examples_per_shard": examples_per_shard,
                 "format_version": layout.FORMAT_VERSION, "scenes": assignment,
                 "shard_writer_options": layout.SHARD_WRITER_OPTIONS,
                 "class_names": {f.name: f.names for f in schema.features if f.names}}
    plan.key = hashlib.sha256(json.dumps(described, sort_keys=True).encode()).hexdigest()
    return plan


def run_plan(plan: PackPlan, work: str, executor, workers: int, progress: bool) -> tuple:
    """Encode the chunks of ``plan`` not yet recorded in the work area ``work`` (a directory or
    a URL whose ``plan.json`` is this plan's) and re-cut a split with corrupt scenes; returns
    (the final shards as the local packer's state, corrupt scenes, resumed scene count)."""
    from tqdm import tqdm
    marks = {n for n in storage.listdir(work) if n.startswith(".") and n.endswith(".json")}
    files = set(storage.listdir(work))
    chunk_of, calls, todo_scenes, records = {}, [], 0, {}
    for key, (file, chunk) in plan.chunk_files().items():
        chunk_of[key] = file
        if f".{file}.json" in marks and file in files:
            records[key] = json.loads(storage.read_bytes(storage.join(work, f".{file}.json")))
            continue
        calls.append((encode_chunk, work, file, chunk, plan.schema, plan.dims))
        todo_scenes += len(chunk)
    resumed = sum(len(r["scenes"]) + len(r["corrupt"]) for r in records.values())
    keys = [key for key in chunk_of if key not in records]
    own = executor is None
    executor = executor or _LocalExecutor(workers)
    bar = tqdm(total=todo_scenes, unit="scene", desc=f"pack {plan.name}", disable=not progress)
    try:
        def done(k, record):
            records[keys[k]] = record
            bar.update(len(record["scenes"]) + len(record["corrupt"]))
        _run(executor, calls, done)
        bar.close()
        state = _recut(work, executor, plan.name, plan.assignment, chunk_of, records,
                       plan.examples_per_shard)
    finally:
        bar.close()
        if own:
            executor.close()
    corrupt = list(plan.corrupt) + [tuple(c) for key in chunk_of for c in records[key]["corrupt"]]
    if not any(sh["scenes"] for shards in state["shards"].values() for sh in shards):
        first = f"; first: {corrupt[0][0]}: {corrupt[0][1]}" if corrupt else ""
        storage.remove(work)
        total = sum(len(v) for v in plan.assignment.values()) + len(plan.corrupt)
        raise DatasetError(f"no scene could be packed: all {total} complete scenes are "
                           f"corrupt{first}")
    return state, corrupt, resumed


def pack_sharded(scenes_dir, out, executor=None, name: str | None = None,
                 splits=packer.DEFAULT_SPLITS, workers: int = 1, schema=None,
                 examples_per_shard: int = 256, progress: bool = True, verify: bool = False,
                 overwrite: bool = False,
                 class_names: Mapping[str, Sequence[str]] | None = None) -> packer.PackResult:
    """Pack like :func:`kubric.datasets.packer.pack`, one task per shard (module doc).
    ``executor``: a :class:`DaskExecutor`, or None for ``workers`` local processes;
    ``class_names`` as for :func:`~kubric.datasets.packer.pack`. ``out`` is a directory; a URL
    is packed by :func:`kubric.datasets.store_commit.pack_to_store` (:func:`pack_into`)."""
    packer.check_pack_output(out, scenes_dir)
    if storage.is_url(str(out)):
        raise DatasetUsageError(f"pack_sharded: --out {str(out)!r} is a URL; use "
                                "kubric.datasets.store_commit.pack_to_store (pack_into)")
    start = time.perf_counter()
    out = pathlib.Path(out).absolute()
    split_fractions = packer.check_options(splits, workers, examples_per_shard, out, overwrite)
    plan = make_plan(scenes_dir, name, split_fractions, schema, examples_per_shard,
                     class_names, verify)
    with packer.output_lock(out):  # one pack per output, as the local packer
        packer.check_out(out, overwrite)
        return _pack_planned(plan, out, executor, workers, progress, verify, split_fractions,
                             start)


def _pack_planned(plan, out, executor, workers, progress, verify, split_fractions,
                  start) -> packer.PackResult:
    work = packer.work_dir(out)
    _open_work(work, plan.key)
    state, corrupt, resumed = run_plan(plan, str(work), executor, workers, progress)
    features = tfds_io.tfds_features(plan.schema, plan.dims)
    write_json(state, work / packer.PROGRESS_FILE)  # finalise removes it
    counts = packer.finalise(work, state, plan.schema, plan.name, plan.dims, split_fractions,
                              plan.incomplete, features)
    if verify:  # in the work folder: a dataset that fails never takes the output's name
        from kubric.datasets.verify import verify_dataset
        try:
            verify_dataset(work, plan.scenes_dir, progress=progress)
        except DatasetError as err:
            shutil.rmtree(work, ignore_errors=True)
            raise DatasetError(f"{err}; nothing was written to {str(out)!r}") from None
    packer.swap_into_place(work, out)
    return packer.PackResult(out, counts, plan.incomplete, corrupt,
                             time.perf_counter() - start, resumed, plan.schema_origin)


def _open_work(work: pathlib.Path, plan_key: str) -> None:
    """The work directory of this plan (kept from an interrupted run of the same plan)."""
    if (work / PLAN_FILE).is_file():
        try:
            if read_json(work / PLAN_FILE).get("plan") == plan_key:
                return
        except ValueError:
            pass
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    write_json({"plan": plan_key}, work / PLAN_FILE)


def _recut(work: str, executor, name: str, assignment: dict, chunk_of: dict,
           records: dict, per_shard: int) -> dict:
    """The final shards as the local packer's progress state ``{"shards": {split: [...]}}``:
    the chunks themselves, or (a split with corrupt scenes) shards re-cut from them to hold
    ``per_shard`` good examples each. A local work directory is left holding only them."""
    state: dict = {"shards": {}}
    calls, targets = [], []
    for split in assignment:
        chunks = [records[key] for key in sorted(k for k in records if k[0] == split)]
        if not any(r["corrupt"] for r in chunks):
            state["shards"][split] = [{"file": r["file"], "scenes": r["scenes"],
                                       "num_bytes": r["num_bytes"], "sha256": r.get("sha256"),
                                       "file_bytes": r.get("file_bytes")}
                                      for r in chunks]
            continue
        good = [(r["file"], i, scene) for r in chunks for i, scene in enumerate(r["scenes"])]
        shards = []
        for j, part in enumerate(_chunks(good, per_shard)):
            pieces: list[tuple[str, list[int]]] = []
            for file, index, _ in part:
                if not pieces or pieces[-1][0] != file:
                    pieces.append((file, []))
                pieces[-1][1].append(index)
            shard = {"file": f"{name}-{split}.shard-{j:05d}", "scenes": [s for *_, s in part],
                     "num_bytes": 0}
            shards.append(shard)
            calls.append((recut_shard, work, shard["file"], pieces))
            targets.append(shard)
        state["shards"][split] = shards

    def done(k, result):
        for key in ("num_bytes", "sha256", "file_bytes"):
            targets[k][key] = result[key]
    _run(executor, calls, done)
    if not storage.is_url(work):  # a URL's work area goes as a whole after the commit
        keep = {sh["file"] for shards in state["shards"].values() for sh in shards}
        for entry in pathlib.Path(work).iterdir():
            if entry.name not in keep:
                entry.unlink()
    return state


__all__ = ["pack_sharded", "DaskExecutor", "PackPlan", "encode_chunk", "make_plan",
           "recut_shard", "run_plan"]
