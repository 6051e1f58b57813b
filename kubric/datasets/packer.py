"""``kubric pack``: scene directories → a TFDS-layout ArrayRecord dataset, without TensorFlow.

* Scenes are the sub-directories of SCENES_DIR; one without ``_SUCCESS`` is incomplete: skipped
  and counted. A complete scene that cannot be read (unreadable PNG, missing layer, a field off
  the schema) is reported by path and skipped; the rest are packed.
* The schema is the one the scenes store (``schema.json``, written by ``write_scene``; no recipe
  is imported), unless given (``--schema``: a schema's or recipe's name, ``FILE.py:Class``;
  then each scene must be of that schema or name it among its variants). A scene written before
  scenes stored their schema falls back to the recipe its ``metadata.json`` names (the result
  says so). Every scene must have the same schema: a scene whose schema is neither stored nor
  known here, or two scenes that disagree, fail the pack in one line before anything is written
  (:mod:`kubric.datasets.pack_schema`).
* A class label whose names come from the scenes (:data:`~kubric.io.schema.NAMES_FROM_SCENES`,
  e.g. ``svr``'s ``instances/category``) gets the sorted distinct values of its source over all
  complete scenes, found before anything is written; the dataset stores them (``features.json``,
  ``kubric_dataset.json``), so a label's id is its index in that sorted list — unless the names
  are given (``--class-names FEATURE=FILE``, e.g. another dataset's labels file, so that two
  datasets share ids).
* Each scene's split is a fixed function of its seed (:func:`~kubric.datasets.layout.split_of`);
  within a split, examples are in scene-name order; serialisation is deterministic, so packing
  the same scenes again gives byte-identical shards.
* Work happens in ``.NAME.incomplete`` next to the output; finished shards are recorded in its
  ``progress.json``, so an interrupted pack resumes after the last finished shard. A record that
  names a file the folder lacks (a kill during the final renames) is not trusted: the pack starts
  afresh. The dataset is finished in the work folder (final shard names, metadata, marker) and,
  with ``verify``, checked there; only then is the work folder renamed to the output: a directory
  at the output's name is complete and (when asked) verified, or absent (the work folder and its
  shards: :mod:`kubric.datasets.pack_shards`).
* One pack per output: ``.NAME.lock`` beside it is held while packing (a second pack refuses).
* ``overwrite`` replaces a dataset only when the output holds nothing but what the packer wrote
  (:func:`packer_files`); any other file in it is refused by name, never deleted.
* Worker processes (``workers`` > 1) ignore SIGINT (the parent decides), die with the parent
  (Linux parent-death signal) and are terminated when the parent is interrupted.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import dataclasses
import hashlib
import multiprocessing
import os
import pathlib
import re
import shutil
import signal
import time
import zipfile
from collections.abc import Mapping, Sequence

from kubric import faults
from kubric.datasets import layout, tfds_io
from kubric.datasets.layout import DatasetError, DatasetUsageError
from kubric.datasets.pack_schema import check_scene_schema, schema_origin_and_dims
from kubric.datasets.pack_shards import (  # noqa: F401  (PROGRESS_FILE: read as packer.PROGRESS_FILE)
    PROGRESS_FILE,
    ShardWriter,
    done_names,
    finalise,
    finish_shard,
    open_work,
    swap_into_place,
    work_dir,
)
from kubric.io import scene_dir
from kubric.io.json_io import read_json
from kubric.io.output_check import check_output, scene_folders
from kubric.io.output_lock import OutputLock
from kubric.io.scene_reader import SceneError, SceneReader
from kubric.io.schema import Schema, SchemaError

DEFAULT_SPLITS = "train=0.9,validation=0.1"


@dataclasses.dataclass
class PackResult:
    out: pathlib.Path
    counts: dict[str, int]
    incomplete: int
    corrupt: list[tuple[str, str]]
    seconds: float
    resumed_scenes: int = 0
    schema_origin: str = ""

    def format(self) -> str:
        lines = [f"packed {sum(self.counts.values())} scenes into {self.out} "
                 f"({', '.join(f'{k}: {v}' for k, v in self.counts.items())}) in "
                 f"{self.seconds:.1f} s"]
        if self.schema_origin:
            lines.append(f"  schema: {self.schema_origin}")
        if self.resumed_scenes:
            lines.append(f"  resumed: {self.resumed_scenes} scenes were already packed")
        if self.incomplete:
            lines.append(f"  skipped {self.incomplete} incomplete scene directories (no _SUCCESS)")
        for path, reason in self.corrupt:
            lines.append(f"  skipped corrupt scene {path}: {reason}")
        for split in [s for s, n in self.counts.items() if not n]:
            lines.append(f"  split {split!r} got no scene (a scene's split is a fixed function of "
                         f"its seed; {sum(self.counts.values())} scenes are few for its fraction): "
                         f"it loads as an empty split; pack more scenes, or give --splits "
                         f"without it")
        return "\n".join(lines)


# ------------------------------------------------------------------------ per-scene encoding
_WORKER: dict = {}


def init_worker(schema: Schema, dims: dict, parent: int | None = None) -> None:
    if parent is not None:  # a pool process: the parent handles Ctrl-C; die with the parent
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _die_with(parent)
    _WORKER.update(schema=schema, dims=dims, features=tfds_io.tfds_features(schema, dims))


def encode_scene(scene_dir: str) -> tuple[str, bytes | None, str | None]:
    """(scene name, serialised example or None, error or None), in a worker."""
    schema, dims = _WORKER["schema"], _WORKER["dims"]
    path = pathlib.Path(scene_dir)
    try:
        faults.point("pack.encode_scene")
        check_scene_schema(path, schema)
        reader = SceneReader(path, schema)
        if reader.dims != dims:
            raise SceneError(f"frames / resolution {reader.dims} differ from the dataset's {dims}")
        flat = reader.example()
        data = tfds_io.serialize(_WORKER["features"], tfds_io.nested_example(schema, flat))
        return path.name, data, None
    except (SceneError, OSError, ValueError, KeyError, TypeError, RuntimeError, EOFError,
            AttributeError, zipfile.BadZipFile) as err:
        # (TFDS re-raises a feature's encoding error as RuntimeError; a truncated .npz is a
        # BadZipFile or EOFError; a metadata.json of the wrong shape a TypeError/AttributeError)
        return path.name, None, str(err).replace("\n", " ")[:500]


def _die_with(parent: int) -> None:
    """Ask Linux to SIGKILL this process when its parent dies; exit now if it already has."""
    import ctypes
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    if os.getppid() != parent:
        os._exit(1)


# ------------------------------------------------------------------------ planning
def find_scenes(scenes_dir: pathlib.Path) -> tuple[list[pathlib.Path], int]:
    """(complete scene directories in name order, number of incomplete ones). Scene directories
    are those named ``scene_*`` (the worker's naming) or holding ``_SUCCESS``; the worker's
    hidden work directories count as incomplete; other folders (``logs``) are ignored."""
    return scene_dir.survey(scenes_dir)


def scene_seed(scene: pathlib.Path) -> int:
    """The scene's seed: ``metadata.seed``, else ``flags.seed``, else the digits of its name.
    A metadata.json of the wrong shape is a :class:`SceneError` naming the file."""
    path = scene / scene_dir.METADATA_FILE
    try:
        meta = read_json(path) if path.is_file() else {}
    except (OSError, ValueError) as err:
        raise SceneError(f"{str(path)!r} cannot be read: {err}") from None
    seed = None
    if not isinstance(meta, dict):
        raise SceneError(f"{str(path)!r} is not a JSON object")
    for section in ("metadata", "flags"):
        part = meta.get(section, {})
        if not isinstance(part, dict):
            raise SceneError(f"{str(path)!r}: {section!r} is not an object")
        if seed is None:
            seed = part.get("seed")
    if seed is None:
        digits = "".join(c for c in scene.name if c.isdigit())
        if not digits:
            raise SceneError(f"{str(scene)!r}: no seed in metadata.json and none in its name")
        return int(digits)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SceneError(f"{str(path)!r}: seed {seed!r} is not a whole number ≥ 0")
    return seed


def resolve_names(schema: Schema, scenes: list[pathlib.Path],
                  given: Mapping[str, Sequence[str]] | None = None) -> Schema:
    """``schema`` with every :data:`~kubric.io.schema.NAMES_FROM_SCENES` class label given the
    sorted distinct values (as text) its source holds in ``scenes``, or the names ``given`` for
    it (e.g. another dataset's, so that ids agree; every value found must be among them). A
    scene whose metadata cannot be read is left out here (the packer reports it as corrupt)."""
    given = {k: [str(n) for n in v] for k, v in dict(given or {}).items()}
    collect = [f for f in schema.features if f.names_from_scenes]
    wrong = sorted(set(given) - {f.name for f in collect})
    if wrong:
        raise DatasetError(f"class names given for {wrong}, which are not class labels collected "
                           f"when packing in schema {schema.name!r} (those are "
                           f"{[f.name for f in collect]})")
    for feature, names in given.items():
        dup = sorted({n for n in names if names.count(n) > 1})
        if not names or dup:
            raise DatasetError(f"class names for {feature!r} must be non-empty and distinct "
                               f"(repeated: {dup})")
    if not collect:
        return schema
    found: dict[str, set[str]] = {f.name: set() for f in collect}
    for scene in scenes:
        reader = SceneReader(scene, schema)
        for f in collect:
            try:
                values = reader.raw_values(f)
            except (SceneError, SchemaError, OSError, ValueError):
                continue
            found[f.name].update(str(v) for v in values)
    for feature, names in given.items():
        extra = sorted(found[feature] - set(names))
        if extra:
            raise DatasetError(f"the scenes hold {feature!r} values {extra}, which the given "
                               f"class names {names} lack")
    empty = sorted(n for n, values in found.items() if not values and n not in given)
    if empty:
        raise DatasetError(f"no complete scene holds a value of {empty}, so their class-label "
                           "names cannot be collected")
    return schema.with_names({n: given.get(n, sorted(values)) for n, values in found.items()})


def read_class_names(specs: Sequence[str]) -> dict[str, list[str]]:
    """``["instances/category=PATH", ...]`` (``--class-names``) → ``{feature: names}``; PATH is a
    text file with one name per line (TFDS's ``*.labels.txt`` of another dataset)."""
    out = {}
    for spec in specs:
        feature, sep, path = spec.partition("=")
        if not sep or not feature or not path:
            raise DatasetUsageError(f"--class-names {spec!r} is not FEATURE=FILE (e.g. "
                               "instances/category=other/instances-category.labels.txt)")
        try:
            text = pathlib.Path(path).read_text(encoding="utf-8")
        except OSError as err:
            raise DatasetError(f"--class-names {spec!r}: cannot read {path!r}: "
                               f"{err.strerror}") from None
        out[feature] = [line.strip() for line in text.splitlines() if line.strip()]
    return out


#: what the packer writes into a dataset directory besides its shards (TFDS metadata, labels)
PACKER_FILES = (layout.INFO_FILE, "dataset_info.json", "features.json")
_SHARD_RE = re.compile(r"^[a-z][a-z0-9_]*-[a-z][a-z0-9_]*\.array_record-\d{5}-of-\d{5}$")


def packer_files(directory: pathlib.Path) -> tuple[list[str], list[str]]:
    """(names the packer wrote, other entries) of a dataset directory."""
    ours, other = [], []
    for entry in sorted(pathlib.Path(directory).iterdir()):
        mine = entry.is_file() and not entry.is_symlink() and (
            entry.name in PACKER_FILES or entry.name.endswith(".labels.txt")
            or _SHARD_RE.match(entry.name))
        (ours if mine else other).append(entry.name)
    return ours, other


def check_out(out: pathlib.Path, overwrite: bool) -> None:
    if out.is_symlink() or (out.exists() and not out.is_dir()):
        raise DatasetUsageError(f"--out {str(out)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not layout.is_dataset(out):
            raise DatasetUsageError(f"--out {str(out)!r} exists and is not a dataset (refusing "
                                    "to write into it)")
        if not overwrite:
            raise DatasetUsageError(f"--out {str(out)!r} is already a dataset; pass --overwrite "
                                    "to replace it")
        _, other = packer_files(out)
        if other:
            raise DatasetUsageError(
                f"--out {str(out)!r} holds {', '.join(other[:5])}"
                f"{' ...' if len(other) > 5 else ''}, which kubric pack did not write; "
                "--overwrite replaces only a dataset the packer wrote: move them away first")


def check_options(splits, workers: int, examples_per_shard: int, out: pathlib.Path,
                  overwrite: bool) -> dict[str, float]:
    """The split fractions; raises DatasetError (one line) on a bad option or output."""
    try:
        split_fractions = layout.parse_splits(splits)
    except DatasetError as err:
        raise DatasetUsageError(str(err)) from None
    if workers < 1:
        raise DatasetUsageError(f"--workers must be ≥ 1, got {workers}")
    if examples_per_shard < 1:
        raise DatasetUsageError(f"examples per shard must be ≥ 1, got {examples_per_shard}")
    check_out(out, overwrite)
    return split_fractions


def check_pack_output(out, scenes_dir) -> None:
    """:func:`kubric.io.output_check.check_output` for a pack (URL outputs allowed)."""
    check_output(out, scene_folders(scenes_dir), [scenes_dir], urls=True, command="kubric pack")


# ------------------------------------------------------------------------ the packer
def pack(scenes_dir, out, name: str | None = None, splits=DEFAULT_SPLITS, workers: int = 1,
         schema: Schema | str | None = None, examples_per_shard: int = 256,
         progress: bool = True, verify: bool = False, overwrite: bool = False,
         class_names: Mapping[str, Sequence[str]] | None = None) -> PackResult:
    """Pack the complete scenes of ``scenes_dir`` into the dataset directory ``out`` (module
    doc); ``class_names`` fixes the names of class labels otherwise collected from the scenes
    (:func:`resolve_names`). Raises :class:`~kubric.datasets.layout.DatasetError` (one line) on
    bad input before writing anything."""
    start = time.perf_counter()
    check_pack_output(out, scenes_dir)
    scenes_dir, out = pathlib.Path(scenes_dir), pathlib.Path(out)
    if not scenes_dir.is_dir():
        raise DatasetError(f"SCENES_DIR {str(scenes_dir)!r} is not a directory")
    split_fractions = check_options(splits, workers, examples_per_shard, out, overwrite)
    complete, incomplete = find_scenes(scenes_dir)
    if not complete:
        raise DatasetError(f"{str(scenes_dir)!r} holds no complete scene directory (with "
                           f"_SUCCESS); {incomplete} incomplete")
    schema, dims, origin = schema_origin_and_dims(complete, schema)
    schema = resolve_names(schema, complete, class_names)
    name = name or schema.name
    if not layout.NAME_PATTERN.match(name):
        raise DatasetError(f"--name {name!r} must be a lower-case identifier (letters, digits, _)")
    assignment: dict[str, list[pathlib.Path]] = {s: [] for s in split_fractions}
    corrupt: list[tuple[str, str]] = []
    seeds = []
    for scene in complete:
        try:
            seeds.append((scene_seed(scene), scene))
            assignment[layout.split_of(seeds[-1][0], split_fractions)].append(scene)
        except (SceneError, ValueError) as err:
            corrupt.append((str(scene), str(err)))
    scene_dir.check_unique_seeds(seeds)

    plan = {"schema": schema.name, "name": name, "splits": split_fractions, "dims": dims,
            "examples_per_shard": examples_per_shard, "format_version": layout.FORMAT_VERSION,
            "shard_writer_options": layout.SHARD_WRITER_OPTIONS,
            "class_names": {f.name: f.names for f in schema.features if f.names},
            "scenes": {s: [p.name for p in v] for s, v in assignment.items()}}
    plan_key = hashlib.sha256(repr(sorted(plan.items())).encode()).hexdigest()
    with output_lock(out):
        check_out(out, overwrite)  # again, now that no other pack can change it
        work = work_dir(out)
        state = open_work(work, plan_key)
        resumed = sum(len(sh["scenes"]) + len(sh.get("corrupt", []))
                      for shards in state["shards"].values() for sh in shards)
        corrupt += [tuple(c) for shards in state["shards"].values() for sh in shards
                    for c in sh.get("corrupt", [])]
        done = {split: done_names(state, split) for split in assignment}  # once: O(N), not O(N²)
        todo = [(split, scene) for split, scenes in assignment.items() for scene in scenes
                if scene.name not in done[split]]
        from kubric.datasets import tfds_io
        features = tfds_io.tfds_features(schema, dims)
        _write_shards(work, state, todo, schema, dims, name, workers, examples_per_shard,
                      corrupt, progress)
        if not any(sh["scenes"] for shards in state["shards"].values() for sh in shards):
            first = f"; first: {corrupt[0][0]}: {corrupt[0][1]}" if corrupt else ""
            shutil.rmtree(work, ignore_errors=True)
            raise DatasetError(f"no scene could be packed: all {len(complete)} complete scenes "
                               f"are corrupt{first}")
        counts = finalise(work, state, schema, name, dims, split_fractions, incomplete,
                           features)
        faults.point("pack.finalised")
        if verify:
            from kubric.datasets.verify import verify_dataset
            try:
                verify_dataset(work, scenes_dir, progress=progress)
            except DatasetError as err:
                shutil.rmtree(work, ignore_errors=True)  # finished but wrong: never the output
                raise DatasetError(f"{err}; nothing was written to {str(out)!r}") from None
        swap_into_place(work, out)
    return PackResult(out, counts, incomplete, corrupt, time.perf_counter() - start, resumed,
                      origin)


def output_lock(out: pathlib.Path):
    """The lock held while packing into ``out`` (``.NAME.lock`` beside it)."""
    @contextlib.contextmanager
    def held():
        lock = OutputLock(out.parent / f".{out.name}.lock", f"--out {str(out)!r}")
        lock.acquire()  # OutputBusy: exit status 3, as every command's busy output
        try:
            yield lock
        finally:
            lock.release()
    return held()


def _write_shards(work, state, todo, schema, dims, name, workers, examples_per_shard, corrupt,
                  progress) -> None:
    """Encode the scenes of ``todo`` and write them into shards, recording each finished shard."""
    results = _encoded(todo, schema, dims, workers)
    from tqdm import tqdm
    bar = tqdm(total=len(todo), unit="scene", desc=f"pack {name}", disable=not progress)
    current: dict[str, ShardWriter] = {}
    try:
        for (split, scene), (scene_name, data, error) in zip(todo, results, strict=True):
            bar.update(1)
            writer = current.get(split)
            if writer is None:
                index = len(state["shards"].setdefault(split, []))
                writer = current[split] = ShardWriter(work, name, split, index)
            if error is not None:
                writer.corrupt.append((str(scene), error))
                corrupt.append((str(scene), error))
            else:
                writer.add(scene_name, data)
            if len(writer.scenes) >= examples_per_shard:
                finish_shard(work, state, current.pop(split))
        for split in list(current):
            finish_shard(work, state, current.pop(split))
    finally:
        bar.close()
        for writer in current.values():  # interrupted: the unfinished shards are dropped
            writer.abandon()
        if hasattr(results, "close"):
            results.close()


def _encoded(todo, schema: Schema, dims: dict, workers: int):
    """Iterator of ``encode_scene`` results in ``todo`` order (a process pool when workers > 1)."""
    paths = [str(scene) for _, scene in todo]
    if workers == 1 or len(paths) <= 1:
        init_worker(schema, dims)
        return (encode_scene(p) for p in paths)
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
        initializer=init_worker, initargs=(schema, dims, os.getpid()))

    def iterate():
        finished = False
        try:
            yield from pool.map(encode_scene, paths, chunksize=1)
            finished = True
        finally:
            if finished:
                pool.shutdown()
            else:  # interrupted (a signal, an error): end the workers now, do not wait for them
                _stop_pool(pool)
    return iterate()


def _stop_pool(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        with contextlib.suppress(OSError, ValueError):
            proc.terminate()
    deadline = time.monotonic() + 5.0
    for proc in processes:
        with contextlib.suppress(OSError, ValueError):
            proc.join(max(0.0, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
