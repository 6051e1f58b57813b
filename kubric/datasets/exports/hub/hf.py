"""``kubric export hf``: a packed dataset (or scene folders) as a Hugging Face ``datasets``
folder — Parquet shards ``data/SPLIT-0000k-of-0000n.parquet`` (one row group per scene, written
by ``datasets``' own Parquet writer) and ``README.md``, the dataset card with the Hub's YAML
header (configs, splits, features, licence, citation). ``datasets.load_dataset(OUT)`` gives the
loader's examples (:func:`kubric.datasets.load`) with typed features:

=====================================  ==============================================
schema feature                         ``datasets`` feature
=====================================  ==============================================
``png`` uint8 with 3 or 4 channels     ``List(Image(), length=T)`` (the PNG bytes)
other fixed-shape arrays, rank 2–5      ``Array{2..5}D(shape, dtype)`` (depth, flow, ...)
rank 1 / scalars                       ``List(Value(dtype), length=n)`` / ``Value(dtype)``
a dimension that varies (``V``, ``P``)  ``List`` of the rest
``class_label``                        ``ClassLabel(names)``
``text``                               ``Value("string")`` (a list: ``List(Value("string"))``)
``instances/...``, ``events/...``       ``List(...)`` of the above, inside nested dicts
=====================================  ==============================================

The nesting is the loader's: ``row["instances"]["positions"]`` is (N, T, 3). Upload with
``huggingface-cli upload USER/NAME OUT --repo-type dataset`` (docs/hub.md).
"""

from __future__ import annotations

import numpy as np

from kubric.datasets.exports.hub import card as card_module
from kubric.datasets.exports.hub.common import (
    dataset_of,
    need,
    progress_bar,
    scene_examples,
    splits_of,
    writing,
)
from kubric.datasets.layout import read_info
from kubric.datasets.tfds_io import flatten, unflatten
from kubric.errors import UsageError
from kubric.io import png_io
from kubric.io.schema import Feature, Schema

#: README.md's citation of Kubric (the Hub card's ``citation`` section)
CITATION = """@inproceedings{greff2022kubric,
  title = {Kubric: A Scalable Dataset Generator},
  author = {Klaus Greff and Francois Belletti and Lucas Beyer and Carl Doersch and Yilun Du and
            Daniel Duckworth and David J. Fleet and Dan Gnanapragasam and Florian Golemo and
            Charles Herrmann and Thomas Kipf and Abhijit Kundu and Dmitry Lagun and Issam Laradji
            and Hsueh-Ti (Derek) Liu and Henning Meyer and Yishu Miao and Derek Nowrouzezahrai and
            Cengiz Oztireli and Etienne Pot and Noha Radwan and Daniel Rebain and Sara Sabour and
            Mehdi S. M. Sajjadi and Matan Sela and Vincent Sitzmann and Austin Stone and Deqing Sun
            and Suhani Vora and Ziyu Wang and Tianhao Wu and Kwang Moo Yi and Fangcheng Zhong and
            Andrea Tagliasacchi},
  booktitle = {IEEE Conference on Computer Vision and Pattern Recognition (CVPR)},
  year = {2022}
}"""
DATA_DIR = "data"


def _hd():
    return need("datasets")


def is_image(f: Feature) -> bool:
    """An RGB(A) frame stack, stored as images (the rest of the per-frame layers are arrays)."""
    return f.encoding == "png" and f.dtype == "uint8" and f.shape[-1] in (3, 4)


def _value_dtype(f: Feature) -> str:
    return "string" if f.dtype == "str" else f.dtype


def _leaf(f: Feature, dims: dict):
    """The ``datasets`` feature of one element of ``f`` (module doc's table)."""
    hd = _hd()
    if f.encoding == "class_label":
        return hd.ClassLabel(names=list(f.names))
    if is_image(f):
        return hd.List(hd.Image(), length=dims["T"])
    value = hd.Value(_value_dtype(f))
    shape = f.concrete_shape(dims)
    if f.dtype == "str":
        return hd.List(value) if shape else value
    if 2 <= len(shape) <= 5 and all(d is not None for d in shape):
        return getattr(hd, f"Array{len(shape)}D")(shape=shape, dtype=f.dtype)
    for d in reversed(shape):
        value = hd.List(value, length=-1 if d is None else d)
    return value


def hf_features(schema: Schema, dims: dict):
    """The ``datasets.Features`` of a schema's examples, nested as the loader's."""
    flat = {f.name: (_hd().List(_leaf(f, dims)) if f.sequence else _leaf(f, dims))
            for f in schema.features}
    return _hd().Features(unflatten(flat))


def hf_row(schema: Schema, example: dict) -> dict:
    """A loader example in the form ``datasets`` encodes: image stacks as PNG bytes per frame,
    everything else as it is."""
    flat = flatten(example)
    for f in schema.features:
        if is_image(f):
            flat[f.name] = [{"bytes": png_io.encode_png(np.ascontiguousarray(frame)),
                             "path": None} for frame in flat[f.name]]
    return unflatten(flat)


def shard_name(split: str, index: int, count: int) -> str:
    return f"{DATA_DIR}/{split}-{index:05d}-of-{count:05d}.parquet"


#: feature → the Hub task category a dataset with it serves
TASKS = {"segmentations": "image-segmentation", "depth": "depth-estimation",
         "instances/bboxes": "object-detection", "instances/keypoints_2d": "keypoint-detection"}


def task_categories(schema: Schema) -> list[str]:
    names = {f.name for f in schema.features}
    return [task for feature, task in TASKS.items() if feature in names]


def yaml_header(features, counts: dict[str, int], sizes: dict[str, int], license_id: str,
                pretty_name: str, tags: list[str], tasks: list[str]) -> str:
    """The Hub's YAML metadata block (between ``---`` lines) of README.md; ``sizes``: each
    split's bytes in Arrow (what ``datasets`` calls ``num_bytes``)."""
    import yaml
    header = {
        "license": license_id,
        "pretty_name": pretty_name,
        "task_categories": tasks,
        "tags": ["synthetic", "kubric", *tags],
        "size_categories": [_size_category(sum(counts.values()))],
        "configs": [{"config_name": "default", "data_files": [
            {"split": s, "path": f"{DATA_DIR}/{s}-*.parquet"} for s in counts]}],
        "dataset_info": {"features": features._to_yaml_list(),
                         "splits": [{"name": s, "num_bytes": sizes[s], "num_examples": n}
                                    for s, n in counts.items()],
                         "dataset_size": sum(sizes.values())},
    }
    return "---\n" + yaml.safe_dump(header, sort_keys=False, width=100) + "---\n"


def _size_category(n: int) -> str:
    for bound, name in ((1_000, "n<1K"), (10_000, "1K<n<10K"), (100_000, "10K<n<100K"),
                        (1_000_000, "100K<n<1M")):
        if n < bound:
            return name
    return "n>1M"


#: scenes per Parquet file by default: one row group per scene, and the writer keeps ~7–19 KB
#: of state per row group until its file closes (docs/hub.md's benchmark), so a shard of 100
#: bounds that at ~2 MB whatever the dataset's size; 100 MOVi scenes at 256² are a few hundred
#: MB, the file size the Hub's viewer and streaming readers handle well
SCENES_PER_SHARD = 100


def export_hf(source, out, splits: str = "train=0.9,validation=0.1",
              scenes_per_shard: int = SCENES_PER_SHARD, scenes=None, license_id: str | None = None,
              progress: bool = True) -> dict:
    """Write the Hugging Face folder ``out`` (module doc) from ``source``: a packed dataset, or a
    folder of scene directories (packed first with ``splits``). ``scenes`` (the scene folder of a
    packed dataset) feeds the card's licences and command; ``license_id`` overrides the licence
    the card derives from the assets. Returns {split: number of examples}."""
    if scenes_per_shard < 1:
        raise UsageError(f"--scenes-per-shard must be ≥ 1, got {scenes_per_shard}")
    ParquetWriter = _hd() and need("datasets.arrow_writer").ParquetWriter

    with writing(out) as work:
        dataset_dir, scene_folder = dataset_of(source, work, splits, progress)
        info = read_info(dataset_dir)
        schema = Schema.from_json(info["schema_json"])
        features = hf_features(schema, info["dims"])
        counts = splits_of(dataset_dir)
        (work / DATA_DIR).mkdir()
        stats = card_module.CardStats(schema, info["dims"])
        bar = progress_bar(sum(counts.values()), "hf", progress)
        sizes = dict.fromkeys(counts, 0)
        for split, count in counts.items():
            shards = -(-count // scenes_per_shard)
            writer = None
            for index, example in enumerate(scene_examples(dataset_dir, split)):
                if index % scenes_per_shard == 0:
                    if writer is not None:
                        sizes[split] += writer.finalize()[1]
                        writer.close()
                    path = work / shard_name(split, index // scenes_per_shard, shards)
                    writer = ParquetWriter(path=str(path), features=features)
                row = hf_row(schema, example)
                writer.write_batch({k: [v] for k, v in row.items()})
                stats.add(split, example)
                bar.update(1)
            sizes[split] += writer.finalize()[1]
            writer.close()
        bar.close()
        card = card_module.build_card(dataset_dir, scenes or scene_folder, work, stats)
        header = yaml_header(features, counts, sizes, license_id or card.license_id,
                             f"Kubric {info['name']}", [str(info["schema"])],
                             task_categories(schema))
        (work / "README.md").write_text(header + card.markdown(citation=CITATION))
    return counts


__all__ = ["CITATION", "export_hf", "hf_features", "hf_row", "is_image", "yaml_header"]
