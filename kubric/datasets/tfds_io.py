"""A schema as TFDS features; examples to TFDS's serialised form and back, without TensorFlow.

The wire format is TFDS's own (a ``tf.train.Example`` proto per example, built from the
``FeatureConnector`` s' encodings), so ``tfds.builder_from_directory(dir)`` reads our datasets.
TFDS 4.9.10's serialiser needs TensorFlow for sequences nested in sequences (``instances/bboxes``)
only to name a dtype; :func:`serialize` builds the same proto fields (``ragged_flat_values`` /
``ragged_row_lengths_0``) from numpy. Per-frame image features are PNG-encoded here (TFDS would
call ``tf.image.encode_png``); TFDS decodes them with OpenCV.

Feature mapping (each encoding's class in :mod:`kubric.io.encodings` makes its connector and its
serialisable value): ``png`` → ``Sequence(Image((H, W, C), dtype, "png"), length=T)``; ``zlib`` →
``Sequence(Tensor((H, W, C), dtype, encoding=zlib), length=T)``; ``text`` → ``Text``;
``class_label`` → ``ClassLabel(names)``; a list of text (shape ``("C",)``) →
``Sequence(Text())``; ``bbox`` → ``Sequence(BBoxFeature())``; a leading ``V``
→ ``Sequence(Tensor(rest))``; anything else → ``Tensor(shape, dtype)``. ``instances/...`` and
``events/collisions/...`` features become one ``Sequence(FeaturesDict)`` each.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from kubric.io.encodings import FEATURE_ENCODINGS
from kubric.io.schema import SEQUENCES, Feature, Schema


def _tfds():
    import tensorflow_datasets as tfds
    return tfds


def _leaf(f: Feature, dims: Mapping[str, int]):
    """The TFDS connector of one feature: its encoding's (:mod:`kubric.io.encodings`)."""
    dtype = np.bool_ if f.dtype == "bool" else np.dtype(f.dtype) if f.dtype != "str" else None
    return f.type.connector(_tfds(), f, f.concrete_shape(dims), dtype)


def _split_name(f: Feature) -> tuple[tuple[str, ...], str | None]:
    """(path of dict keys, sequence group) of a feature name."""
    seq = f.sequence
    if seq:
        return tuple(seq.rstrip("/").split("/")) + (f.name[len(seq):],), seq
    return tuple(f.name.split("/")), None


def nested_spec(schema: Schema, dims: Mapping[str, int]) -> dict:
    """The nested dict of TFDS feature connectors (sequence groups as plain dicts)."""
    root: dict = {}
    for f in schema.features:
        path, _ = _split_name(f)
        node = root
        for key in path[:-1]:
            node = node.setdefault(key, {})
        node[path[-1]] = _leaf(f, dims)
    return root


def tfds_features(schema: Schema, dims: Mapping[str, int]):
    """The ``tfds.features.FeaturesDict`` of ``schema`` at frame count / resolution ``dims``."""
    tfds = _tfds()
    spec = nested_spec(schema, dims)
    for seq in SEQUENCES:
        keys = seq.rstrip("/").split("/")
        node = spec
        for key in keys[:-1]:
            node = node.get(key, {})
        if keys[-1] in node:
            node[keys[-1]] = tfds.features.Sequence(tfds.features.FeaturesDict(node[keys[-1]]))
    return tfds.features.FeaturesDict(spec)


def encode_frames(frames: np.ndarray) -> list[bytes]:
    """(T, H, W, C) uint8 / uint16 → one PNG per frame (the ``png`` encoding's)."""
    return FEATURE_ENCODINGS["png"].serialisable(None, None, frames)


def nested_example(schema: Schema, flat: Mapping) -> dict:
    """A flat example (:mod:`kubric.io.scene_reader`) → the nested dict TFDS encodes
    (sequence groups as lists of per-element dicts)."""
    tfds = _tfds()
    root: dict = {}
    groups: dict[str, dict[str, list]] = {}
    for f in schema.features:
        value = f.type.serialisable(tfds, f, flat[f.name])
        if f.sequence:
            groups.setdefault(f.sequence, {})[f.name[len(f.sequence):]] = list(value)
            continue
        node = root
        *parents, leaf = f.name.split("/")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = value
    for seq, columns in groups.items():
        lengths = {len(v) for v in columns.values()}
        if len(lengths) > 1:
            raise ValueError(f"{seq}: features disagree on the number of elements {lengths}")
        count = lengths.pop() if lengths else 0
        node = root
        *parents, leaf = seq.rstrip("/").split("/")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = [{k: v[i] for k, v in columns.items()} for i in range(count)]
    return root


def serialize(features, example: Mapping) -> bytes:
    """TFDS's serialised ``tf.train.Example`` bytes of a nested example, with numpy only."""
    from tensorflow_datasets.core import example_serializer as es
    from tensorflow_datasets.core import utils
    from tensorflow_datasets.core.features.feature import TensorInfo
    from tensorflow_datasets.proto import tf_example_pb2, tf_feature_pb2

    encoded = utils.flatten_nest_dict(features.encode_example(example))
    out = {}
    for key, info in utils.flatten_nest_dict(features.get_serialized_info()).items():
        value = encoded[key]
        if info.sequence_rank:  # as TFDS: stack the (nested) sequence's items
            value, row_lengths = es._extract_ragged_attributes(value, info)
        if info.sequence_rank >= 2:
            flat = value
            for i, lengths in enumerate(row_lengths):
                out[f"{key}/ragged_row_lengths_{i}"] = es._item_to_tf_feature(
                    lengths, TensorInfo(shape=(None,), dtype=np.int64))
            flat_info = TensorInfo(shape=(None, *info.shape[info.sequence_rank:]),
                                   dtype=info.np_dtype)
            out[f"{key}/ragged_flat_values"] = es._item_to_tf_feature(flat, flat_info)
        else:
            out[key] = es._item_to_tf_feature(value, info)
    proto = tf_example_pb2.Example(features=tf_feature_pb2.Features(feature=out))
    return proto.SerializeToString(deterministic=True)  # map keys sorted: same bytes every run


def flatten(nested: Mapping, prefix: str = "") -> dict:
    """``{"a": {"b": v}}`` → ``{"a/b": v}``."""
    out = {}
    for key, value in nested.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, name + "/"))
        else:
            out[name] = value
    return out


def unflatten(flat: Mapping) -> dict:
    """``{"a/b": v}`` → ``{"a": {"b": v}}``."""
    root: dict = {}
    for name, value in flat.items():
        node = root
        *parents, leaf = name.split("/")
        for key in parents:
            node = node.setdefault(key, {})
        node[leaf] = value
    return root
