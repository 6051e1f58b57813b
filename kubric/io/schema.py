"""The output contract of a recipe, declared once: its layers and the features of its examples.

A :class:`Schema` names

* ``layers``: the per-frame image layers the recipe writes into a scene directory beyond the
  standard table :data:`kubric.io.layers.LAYERS` (file template, channels, encoding), and
* ``features``: every field of one packed example, each a :class:`Feature` with its dtype, its
  shape in named dimensions, its encoding in the packed dataset, its unit, a one-line doc and
  ``source``: where the value lives in a scene directory.

The scene-directory writer (:func:`write_scene`), the scene reader and the packer
(:mod:`kubric.datasets`), the loaders and ``kubric inspect`` all read the schema, so adding a
layer or a metadata field to a recipe is one edit of its schema. :func:`schema_markdown` renders
a schema as the Markdown table of the generated docs.

Dimensions: ``T`` frames (the views of a multi-view scene), ``H`` × ``W`` pixels, ``N``
instances, ``K`` collision events, ``V`` the frames in which one instance is visible (varies per
instance), ``P`` points (point tracks), ``C`` classes, ``B`` bands, ``R`` the cameras of a rig. Features named
``instances/...`` hold one value per instance (their shape omits ``N``), ``events/collisions/...``
one per event (shape omits ``K``).

Sources (``source`` strings):

=====================  =====================================================================
``scene_name``         the scene directory's name
``layer:NAME``         layer NAME as stored (uint8 images, labels, raw uint16 PNG samples,
                       float32 TIFF samples); a float (TIFF) layer stored as a feature of dtype
                       uint16 is quantised with the range of ``range:NAME``;
                       ``layer:NAME[:3]`` keeps channels 0–2, ``layer:NAME[3:4]`` channel 3
``range:NAME``         [min, max] of layer NAME (``data_ranges.json``; for a float layer
                       quantised to uint16: min and max of its finite samples)
``meta:PATH``          ``metadata.json["metadata"][PATH]``; PATH is dotted (``resolution.0``)
``camera:PATH``        ``metadata.json["camera"][PATH]``
``instance:PATH``      ``metadata.json["instances"][n][PATH]`` for every instance n
``collision:PATH``     ``events.json["collisions"][k][PATH]`` for every event k
``npz:FILE:KEY``       array KEY of the numpy archive FILE in the scene directory (a FILE
                       ending in ``.h5``: its HDF5 dataset KEY, e.g. ``events/x``)
=====================  =====================================================================

``convert`` names a conversion applied after reading (:data:`CONVERSIONS`).

``default`` (instance and collision sources only; a scalar of the feature's dtype) is the value
of an element that lacks the field: fields a recipe writes for some instances only, e.g. the
URDF link name of the parts of an articulated object (``vbr``'s ``instances/articulated_link``:
``""`` for the base and for a rigid object). Without a default a missing field is an error.

Text features (dtype ``str``) are one string, or with shape ``("C",)`` (any one named
dimension) a list of strings. A class label whose ``names`` are :data:`NAMES_FROM_SCENES` gets
its names when packing: the sorted distinct values of its source over the packed scenes (e.g.
the object categories of an asset collection, which no schema can know in advance); the packed
dataset stores the resolved names.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Iterable, Mapping

import numpy as np

from kubric.errors import KubricError
from kubric.io.encodings import FEATURE_ENCODINGS, LayerKind
from kubric.io.layers import LAYERS, LayerFormat, layer_table

#: named dimensions and what they count
DIMS = {"T": "frames", "H": "image height (pixels)", "W": "image width (pixels)",
        "N": "instances", "K": "collision events", "V": "frames in which the instance is visible",
        "P": "points (e.g. point tracks)", "C": "classes (e.g. semantic classes)",
        "B": "bands (e.g. texture frequency bands)",
        "R": "cameras of a rig (the reference camera first)"}
#: feature name prefixes that hold one value per element of a sequence, and its dimension
SEQUENCES = {"instances/": "N", "events/collisions/": "K"}
#: feature encodings by name (the classes of :mod:`kubric.io.encodings`)
ENCODINGS = FEATURE_ENCODINGS
DTYPES = ("uint8", "uint16", "int32", "int64", "float32", "bool", "str")
SOURCE_KINDS = ("scene_name", "layer", "range", "meta", "camera", "instance", "collision", "npz")
#: the splits of a multi-view scene's views (NeRF's transforms_{split}.json), in index order
VIEW_SPLITS = ("train", "val", "test")
UINT16_MAX = 65535


def _hex_to_rgb(value) -> np.ndarray:
    text = str(value)
    digits = text[1:] if text.startswith("#") else ""
    if len(digits) not in (6, 8) or any(c not in "0123456789abcdefABCDEF" for c in digits):
        raise ValueError(f"{value!r} is not a '#rrggbb' or '#rrggbbaa' colour")
    return np.array([int(digits[i:i + 2], 16) / 255.0 for i in (0, 2, 4)], dtype=np.float32)


def _split_indices(value) -> np.ndarray:
    names = [v["split"] if isinstance(v, Mapping) else v for v in value]
    unknown = sorted({str(n) for n in names} - set(VIEW_SPLITS))
    if unknown:
        raise ValueError(f"splits {unknown} are not in {VIEW_SPLITS}")
    return np.array([VIEW_SPLITS.index(n) for n in names], dtype=np.int64)


def _negative_to_uint16_max(value) -> np.ndarray:
    arr = np.asarray(value, dtype=np.int64)
    return np.where(arr < 0, UINT16_MAX, arr)


@dataclasses.dataclass(frozen=True)
class Conversion:
    """A conversion a feature may name in ``convert``: what it does (for the docs) and the
    function the reader applies to the value read from the scene directory."""

    doc: str
    apply: Callable


#: conversions a feature may name in ``convert``
CONVERSIONS: dict[str, Conversion] = {
    "hex_to_rgb": Conversion("colour hex string '#rrggbb' (or '#rrggbbaa', as kb.Color.hexstr "
                             "writes it: alpha dropped) → float32 (3,) in [0, 1]", _hex_to_rgb),
    "floor": Conversion("number → its floor (e.g. a fractional collision frame → the frame it "
                        "falls in)",
                        lambda v: np.floor(np.asarray(v, dtype=np.float64)).astype(np.int64)),
    "negative_to_uint16_max": Conversion("−1 (no instance) → 65535, as upstream's uint16 "
                                         "instance indices", _negative_to_uint16_max),
    "split_index": Conversion("per-view split names (a list of {'split': name} or of names) → "
                              "their indices in (train, val, test)", _split_indices),
}


def convert(name: str, value):
    """``value`` after conversion ``name`` (the empty name: unchanged)."""
    return CONVERSIONS[name].apply(value) if name else value


#: ``names`` of a class label whose names are collected from the scenes when packing
NAMES_FROM_SCENES = ("<sorted values found when packing>",)
#: version of the schema contract (bumped when a feature changes meaning, never for additions)
SCHEMA_VERSION = "1.0.0"


class SchemaError(KubricError, ValueError):
    """A schema, or a value checked against it, breaks the contract (one-line message)."""


@dataclasses.dataclass(frozen=True)
class Feature:
    """One field of a packed example (see the module doc for names, dims and sources)."""

    name: str
    dtype: str
    shape: tuple = ()
    source: str = ""
    encoding: str = "none"
    unit: str = ""
    doc: str = ""
    names: tuple[str, ...] = ()      # class-label names (encoding "class_label")
    convert: str = ""
    default: str | int | float | bool | None = None   # value where an element lacks the field

    def __post_init__(self):
        what = f"feature {self.name!r}"
        if self.dtype not in DTYPES:
            raise SchemaError(f"{what}: dtype {self.dtype!r} is not one of {DTYPES}")
        if self.encoding not in ENCODINGS:
            raise SchemaError(f"{what}: encoding {self.encoding!r} is not one of "
                              f"{tuple(ENCODINGS)}")
        for dim in self.shape:
            if not (isinstance(dim, int) and dim > 0) and dim not in DIMS:
                raise SchemaError(f"{what}: shape entry {dim!r} must be a positive int or one of "
                                  f"{sorted(DIMS)}")
        kind = self.source.split(":", 1)[0]
        if kind not in SOURCE_KINDS:
            raise SchemaError(f"{what}: source {self.source!r} must start with one of "
                              f"{SOURCE_KINDS}")
        if self.convert and self.convert not in CONVERSIONS:
            raise SchemaError(f"{what}: convert {self.convert!r} is not one of "
                              f"{sorted(CONVERSIONS)}")
        try:
            self.type.check(self, what)
        except ValueError as err:
            raise SchemaError(str(err)) from None
        if self.dtype == "str" and (len(self.shape) > 1 or self.shape[:1] not in
                                    ((), *((d,) for d in DIMS))):
            raise SchemaError(f"{what}: text features have shape () or one named dimension")
        if self.source_kind == "layer":
            layer_channels(self.source_arg, what)
        if self.default is not None:
            self._check_default(what)

    def _check_default(self, what: str) -> None:
        if self.source_kind not in ("instance", "collision") or self.shape or self.names:
            raise SchemaError(f"{what}: a default is allowed for scalar instance / collision "
                              f"features only (source {self.source!r}, shape {self.shape})")
        value = self.default
        number = isinstance(value, int | float) and not isinstance(value, bool)
        fits = {"str": isinstance(value, str), "bool": isinstance(value, bool),
                "float32": number}.get(self.dtype, number and isinstance(value, int))
        if not fits:
            raise SchemaError(f"{what}: default {value!r} is not a value of dtype {self.dtype}")

    @property
    def type(self):
        """The :class:`~kubric.io.encodings.FeatureEncoding` of :attr:`encoding`."""
        return ENCODINGS[self.encoding]

    @property
    def sequence(self) -> str | None:
        """The sequence prefix (``instances/``, ``events/collisions/``) this feature is in."""
        return next((p for p in SEQUENCES if self.name.startswith(p)), None)

    @property
    def source_kind(self) -> str:
        return self.source.split(":", 1)[0]

    @property
    def source_arg(self) -> str:
        return self.source.split(":", 1)[1] if ":" in self.source else ""

    @property
    def names_from_scenes(self) -> bool:
        """Its class-label names are collected when packing (:data:`NAMES_FROM_SCENES`)."""
        return tuple(self.names) == NAMES_FROM_SCENES

    def full_shape(self) -> tuple:
        """The shape with the sequence dimension in front (``instances/mass`` → ("N",))."""
        seq = self.sequence
        return ((SEQUENCES[seq],) if seq else ()) + tuple(self.shape)

    def concrete_shape(self, dims: Mapping[str, int]) -> tuple:
        """``shape`` with T / H / W replaced by ``dims``; N, K, V, P stay None (they vary)."""
        return tuple(d if isinstance(d, int) else dims.get(d) for d in self.shape)


@dataclasses.dataclass(frozen=True)
class Schema:
    """A recipe's output contract: its extra layers and its example features."""

    name: str
    features: tuple[Feature, ...]
    layers: Mapping[str, LayerFormat] = dataclasses.field(default_factory=dict)
    description: str = ""
    version: str = SCHEMA_VERSION

    def __post_init__(self):
        names = [f.name for f in self.features]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise SchemaError(f"schema {self.name!r}: features {dup} are declared twice")
        table = layer_table(self.layers)
        for f in self.features:
            if f.source_kind in ("layer", "range"):
                layer = f.source_arg.split("[", 1)[0]
                if layer not in table:
                    raise SchemaError(f"schema {self.name!r}: feature {f.name!r} reads layer "
                                      f"{layer!r}, which is neither standard nor declared")

    def __getitem__(self, name: str) -> Feature:
        for f in self.features:
            if f.name == name:
                return f
        raise KeyError(f"schema {self.name!r} has no feature {name!r}")

    def __contains__(self, name) -> bool:
        return any(f.name == name for f in self.features)

    @property
    def names(self) -> list[str]:
        return [f.name for f in self.features]

    @property
    def layer_formats(self) -> dict[str, LayerFormat]:
        """Every layer this schema may read: the standard table plus its own."""
        return layer_table(self.layers)

    def layer_kind(self, feature: Feature | str) -> tuple[str, LayerKind] | None:
        """(layer name, its :class:`~kubric.io.encodings.LayerKind`) of a ``layer:`` feature;
        None for a feature of another source."""
        f = self[feature] if isinstance(feature, str) else feature
        if f.source_kind != "layer":
            return None
        layer = layer_channels(f.source_arg, f.name)[0]
        return layer, self.layer_formats[layer].type

    def range_feature(self, layer: str) -> str | None:
        """The name of the feature holding layer ``layer``'s [min, max] (source
        ``range:LAYER``), or None."""
        return next((f.name for f in self.features
                     if f.source_kind == "range" and f.source_arg == layer), None)

    def physical(self, flat: Mapping) -> dict:
        """``flat`` (feature name → packed value) with every ``layer:`` feature decoded by its
        layer kind to physical units, float32 (flow in pixels, depth in metres, normals as unit
        vectors, object coordinates and UV in [0, 1]; colour and labels unchanged). Quantised
        samples use the per-scene range of the layer's ``range:`` feature in ``flat``."""
        out = dict(flat)
        for f in self.features:
            source = self.layer_kind(f) if f.name in flat else None
            if source is None:
                continue
            layer, kind = source
            value = np.asarray(flat[f.name])
            value_range = None
            if kind.needs_range(value.dtype):
                name = self.range_feature(layer)
                if name is None or name not in flat:
                    raise SchemaError(f"feature {f.name!r}: decoding layer {layer!r} needs its "
                                      f"range, a feature with source 'range:{layer}'"
                                      + (f" ({name!r} was not read)" if name else
                                         f" (schema {self.name!r} has none)"))
                value_range = flat[name]
            out[f.name] = kind.decode(value, value_range, f"feature {f.name!r}")
        return out

    def image_layers(self) -> list[str]:
        """The scene-directory layers its features read."""
        out = []
        for f in self.features:
            if f.source_kind == "layer":
                layer = f.source_arg.split("[", 1)[0]
                if layer not in out:
                    out.append(layer)
        return out

    def extend(self, name: str, features: Iterable[Feature] = (),
               layers: Mapping[str, LayerFormat] | None = None, description: str = "",
               drop: Iterable[str] = ()) -> Schema:
        """A new schema: this one's features (less ``drop``) plus ``features`` and ``layers``."""
        drop = set(drop)
        missing = sorted(drop - set(self.names))
        if missing:
            raise SchemaError(f"schema {self.name!r}: cannot drop unknown features {missing}")
        return Schema(name, tuple(f for f in self.features if f.name not in drop)
                      + tuple(features), {**self.layers, **dict(layers or {})},
                      description or self.description, self.version)

    def to_json(self) -> dict:
        """The schema as a JSON document (what a packed dataset stores beside its shards)."""
        return {"name": self.name, "version": self.version, "description": self.description,
                "features": [{k: (list(v) if isinstance(v, tuple) else v)
                              for k, v in vars(f).items()} for f in self.features],
                "layers": {k: vars(v) for k, v in self.layers.items()}}

    @classmethod
    def from_json(cls, data: Mapping) -> Schema:
        """The inverse of :meth:`to_json`; :class:`SchemaError` (one line) for a document that
        is not a schema or whose major version this code does not read."""
        if not isinstance(data, Mapping) or not isinstance(data.get("features"), list):
            raise SchemaError("schema document: expected an object with a 'features' list")
        version = str(data.get("version", SCHEMA_VERSION))
        if version.split(".")[0] != SCHEMA_VERSION.split(".")[0]:
            raise SchemaError(f"schema {data.get('name')!r} has version {version}; this kubric "
                              f"reads schema versions {SCHEMA_VERSION.split('.')[0]}.x")
        try:
            features = tuple(Feature(**{k: (tuple(v) if isinstance(v, list) else v)
                                        for k, v in f.items()}) for f in data["features"])
            layers = {k: LayerFormat(**v) for k, v in dict(data.get("layers", {})).items()}
        except TypeError as err:
            raise SchemaError(f"schema {data.get('name')!r}: malformed feature or layer: "
                              f"{err}") from None
        return cls(str(data["name"]), features, layers, str(data.get("description", "")),
                   version)

    def with_names(self, names: Mapping[str, Iterable[str]]) -> Schema:
        """This schema with the class-label names of the features in ``names`` replaced (how
        the packer resolves :data:`NAMES_FROM_SCENES`)."""
        unknown = sorted(set(names) - set(self.names))
        if unknown:
            raise SchemaError(f"schema {self.name!r}: no features {unknown}")
        features = tuple(dataclasses.replace(f, names=tuple(names[f.name]))
                         if f.name in names else f for f in self.features)
        return Schema(self.name, features, self.layers, self.description, self.version)


def layer_channels(arg: str, what: str = "source") -> tuple[str, slice]:
    """``"rgba[:3]"`` → ("rgba", slice(None, 3)); ``"rgba"`` → ("rgba", slice(None))."""
    name, bracket, rest = arg.partition("[")
    if not bracket:
        return name, slice(None)
    match = re.fullmatch(r"(\d*):(\d*)\]", rest)
    if not name or match is None:
        raise SchemaError(f"{what}: layer source {arg!r} must be NAME, NAME[:stop] or "
                          "NAME[start:stop]")
    start, stop = (int(v) if v else None for v in match.groups())
    return name, slice(start, stop)


# ------------------------------------------------------------------------------ registry
#: schemas by name. A recipe's schema (and its variants, e.g. ``movi_a_tracks``) is registered
#: when the recipe class is (:class:`kubric.pipeline.recipe.Recipe`); other code may register
#: its own with :func:`register_schema`. Lookups by recipe name that must see the built-in
#: recipes go through :func:`kubric.pipeline.recipe.schema_of`, which imports them first.
REGISTRY: dict[str, Schema] = {}


def register_schema(schema: Schema) -> Schema:
    """Make ``schema`` findable by :func:`get_schema` under ``schema.name``; returns it."""
    if not isinstance(schema, Schema):
        raise TypeError(f"register_schema: expected a Schema, got {type(schema).__name__}")
    REGISTRY[schema.name] = schema
    return schema


def get_schema(name: Schema | str) -> Schema:
    """``name`` itself when it is a :class:`Schema`, else the registered schema of that name;
    :class:`SchemaError` (one line, naming the known schemas) when there is none."""
    if isinstance(name, Schema):
        return name
    if name in REGISTRY:
        return REGISTRY[name]
    raise SchemaError(f"unknown recipe schema {name!r} (schemas: {', '.join(sorted(REGISTRY))})")


# ------------------------------------------------------------------------------ docs
def shape_text(feature: Feature, dims: Mapping[str, int] | None = None) -> str:
    shape = feature.full_shape()
    if dims:
        shape = tuple(dims.get(d, d) if isinstance(d, str) else d for d in shape)
    return "(" + ", ".join(str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"


def schema_markdown(schema: Schema | str) -> str:
    """The schema as a Markdown section: a table of every feature (name, dtype, shape, encoding,
    unit, source, doc) and one of the layers it declares beyond the standard ones."""
    schema = get_schema(schema)
    lines = [f"### `{schema.name}`", ""]
    if schema.description:
        lines += [schema.description, ""]
    lines += ["| feature | dtype | shape | encoding | unit | from the scene directory | doc |",
              "|---|---|---|---|---|---|---|"]
    for f in schema.features:
        dtype = ("class label (names: the sorted values found when packing)"
                 if f.names_from_scenes else
                 f"class label ({', '.join(f.names)})" if f.names else f.dtype)
        source = f"`{f.source}`" + (f" → {f.convert}" if f.convert else "") + \
            (f" (missing: `{f.default!r}`)" if f.default is not None else "")
        doc = f.doc.replace("|", "\\|")
        lines.append(f"| `{f.name}` | {dtype} | {shape_text(f)} | {f.encoding} | {f.unit} | "
                     f"{source} | {doc} |")
    if schema.layers:
        lines += ["", "Layers beyond the standard ones:", "",
                  "| layer | file | channels | encoding |", "|---|---|---|---|"]
        for name, fmt in schema.layers.items():
            lines.append(f"| `{name}` | `{fmt.template}` | {fmt.channels} | {fmt.kind} |")
    return "\n".join(lines) + "\n"


def dims_markdown() -> str:
    """The named dimensions as a Markdown list."""
    return "\n".join(f"* `{k}`: {v}" for k, v in DIMS.items()) + "\n"


__all__ = ["CONVERSIONS", "DIMS", "Conversion", "Feature", "LAYERS", "LayerFormat",
           "NAMES_FROM_SCENES", "REGISTRY", "Schema", "VIEW_SPLITS", "convert", "layer_channels",
           "SchemaError", "SEQUENCES", "dims_markdown", "get_schema", "register_schema",
           "schema_markdown"]
