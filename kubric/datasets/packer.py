"""``kubric pack``: scene directories → a TFDS-layout ArrayRecord dataset, without TensorFlow.

* Scenes are the sub-directories of SCENES_DIR; one without ``_SUCCESS`` is incomplete: skipped
  and counted. A complete scene that cannot be read (unreadable PNG, missing layer, a field off
  the schema) is reported by path and skipped; the rest are packed.
* The recipe schema comes from the scenes' ``metadata.json`` (``flags.recipe``) unless given.
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
  ``progress.json``, so an interrupted pack resumes after the last finished shard. The work
  directory is renamed to the output only when everything is written.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import hashlib
import multiprocessing
import os
import pathlib
import shutil
import time
from collections.abc import Mapping, Sequence

from kubric.datasets import layout
from kubric.datasets.layout import DatasetError
from kubric.datasets.scene_reader import SceneError, SceneReader, is_complete
from kubric.io.json_io import read_json, write_json
from kubric.io.schema import Schema, SchemaError, get_schema

PROGRESS_FILE = "progress.json"
DEFAULT_SPLITS = "train=0.9,validation=0.1"


@dataclasses.dataclass
class PackResult:
    out: pathlib.Path
    counts: dict[str, int]
    incomplete: int
    corrupt: list[tuple[str, str]]
    seconds: float
    resumed_scenes: int = 0

    def format(self) -> str:
        lines = [f"packed {sum(self.counts.values())} scenes into {self.out} "
                 f"({', '.join(f'{k}: {v}' for k, v in self.counts.items())}) in "
                 f"{self.seconds:.1f} s"]
        if self.resumed_scenes:
            lines.append(f"  resumed: {self.resumed_scenes} scenes were already packed")
        if self.incomplete:
            lines.append(f"  skipped {self.incomplete} incomplete scene directories (no _SUCCESS)")
        for path, reason in self.corrupt:
            lines.append(f"  skipped corrupt scene {path}: {reason}")
        return "\n".join(lines)


# ------------------------------------------------------------------------ per-scene encoding
_WORKER: dict = {}


def _init_worker(schema: Schema, dims: dict) -> None:
    from kubric.datasets import tfds_io
    _WORKER.update(schema=schema, dims=dims, features=tfds_io.tfds_features(schema, dims))


def _encode_scene(scene_dir: str) -> tuple[str, bytes | None, str | None]:
    """(scene name, serialised example or None, error or None), in a worker."""
    from kubric.datasets import tfds_io
    schema, dims = _WORKER["schema"], _WORKER["dims"]
    path = pathlib.Path(scene_dir)
    try:
        reader = SceneReader(path, schema)
        if reader.dims != dims:
            raise SceneError(f"frames / resolution {reader.dims} differ from the dataset's {dims}")
        flat = reader.example()
        data = tfds_io.serialize(_WORKER["features"], tfds_io.nested_example(schema, flat))
        return path.name, data, None
    except (SceneError, OSError, ValueError, KeyError, TypeError, RuntimeError) as err:
        # (TFDS re-raises a feature's encoding error as RuntimeError)
        return path.name, None, str(err).replace("\n", " ")[:500]


# ------------------------------------------------------------------------ planning
def find_scenes(scenes_dir: pathlib.Path) -> tuple[list[pathlib.Path], int]:
    """(complete scene directories in name order, number of incomplete ones). Scene directories
    are those named ``scene_*`` (the worker's naming) or holding ``_SUCCESS``; the worker's
    hidden work directories count as incomplete; other folders (``logs``) are ignored."""
    complete, incomplete = [], 0
    for entry in sorted(scenes_dir.iterdir()):
        if not entry.is_dir():
            continue
        if is_complete(entry):
            complete.append(entry)
        elif entry.name.startswith("scene_") or (entry.name.startswith(".scene_")
                                                 and ".incomplete" in entry.name):
            incomplete += 1
    return complete, incomplete


def _seed_of(scene: pathlib.Path) -> int:
    meta = read_json(scene / "metadata.json") if (scene / "metadata.json").is_file() else {}
    seed = meta.get("metadata", {}).get("seed", meta.get("flags", {}).get("seed"))
    if seed is None:
        digits = "".join(c for c in scene.name if c.isdigit())
        if not digits:
            raise SceneError(f"{str(scene)!r}: no seed in metadata.json and none in its name")
        seed = int(digits)
    return int(seed)


def _recipe_of(scene: pathlib.Path) -> str:
    try:
        return str(read_json(scene / "metadata.json")["flags"]["recipe"])
    except (OSError, KeyError, TypeError, ValueError):
        raise DatasetError(f"{str(scene)!r}: metadata.json is missing or names no recipe "
                           "(flags.recipe); pass --schema") from None


def _schema_and_dims(complete: list[pathlib.Path], schema) -> tuple[Schema, dict]:
    """The schema (given, or the recipe of the first scene whose metadata.json reads) and the
    frame count / resolution of the first scene that has them."""
    errors = []
    for scene in complete:
        try:
            found = get_schema(schema if schema is not None else _recipe_of(scene))
            return found, SceneReader(scene, found).dims
        except (SceneError, DatasetError, OSError) as err:
            errors.append(err)
    raise DatasetError(f"no complete scene has a readable metadata.json (first: {errors[0]})")


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
            raise DatasetError(f"--class-names {spec!r} is not FEATURE=FILE (e.g. "
                               "instances/category=other/instances-category.labels.txt)")
        try:
            text = pathlib.Path(path).read_text(encoding="utf-8")
        except OSError as err:
            raise DatasetError(f"--class-names {spec!r}: cannot read {path!r}: "
                               f"{err.strerror}") from None
        out[feature] = [line.strip() for line in text.splitlines() if line.strip()]
    return out


def _check_out(out: pathlib.Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise DatasetError(f"--out {str(out)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not layout.is_dataset(out):
            raise DatasetError(f"--out {str(out)!r} exists and is not a dataset (refusing to "
                               "write into it)")
        if not overwrite:
            raise DatasetError(f"--out {str(out)!r} is already a dataset; pass --overwrite to "
                               "replace it")


def check_options(splits, workers: int, examples_per_shard: int, out: pathlib.Path,
                  overwrite: bool) -> dict[str, float]:
    """The split fractions; raises DatasetError (one line) on a bad option or output."""
    split_fractions = layout.parse_splits(splits)
    if workers < 1:
        raise DatasetError(f"--workers must be ≥ 1, got {workers}")
    if examples_per_shard < 1:
        raise DatasetError(f"examples per shard must be ≥ 1, got {examples_per_shard}")
    _check_out(out, overwrite)
    return split_fractions


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
    scenes_dir, out = pathlib.Path(scenes_dir), pathlib.Path(out)
    if not scenes_dir.is_dir():
        raise DatasetError(f"SCENES_DIR {str(scenes_dir)!r} is not a directory")
    split_fractions = check_options(splits, workers, examples_per_shard, out, overwrite)
    complete, incomplete = find_scenes(scenes_dir)
    if not complete:
        raise DatasetError(f"{str(scenes_dir)!r} holds no complete scene directory (with "
                           f"_SUCCESS); {incomplete} incomplete")
    schema, dims = _schema_and_dims(complete, schema)
    schema = resolve_names(schema, complete, class_names)
    name = name or schema.name
    if not layout.NAME_PATTERN.match(name):
        raise DatasetError(f"--name {name!r} must be a lower-case identifier (letters, digits, _)")
    assignment: dict[str, list[pathlib.Path]] = {s: [] for s in split_fractions}
    corrupt: list[tuple[str, str]] = []
    for scene in complete:
        try:
            assignment[layout.split_of(_seed_of(scene), split_fractions)].append(scene)
        except (SceneError, ValueError) as err:
            corrupt.append((str(scene), str(err)))

    plan = {"schema": schema.name, "name": name, "splits": split_fractions, "dims": dims,
            "examples_per_shard": examples_per_shard, "format_version": layout.FORMAT_VERSION,
            "class_names": {f.name: f.names for f in schema.features if f.names},
            "scenes": {s: [p.name for p in v] for s, v in assignment.items()}}
    plan_key = hashlib.sha256(repr(sorted(plan.items())).encode()).hexdigest()
    work = out.parent / f".{out.name}.incomplete"
    state = _open_work(work, plan_key)
    resumed = sum(len(sh["scenes"]) + len(sh.get("corrupt", []))
                  for shards in state["shards"].values() for sh in shards)
    corrupt += [tuple(c) for shards in state["shards"].values() for sh in shards
                for c in sh.get("corrupt", [])]

    done = {split: _done_names(state, split) for split in assignment}  # once: O(N), not O(N²)
    todo = [(split, scene) for split, scenes in assignment.items() for scene in scenes
            if scene.name not in done[split]]
    from kubric.datasets import tfds_io
    features = tfds_io.tfds_features(schema, dims)
    results = _encoded(todo, schema, dims, workers)
    from tqdm import tqdm
    bar = tqdm(total=len(todo), unit="scene", desc=f"pack {name}", disable=not progress)
    try:
        current: dict[str, _ShardWriter] = {}
        for (split, scene), (scene_name, data, error) in zip(todo, results, strict=True):
            bar.update(1)
            writer = current.get(split)
            if writer is None:
                index = len(state["shards"].setdefault(split, []))
                writer = current[split] = _ShardWriter(work, name, split, index)
            if error is not None:
                writer.corrupt.append((str(scene), error))
                corrupt.append((str(scene), error))
            else:
                writer.add(scene_name, data)
            if len(writer.scenes) >= examples_per_shard:
                _finish_shard(work, state, writer)
                current.pop(split)
        for writer in current.values():
            _finish_shard(work, state, writer)
    finally:
        bar.close()
        if hasattr(results, "close"):
            results.close()
    if not any(sh["scenes"] for shards in state["shards"].values() for sh in shards):
        first = f"; first: {corrupt[0][0]}: {corrupt[0][1]}" if corrupt else ""
        shutil.rmtree(work, ignore_errors=True)
        raise DatasetError(f"no scene could be packed: all {len(complete)} complete scenes are "
                           f"corrupt{first}")
    counts = _finalise(work, state, schema, name, dims, split_fractions, incomplete, features)
    _swap_into_place(work, out)
    result = PackResult(out, counts, incomplete, corrupt, time.perf_counter() - start, resumed)
    if verify:
        from kubric.datasets.verify import verify_dataset
        verify_dataset(out, scenes_dir, progress=progress)
    return result


def _encoded(todo, schema: Schema, dims: dict, workers: int):
    """Iterator of ``_encode_scene`` results in ``todo`` order (a process pool when workers > 1)."""
    paths = [str(scene) for _, scene in todo]
    if workers == 1 or len(paths) <= 1:
        _init_worker(schema, dims)
        return (_encode_scene(p) for p in paths)
    pool = concurrent.futures.ProcessPoolExecutor(
        max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
        initializer=_init_worker, initargs=(schema, dims))

    def iterate():
        try:
            yield from pool.map(_encode_scene, paths, chunksize=1)
        finally:
            pool.shutdown(cancel_futures=True)
    return iterate()


def _open_work(work: pathlib.Path, plan_key: str) -> dict:
    """The work directory's progress (fresh unless it was made for the same plan)."""
    progress_path = work / PROGRESS_FILE
    if progress_path.is_file():
        try:
            state = read_json(progress_path)
        except ValueError:
            state = {}
        if state.get("plan") == plan_key:
            keep = {sh["file"] for shards in state["shards"].values() for sh in shards}
            for entry in work.iterdir():  # drop a shard that was being written
                if entry.name != PROGRESS_FILE and entry.name not in keep:
                    entry.unlink()
            return state
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    state = {"plan": plan_key, "shards": {}}
    write_json(state, progress_path)
    return state


def _done_names(state: dict, split: str) -> set[str]:
    done = set()
    for shard in state["shards"].get(split, []):
        done.update(shard["scenes"])
        done.update(pathlib.Path(p).name for p, _ in shard.get("corrupt", []))
    return done


class _ShardWriter:
    """One shard being written (a temporary name until finished)."""

    def __init__(self, work: pathlib.Path, name: str, split: str, index: int):
        from array_record.python import array_record_module
        self.split, self.index = split, index
        self.file = f"{name}-{split}.part-{index:05d}"
        self.path = work / self.file
        self._writer = array_record_module.ArrayRecordWriter(str(self.path), "group_size:1")
        self.scenes: list[str] = []
        self.corrupt: list[tuple[str, str]] = []
        self.num_bytes = 0

    def add(self, scene_name: str, data: bytes) -> None:
        self._writer.write(data)
        self.scenes.append(scene_name)
        self.num_bytes += len(data)

    def close(self) -> None:
        self._writer.close()


def _finish_shard(work: pathlib.Path, state: dict, writer: _ShardWriter) -> None:
    writer.close()
    if not writer.scenes:
        writer.path.unlink()
    state["shards"].setdefault(writer.split, []).append(
        {"file": writer.file if writer.scenes else "", "scenes": writer.scenes,
         "corrupt": writer.corrupt, "num_bytes": writer.num_bytes})
    write_json(state, work / PROGRESS_FILE)


def _finalise(work, state, schema, name, dims, split_fractions, incomplete, features) -> dict:
    """Final shard names, TFDS metadata and the kubric marker; returns counts per split."""
    import tensorflow_datasets as tfds

    from kubric import __version__
    from kubric.datasets.source import schema_to_json
    split_infos, counts, scenes, shard_lengths = [], {}, {}, {}
    for split in split_fractions:
        shards = [sh for sh in state["shards"].get(split, []) if sh["scenes"]]
        for i, shard in enumerate(shards):
            os.replace(work / shard["file"], work / layout.shard_name(name, split, i, len(shards)))
        counts[split] = sum(len(sh["scenes"]) for sh in shards)
        scenes[split] = [s for sh in shards for s in sh["scenes"]]
        shard_lengths[split] = [len(sh["scenes"]) for sh in shards]
        if shards:
            split_infos.append(tfds.core.SplitInfo(
                name=split, shard_lengths=[len(sh["scenes"]) for sh in shards],
                num_bytes=sum(sh["num_bytes"] for sh in shards)))
    (work / PROGRESS_FILE).unlink()
    tfds.folder_dataset.write_metadata(
        data_dir=str(work), features=features, split_infos=split_infos, check_data=False,
        description=f"Kubric {schema.name} scenes packed by kubric {__version__}. "
                    f"{schema.description}",
        homepage="https://github.com/google-research/kubric")
    write_json({"format": layout.FORMAT, "format_version": layout.FORMAT_VERSION,
                "name": name, "schema": schema.name, "schema_version": schema.version,
                "dims": dims, "splits": split_fractions, "counts": counts,
                "shard_lengths": shard_lengths, "scenes": scenes,
                "incomplete_skipped": incomplete, "kubric_version": __version__,
                "schema_json": schema_to_json(schema)},
               work / layout.INFO_FILE)
    return counts


def _swap_into_place(work: pathlib.Path, out: pathlib.Path) -> None:
    """Rename the finished work directory to ``out`` (replacing an old dataset / empty dir)."""
    old = None
    if out.exists():
        old = out.parent / f".{out.name}.old-{os.getpid()}"
        os.replace(out, old)
    os.replace(work, out)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
