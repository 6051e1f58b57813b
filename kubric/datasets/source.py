"""Random access to a packed dataset as numpy dicts, without TensorFlow.

``load(DATASET_DIR, split, task=None, **options)`` returns a :class:`DataSource`: ``len``,
``source[i]`` and ``source.__getitems__([i, j, ...])`` (what Grain and PyTorch's samplers use).
It reads the split's ArrayRecord shards, parses only the top-level features its task needs
(TFDS's numpy parser) and decodes them with the dataset's own TFDS feature connectors.

An example (task ``None``) is the nested dict TFDS gives (``ex["metadata"]["depth_range"]``,
``ex["instances"]["positions"]``), made regular: per-frame features are arrays (T, H, W, C),
per-instance features are arrays with N first (ragged ``bboxes`` / ``bbox_frames``: a list of N
arrays), text is ``str``. ``units`` picks the form of the per-frame layers: ``"raw"`` (the
default) gives what the dataset stores, upstream Kubric's layout (MOVi's flow, depth, normals and
object coordinates as uint16 samples, decoded by hand with ``metadata/*_range``);
``"physical"`` decodes every layer feature by its layer kind (:mod:`kubric.io.encodings`) to
float32 physical units: flow in pixels and depth in metres (over the scene's range), normals as
unit vectors, object coordinates and UV in [0, 1]; RGB and labels stay integers. Tasks see the
decoded example. A source is picklable (readers reopen lazily in each process), so it
works in ``DataLoader(num_workers=...)`` and Grain worker processes. It is also safe across
``fork``: a reader opened in the parent (e.g. by looking at ``source[0]`` first) is never used in a
forked child; the child opens its own (the process id is checked on every read).
A shard or ``features.json`` that cannot be read is a :class:`DatasetError` naming the file.

``DATASET_DIR`` may be a URL (``s3://bucket/ds``, ``gs://...``, any fsspec URL): the split's
shards are fetched once into a local cache (:mod:`kubric.datasets.dataset_cache`) and read from
there.
"""

from __future__ import annotations

import bisect
import os
import pathlib
import threading
from collections.abc import Sequence

import numpy as np

from kubric.datasets import layout
from kubric.datasets.layout import DatasetError
from kubric.datasets.tasks import check_servable, get_task
from kubric.datasets.tfds_io import flatten, unflatten
from kubric.io import storage
from kubric.io.schema import Feature, Schema, SchemaError

#: held while a source imports TFDS and opens its shards: two threads whose first use of a
#: source coincides (Grain's and PyTorch's prefetch threads) could otherwise import TFDS's lazily
#: imported modules at once, which deadlocked the JAX snippet of the README under load
_OPEN_LOCK = threading.RLock()

#: what ``load(..., units=...)`` accepts (module doc)
UNITS = ("raw", "physical")


def _regular(f: Feature, value, dims: dict):
    """A TFDS-decoded value of feature ``f`` in the regular form (module doc)."""
    if f.dtype == "str":
        as_str = lambda v: v.decode("utf-8") if isinstance(v, bytes) else str(v)
        if f.sequence and f.shape:
            return [[as_str(x) for x in v] for v in value]
        return [as_str(v) for v in value] if f.sequence or f.shape else as_str(value)
    dtype = f.type.value_dtype(f)
    if f.shape and f.shape[0] == "V":
        rest = tuple(d for d in f.shape[1:])
        fix = lambda v: np.asarray(v, dtype=dtype).reshape((-1, *rest))
        return [fix(v) for v in value] if f.sequence else fix(value)
    if f.sequence or f.type.per_frame:
        if isinstance(value, np.ndarray):
            return value.astype(dtype, copy=False)
        if len(value) == 0:
            shape = tuple(d if isinstance(d, int) else dims.get(d, 0) for d in f.shape)
            return np.zeros((0, *shape), dtype=dtype)
        return np.stack([np.asarray(v, dtype=dtype) for v in value])
    return np.asarray(value, dtype=dtype)[()] if not f.shape else np.asarray(value, dtype=dtype)


def _with_ranges(schema: Schema, keys: tuple[str, ...]) -> tuple[str, ...]:
    """``keys`` (top-level features to decode) plus those holding the ranges that decode the
    quantised layer features among them to physical units."""
    top = lambda name: name.split("/", 1)[0]
    extra = []
    for f in schema.features:
        source = schema.layer_kind(f) if top(f.name) in keys else None
        if source and source[1].needs_range(f.dtype):
            extra += [top(r) for r in [schema.range_feature(source[0])] if r]
    return tuple(dict.fromkeys(keys + tuple(extra)))


class _ShardReader:
    """Records of a split's shards by global index. Each shard's ArrayRecord reader is opened on
    first use, in the calling thread: array_record's own data source opens readers in a thread
    pool, and a reader made in a pool thread of a forked child crashes (segfault) once the parent
    has read."""

    def __init__(self, paths: list[str], lengths: list[int]):
        self.paths = paths
        self.ends = list(np.cumsum(lengths))
        self.readers: dict[int, object] = {}

    def shard_of(self, index: int) -> tuple[int, int]:
        shard = bisect.bisect_right(self.ends, index)
        return shard, index - (self.ends[shard - 1] if shard else 0)

    def __getitems__(self, indices: Sequence[int]) -> list[bytes]:
        from array_record.python import array_record_module
        out = []
        for index in indices:
            shard, position = self.shard_of(int(index))
            if shard not in self.readers:
                self.readers[shard] = array_record_module.ArrayRecordReader(
                    self.paths[shard], "readahead_buffer_size:0", file_reader_buffer_size=32768)
            out.append(self.readers[shard].read([position])[0])
        return out


#: readers a forked child inherited from its parent (never used, never destroyed; see _open)
_INHERITED: list = []


class DataSource:
    """A map-style source of one split (see module doc). Build with :func:`load`."""

    def __init__(self, dataset_dir, split: str, task=None, units: str = "raw", **task_options):
        #: the dataset as given: a directory or a URL (read through a local cache)
        remote = storage.is_url(str(dataset_dir))
        self.location = str(dataset_dir) if remote else str(pathlib.Path(dataset_dir))
        if remote:
            from kubric.datasets.dataset_cache import fetch
            dataset_dir = fetch(self.location, split if isinstance(split, str) else None)
        self.dataset_dir = pathlib.Path(dataset_dir)
        self.info = layout.read_info(self.dataset_dir)
        if split not in self.info["counts"]:  # a split that got no scene loads empty
            raise DatasetError(f"{self.location!r} has no split {split!r} (splits: "
                               f"{', '.join(self.info['counts'])})")
        self.split = split
        self.schema = Schema.from_json(self.info["schema_json"])
        self.dims = dict(self.info["dims"])
        self.task = get_task(task)
        self.task_options = self.task.check_options(task_options)
        check_servable(self.task, self.schema, repr(self.location))
        if units not in UNITS:
            raise DatasetError(f"units {units!r} is not one of {UNITS}")
        self.units = units
        self._keys = self.task.decode_keys(self.schema, self.task_options)
        if units == "physical" and self._keys is not None:
            self._keys = _with_ranges(self.schema, self._keys)
        self.scenes: list[str] = list(self.info["scenes"][split])
        self._frames = self.task.per_frame and int(self.dims["T"])
        self._reader = None
        self._features = None
        self._parser = None
        self._last = None
        self._pid = os.getpid()

    # ---------------------------------------------------------------- pickling
    def __getstate__(self):
        state = dict(self.__dict__)
        state.update(_reader=None, _features=None, _parser=None, _last=None)
        return state

    # ---------------------------------------------------------------- lazy openers
    def shard_paths(self) -> list[str]:
        name, count = self.info["name"], len(self.info["shard_lengths"][self.split])
        return [str(self.dataset_dir / layout.shard_name(name, self.split, i, count))
                for i in range(count)]

    def _open(self):
        if self._pid != os.getpid():  # a forked child: the parent's reader is not ours to use
            # ... nor to destroy: its destructor would join the parent's reader threads, which
            # do not exist in the child (a segfault). It is kept, unused, until the child exits.
            if self._reader is not None and "uncompressed" not in self.info.get(
                    "shard_writer_options", ""):
                raise DatasetError(
                    f"{str(self.dataset_dir)!r} has zstd-compressed shards (packed by an older "
                    "kubric), which cannot be read in a forked process once the parent has "
                    "read them; pack it again, or use multiprocessing_context='spawn'")
            _INHERITED.append((self._reader, self._features))
            self._reader = self._features = self._parser = self._last = None
            self._pid = os.getpid()
        if self._reader is None:
            with _OPEN_LOCK:  # one thread imports TFDS and opens the reader (see _OPEN_LOCK)
                if self._reader is None:
                    self._open_reader()
        return self._reader

    def _open_reader(self) -> None:
        """Parse the dataset's features.json and open its shards (under :data:`_OPEN_LOCK`)."""
        import tensorflow_datasets as tfds
        from tensorflow_datasets.core import utils
        try:
            features = tfds.features.FeatureConnector.from_config(str(self.dataset_dir))
        except Exception as err:  # JSONDecodeError, KeyError, OSError ... of TFDS's parser
            raise DatasetError(f"{str(self.dataset_dir / 'features.json')!r} cannot be read: "
                               f"{_one_line(err)}") from None
        self._features = features
        keys = self._keys or tuple(self._features.keys())
        specs = {k: self._features.get_serialized_info()[k] for k in keys}
        self._parser = (specs, utils.flatten_nest_dict(specs), keys)
        lengths = self.info["shard_lengths"][self.split]
        missing = [p for p in self.shard_paths() if not os.path.isfile(p)]
        if missing:
            raise DatasetError(f"{missing[0]!r}: shard missing ({len(missing)} of the "
                               f"{self.split} split's shards are)")
        self._reader = _ShardReader(self.shard_paths(), lengths)

    def _records(self, scenes: list[int]) -> list[bytes]:
        """The serialised examples of ``scenes``; a shard that cannot be read is named."""
        reader = self._open()
        try:
            return list(reader.__getitems__(scenes))
        except Exception as err:  # array_record raises RuntimeError / ValueError with no path
            bad = sorted({reader.paths[reader.shard_of(s)[0]] for s in scenes})
            raise DatasetError(f"{bad[0]!r}: cannot read example(s) {scenes} of the "
                               f"{self.split} split (truncated or corrupt shard?): "
                               f"{_one_line(err)}") from None

    # ---------------------------------------------------------------- access
    def __len__(self) -> int:
        return len(self.scenes) * (self._frames or 1)

    def _locate(self, index) -> tuple[int, int | None]:
        n = len(self)
        i = int(index)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"index {index} out of range for {n} examples")
        return (i // self._frames, i % self._frames) if self._frames else (i, None)

    def decode(self, data: bytes) -> dict:
        """Serialised example → regular nested numpy dict of the task's features."""
        self._open()  # first: TFDS is imported under its lock
        from tensorflow_datasets.core import example_parser, utils
        from tensorflow_datasets.proto import tf_example_pb2

        specs, flat_specs, keys = self._parser
        proto = tf_example_pb2.Example.FromString(data)
        if len(keys) < len(self._features.keys()):  # parse only the task's features
            feature_map = proto.features.feature
            for key in [k for k in feature_map if k.split("/", 1)[0] not in keys]:
                del feature_map[key]
        parsed = utils.pack_as_nest_dict(
            example_parser._features_to_numpy(proto.features, flat_specs), specs)
        decoded = {k: self._features[k].decode_example_np(parsed[k]) for k in keys}
        flat = flatten(decoded)
        by_name = {f.name: f for f in self.schema.features}
        out = {}
        for name, value in flat.items():
            f = by_name.get(name)
            out[name] = _regular(f, value, self.dims) if f is not None else value
        if self.units == "physical":
            try:
                out = self.schema.physical(out)
            except SchemaError as err:
                raise DatasetError(f"{self.location!r}: {err}") from None
        return unflatten(out)

    def _scene_example(self, scene: int, record: bytes | None = None) -> dict:
        """The decoded example of scene ``scene``; per-frame tasks keep the last one, so reading
        a scene's frames in order decodes it once."""
        if self._last is not None and self._last[0] == scene:
            return self._last[1]
        example = self.decode(self._records([scene])[0] if record is None else record)
        if self._frames:
            self._last = (scene, example)
        return example

    def __getitem__(self, index):
        scene, frame = self._locate(index)
        return self.task(self._scene_example(scene), frame, self)

    def __getitems__(self, indices: Sequence[int]) -> list:
        located = [self._locate(i) for i in indices]
        scenes = sorted({s for s, _ in located})
        records = dict(zip(scenes, self._records(scenes), strict=True))
        examples = {s: self._scene_example(s, records[s]) for s in scenes}
        return [self.task(examples[s], frame, self) for s, frame in located]

    def __iter__(self):
        for i in range(len(self)):
            yield self[i]

    def __repr__(self) -> str:
        return (f"DataSource({self.location!r}, split={self.split!r}, "
                f"task={self.task.name!r}, len={len(self)})")


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300] or type(err).__name__


def load(dataset_dir, split: str = "train", task: str | None = None, units: str = "raw",
         **task_options) -> DataSource:
    """A :class:`DataSource` over ``split`` of a packed dataset; ``task`` (see
    :mod:`kubric.datasets.tasks`) picks the features and transforms each example; ``units``:
    ``"raw"`` (stored samples, upstream's layout) or ``"physical"`` (module doc)."""
    return DataSource(dataset_dir, split, task, units, **task_options)
