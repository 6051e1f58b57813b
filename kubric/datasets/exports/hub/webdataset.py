"""``kubric export webdataset``: a packed dataset (or scene folders) as WebDataset tar shards,
``OUT/SPLIT-00000k.tar``, that the ``webdataset`` library streams (local paths, or any fsspec
URL once :func:`register_fsspec` is called) into a PyTorch pipeline with shuffling across
shards; ``OUT/shards.json`` names each split's shards, their brace pattern and sample counts,
``OUT/README.md`` is the dataset card.

A sample (``__key__`` the scene name; per frame: ``SCENE_fFFFFF``) holds the loader's example
(:func:`kubric.datasets.load`), each feature under its name lower-cased (``webdataset``
lower-cases file suffixes) with ``/`` → ``.`` (``camera/K`` → ``camera.k.npy``;
``shards.json``'s ``files`` maps every suffix back to its feature):

* every fixed-shape array feature: ``NAME.npy`` (its dtype and shape);
* per frame (``per_frame=True``): the per-frame features (shape ``(T, ...)``) hold frame ``f``
  alone, the RGB(A) image as ``NAME.png``;
* everything else (text, scalars, ragged per-instance lists such as ``instances/bboxes``):
  ``json``, one object {feature name: value} (floats are float32 values written exactly).

``webdataset.WebDataset(pattern).decode("rgb8")`` gives numpy arrays for ``.npy`` and ``.png``
and a dict for ``.json``.
"""

from __future__ import annotations

import io
import json

import numpy as np

from kubric.datasets.exports.hub import card as card_module
from kubric.datasets.exports.hub import common
from kubric.datasets.exports.hub.hf import is_image
from kubric.datasets.exports.scenes import ExportError
from kubric.datasets.layout import read_info
from kubric.datasets.tfds_io import flatten
from kubric.errors import UsageError
from kubric.io import png_io
from kubric.io.schema import Feature, Schema

INDEX_FILE = "shards.json"


def _npy(value: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(value), allow_pickle=False)
    return buffer.getvalue()


def _plain(value):
    """A JSON-able form of a feature value (lists of arrays, numpy scalars)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def is_array(f: Feature, value) -> bool:
    """Stored as ``.npy``: a numpy array whose shape is fixed or whose only varying dimension
    is the sequence's (not a list of ragged arrays, not text)."""
    return isinstance(value, np.ndarray) and value.dtype != object and f.dtype != "str"


def suffix(name: str) -> str:
    """The sample file suffix (without its extension) of feature ``name``."""
    return name.replace("/", ".").lower()


def check_names(schema: Schema) -> None:
    """Two features whose suffixes would clash (names that differ only by case)."""
    seen: dict[str, str] = {}
    for f in schema.features:
        other = seen.setdefault(suffix(f.name), f.name)
        if other != f.name:
            raise ExportError(f"features {other!r} and {f.name!r} would share the WebDataset "
                              f"file {suffix(f.name)!r} (webdataset lower-cases names)")


def is_per_frame(f: Feature) -> bool:
    return not f.sequence and f.shape[:1] == ("T",)


def samples(schema: Schema, example: dict, per_frame: bool = False):
    """The tar samples of one loader example (module doc): one, or one per frame."""
    flat = flatten(example)
    scene = str(flat["metadata/video_name"])
    frames = [None]
    if per_frame:
        per = [f for f in schema.features if is_per_frame(f)]
        frames = range(len(flat[per[0].name])) if per else [None]
    for frame in frames:
        sample = {"__key__": scene if frame is None else f"{scene}_f{frame:06d}"}
        rest = {} if frame is None else {"frame": int(frame)}
        for f in schema.features:
            value = flat[f.name]
            if frame is not None and is_per_frame(f):
                value = value[frame]
                if is_image(f):
                    sample[f"{suffix(f.name)}.png"] = png_io.encode_png(
                        np.ascontiguousarray(value))
                    continue
            if is_array(f, value):
                sample[f"{suffix(f.name)}.npy"] = _npy(value)
            else:
                rest[f.name] = _plain(value)
        sample["json"] = json.dumps(rest, sort_keys=True).encode()
        yield sample


def shard_file(split: str, index: int) -> str:
    return f"{split}-{index:06d}.tar"


def export_webdataset(source, out, splits: str = "train=0.9,validation=0.1",
                      samples_per_shard: int = 1000, per_frame: bool = False, scenes=None,
                      progress: bool = True) -> dict:
    """Write the WebDataset folder ``out`` (module doc) from ``source``: a packed dataset, or a
    folder of scene directories (packed first with ``splits``). Returns :data:`INDEX_FILE`'s
    content: {"splits": {split: {"shards": [...], "pattern": ..., "samples": n, "scenes": n}},
    "files": {suffix: feature name}}."""
    if samples_per_shard < 1:
        raise UsageError(f"--samples-per-shard must be ≥ 1, got {samples_per_shard}")
    webdataset = common.need("webdataset")
    index: dict = {}
    with common.writing(out) as work:
        dataset_dir, scene_folder = common.dataset_of(source, work, splits, progress)
        info = read_info(dataset_dir)
        schema = Schema.from_json(info["schema_json"])
        check_names(schema)
        stats = card_module.CardStats(schema, info["dims"])
        counts = common.splits_of(dataset_dir)
        bar = common.progress_bar(sum(counts.values()), "webdataset", progress)
        for split, count in counts.items():
            shards, written, writer = [], 0, None
            for example in common.scene_examples(dataset_dir, split):
                for sample in samples(schema, example, per_frame):
                    if written % samples_per_shard == 0:
                        if writer is not None:
                            writer.close()
                        shards.append(shard_file(split, len(shards)))
                        writer = webdataset.TarWriter(str(work / shards[-1]))
                    writer.write(sample)
                    written += 1
                stats.add(split, example)
                bar.update(1)
            writer.close()
            last = f"{len(shards) - 1:06d}"
            index.setdefault("splits", {})[split] = {"shards": shards, "samples": written, "scenes": count,
                            "pattern": f"{split}-{{000000..{last}}}.tar"}
        bar.close()
        index["files"] = {suffix(f.name): f.name for f in schema.features}
        (work / INDEX_FILE).write_text(json.dumps(index, indent=1) + "\n")
        card = card_module.build_card(dataset_dir, scenes or scene_folder, work, stats)
        (work / "README.md").write_text(card.markdown())
    return index


def register_fsspec(*schemes: str) -> None:
    """Let ``webdataset`` open ``SCHEME://...`` shard URLs through fsspec (``s3``, ``gs``,
    ``memory``, ...): it opens only local files, pipes and HTTP itself."""
    import importlib

    import fsspec
    gopen = importlib.import_module("webdataset.gopen")  # `webdataset.gopen` is also a function

    def opener(url, mode="rb", bufsize=8192):
        return fsspec.open(url, mode).open()

    for scheme in schemes:
        gopen.gopen_schemes[scheme] = opener


__all__ = ["INDEX_FILE", "export_webdataset", "register_fsspec", "samples"]
