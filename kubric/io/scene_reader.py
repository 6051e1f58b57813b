"""One scene directory → one example: a flat dict ``{feature name: numpy value}`` per schema.

Values are what the packed dataset stores (before serialisation): integer layers exactly as in
the scene's files (uint8 RGB and labels, the raw uint16 samples of flow / normal / object
coordinates PNGs), float (TIFF) layers declared uint16 quantised with their ``range:`` feature,
per-instance / per-event features stacked along N / K (ragged ``V`` features as lists), text as
``str`` and class labels as indices into the feature's ``names``. Any problem is a
:class:`SceneError` naming the scene and the feature.
"""

from __future__ import annotations

import functools
import pathlib
import zipfile
from collections.abc import Mapping

import numpy as np

from kubric.errors import InputError, KubricError
from kubric.io import encodings, json_io, layers, png_io
from kubric.io.scene_dir import EVENTS_FILE, METADATA_FILE, is_complete
from kubric.io.scene_dir import SUCCESS_FILE as SUCCESS
from kubric.io.schema import Feature, Schema, SchemaError, convert, layer_channels


class SceneError(KubricError, ValueError):
    """A scene directory that cannot become an example (corrupt or off-contract)."""


def lookup(tree, path: str, what: str):
    """``tree[a][b][0]`` for ``path`` ``"a.b.0"``; :class:`SchemaError` naming ``what`` when a
    step is missing."""
    value = tree
    for step in path.split("."):
        try:
            value = value[int(step)] if step.lstrip("-").isdigit() and not isinstance(
                value, Mapping) else value[step]
        except (KeyError, IndexError, TypeError):
            raise SchemaError(f"{what}: no field {path!r}") from None
    return value


def element_value(feature: Feature, element, what: str):
    """The value of instance / collision ``feature`` in one ``element`` (a dict of
    ``metadata.json["instances"]`` or ``events.json["collisions"]``): its field, or the
    feature's ``default`` where the element lacks the field and the feature has one."""
    try:
        return lookup(element, feature.source_arg, what)
    except SchemaError:
        if feature.default is None:
            raise
        return feature.default


#: float → uint16 over [lo, hi]: the one quantiser of layers (kubric.io.png_io.scale_to_uint16)
quantise = png_io.scale_to_uint16


def dequantise(q: np.ndarray, value_range) -> np.ndarray:
    """The inverse of :func:`quantise` (float32): ``q / 65535 · (max − min) + min`` with
    ``value_range`` = (min, max) — :func:`kubric.io.encodings.dequantise`, the decode of the
    scaled and quantised-depth layer kinds."""
    lo, hi = (float(v) for v in np.asarray(value_range).reshape(2))
    return encodings.dequantise(q, lo, hi)


def _cast(feature: Feature, value, dims: Mapping[str, int], what: str):
    """One element's value (an instance's, an event's, or the scene's) checked and cast."""
    if feature.dtype == "str":
        as_str = lambda v: v.decode("utf-8") if isinstance(v, bytes) else str(v)
        if feature.shape:
            if isinstance(value, str | bytes) or not isinstance(value, list | tuple):
                raise SchemaError(f"{what}: expected a list of strings, got {value!r}"[:300])
            return [as_str(v) for v in value]
        return as_str(value)
    try:
        value = feature.type.stored(feature, value, what)
    except ValueError as err:
        raise SchemaError(str(err)) from None
    arr = np.asarray(value)
    if arr.dtype == object:
        raise SchemaError(f"{what}: ragged value")
    target = feature.type.value_dtype(feature)
    if target.kind in "ui" and arr.size:
        if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
            raise SchemaError(f"{what}: NaN / inf in an integer feature")
        info = np.iinfo(target)
        if arr.min() < info.min or arr.max() > info.max:
            raise SchemaError(f"{what}: values [{arr.min()}, {arr.max()}] do not fit {target}")
    if arr.dtype.kind == "f" and target.kind in "ui" and arr.size:
        if not np.array_equal(arr, np.round(arr)):
            raise SchemaError(f"{what}: non-integer values for dtype {target}")
    arr = arr.astype(target)
    expected = feature.concrete_shape(dims)
    if arr.size == 0 and expected and expected[0] is None and None not in expected[1:]:
        arr = arr.reshape((0, *expected[1:]))  # e.g. no boxes: [] → (0, 4), as the loader gives
    if len(expected) != arr.ndim or any(e is not None and e != s
                                        for e, s in zip(expected, arr.shape, strict=False)):
        if not (arr.size == 0 and expected and expected[0] is None):
            raise SchemaError(f"{what}: shape {arr.shape} does not match {feature.shape} = "
                              f"{expected}")
    return arr[()] if arr.ndim == 0 else arr


class SceneReader:
    """Reads the features of ``schema`` from one scene directory (files read once, lazily)."""

    def __init__(self, scene_dir, schema: Schema):
        self.scene_dir = pathlib.Path(scene_dir)
        self.schema = schema
        self._layers: dict[str, np.ndarray] = {}

    def _json(self, name: str):
        path = self.scene_dir / name
        if not path.is_file():
            raise SceneError(f"{str(self.scene_dir)!r}: missing {name}")
        return json_io.read_json(path)

    @functools.cached_property
    def metadata(self) -> dict:
        return self._json(METADATA_FILE)

    @functools.cached_property
    def events(self) -> dict:
        path = self.scene_dir / EVENTS_FILE
        return json_io.read_json(path) if path.is_file() else {"collisions": []}

    @functools.cached_property
    def data_ranges(self) -> dict:
        path = self.scene_dir / layers.DATA_RANGES_FILE
        return json_io.read_json(path) if path.is_file() else {}

    @functools.cached_property
    def dims(self) -> dict[str, int]:
        meta = self.metadata.get("metadata", {})
        try:
            width, height = (int(v) for v in meta["resolution"])
            frames = int(meta["num_frames"])
        except (KeyError, TypeError, ValueError):
            raise SceneError(f"{str(self.scene_dir)!r}: metadata.json lacks metadata.resolution "
                             "/ metadata.num_frames") from None
        return {"T": frames, "H": height, "W": width}

    def layer(self, name: str) -> np.ndarray:
        """A layer's stored samples (raw), checked against T, H, W (read once)."""
        if name in self._layers:
            return self._layers[name]
        try:
            arr = layers.read_layer(self.scene_dir, name, formats=self.schema.layers, raw=True)
        except (OSError, ValueError) as err:
            raise SceneError(f"{str(self.scene_dir)!r}: layer {name!r}: {err}") from None
        dims = self.dims
        if arr.shape[:3] != (dims["T"], dims["H"], dims["W"]):
            raise SceneError(f"{str(self.scene_dir)!r}: layer {name!r} has (T, H, W) "
                             f"{arr.shape[:3]}, metadata says {(dims['T'], dims['H'], dims['W'])}")
        self._layers[name] = arr
        return arr

    def layer_range(self, name: str) -> np.ndarray:
        """[min, max] of a layer as its kind packs it: ``data_ranges.json`` for scaled layers,
        the finite samples otherwise (the range its uint16 quantisation uses)."""
        try:
            return self.schema.layer_formats[name].type.value_range(
                lambda: self.layer(name), self.data_ranges.get(name),
                f"{str(self.scene_dir)!r}: layer {name!r}")
        except InputError as err:
            raise SceneError(str(err)) from None

    def _layer_feature(self, f: Feature) -> np.ndarray:
        name, channels = layer_channels(f.source_arg, f.name)
        kind = self.schema.layer_formats[name].type
        try:
            arr = kind.packed(self.layer(name)[..., channels], np.dtype(f.dtype),
                              lambda: self.layer_range(name),
                              f"{str(self.scene_dir)!r}: layer {name!r} (feature {f.name!r})")
        except InputError as err:
            raise SceneError(str(err)) from None
        return _cast(f, arr, self.dims, f"{str(self.scene_dir)!r} feature {f.name!r}")

    def _elements(self, kind: str) -> list:
        if kind == "instance":
            return list(self.metadata.get("instances", []))
        return list(self.events.get("collisions", []))

    @staticmethod
    def _converted(f: Feature, value, what: str):
        try:
            return convert(f.convert, value)
        except (ValueError, TypeError, KeyError) as err:
            raise SchemaError(f"{what}: {f.convert}: {err}") from None

    def raw_values(self, f: Feature) -> list:
        """The values of a ``meta`` / ``camera`` / ``instance`` / ``collision`` feature as the
        JSON holds them, before any cast (one per element for a sequence feature): what the
        packer collects class-label names from."""
        what = f"{str(self.scene_dir)!r} feature {f.name!r}"
        kind, arg = f.source_kind, f.source_arg
        if kind in ("meta", "camera"):
            tree = self.metadata.get("metadata" if kind == "meta" else "camera", {})
            return [lookup(tree, arg, what)]
        if kind in ("instance", "collision"):
            return [element_value(f, el, f"{what} [{i}]")
                    for i, el in enumerate(self._elements(kind))]
        raise SchemaError(f"{what}: names are collected from metadata sources only, not "
                          f"{f.source!r}")

    def feature(self, f: Feature):
        what = f"{str(self.scene_dir)!r} feature {f.name!r}"
        kind, arg = f.source_kind, f.source_arg
        if kind == "scene_name":
            return self.scene_dir.name
        if kind == "layer":
            return self._layer_feature(f)
        if kind == "range":
            return self.layer_range(arg)
        if kind == "npz":
            file, _, key = arg.partition(":")
            path = self.scene_dir / file
            try:
                if path.suffix == ".h5":  # an HDF5 file's dataset KEY (events.h5)
                    import h5py
                    with h5py.File(path, "r") as h5:
                        value = np.asarray(h5[key][()])
                else:
                    with np.load(path, allow_pickle=False) as archive:
                        value = archive[key]
            except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as err:
                raise SceneError(f"{what}: cannot read {key!r} from {file}: {err}") from None
            return _cast(f, value, self.dims, what)
        if kind in ("meta", "camera"):
            tree = self.metadata.get("metadata" if kind == "meta" else "camera", {})
            value = self._converted(f, lookup(tree, arg, what), what)
            return _cast(f, value, self.dims, what)
        values = [_cast(f, self._converted(f, element_value(f, el, f"{what} [{i}]"),
                                           f"{what} [{i}]"),
                        self.dims, f"{what} [{i}]") for i, el in enumerate(self._elements(kind))]
        if f.dtype == "str" or (f.shape and f.shape[0] == "V"):
            return values
        if not values:
            shape = tuple(d if isinstance(d, int) else self.dims.get(d, 0) for d in f.shape)
            return np.zeros((0, *shape), dtype=f.type.value_dtype(f))
        return np.stack(values)

    def _read(self, f: Feature):
        """:meth:`feature`, with a schema error about this scene raised as a SceneError."""
        try:
            return self.feature(f)
        except SchemaError as err:
            raise SceneError(str(err)) from None

    def example(self, names=None) -> dict:
        """``{feature name: value}`` for ``names`` (default: every feature of the schema)."""
        return {f.name: self._read(f) for f in self.schema.features
                if names is None or f.name in names}

    def check_each(self) -> None:
        """Read every feature once, as :meth:`example` does, but keep a layer's samples only
        until its last feature is read (the write-time check: one layer in memory at a time,
        not the whole scene a second time)."""
        last_use: dict[str, int] = {}  # layer name → index of the last feature that reads it
        for i, f in enumerate(self.schema.features):
            if f.source_kind == "layer":
                last_use[layer_channels(f.source_arg, f.name)[0]] = i
            elif f.source_kind == "range":
                last_use[f.source_arg] = i
        drop_after: dict[int, list[str]] = {}
        for name, i in last_use.items():
            drop_after.setdefault(i, []).append(name)
        for i, f in enumerate(self.schema.features):
            self._read(f)
            for name in drop_after.get(i, ()):
                self._layers.pop(name, None)


def read_scene_example(scene_dir, schema: Schema, names=None) -> dict:
    """The example of one complete scene directory (see module doc)."""
    if not is_complete(scene_dir):
        raise SceneError(f"{str(scene_dir)!r} is incomplete (no {SUCCESS})")
    return SceneReader(scene_dir, schema).example(names)


__all__ = ["SceneError", "SceneReader", "dequantise", "element_value", "is_complete", "lookup",
           "quantise", "read_scene_example"]
