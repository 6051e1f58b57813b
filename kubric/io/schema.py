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
instance), ``P`` points (point tracks), ``C`` classes, ``B`` bands. Features named
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
``npz:FILE:KEY``       array KEY of the numpy archive FILE in the scene directory
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
import importlib
import re
from collections.abc import Iterable, Mapping

from kubric.io.layers import LAYERS, LayerFormat, layer_table

#: named dimensions and what they count
DIMS = {"T": "frames", "H": "image height (pixels)", "W": "image width (pixels)",
        "N": "instances", "K": "collision events", "V": "frames in which the instance is visible",
        "P": "points (e.g. point tracks)", "C": "classes (e.g. semantic classes)",
        "B": "bands (e.g. texture frequency bands)"}
#: feature name prefixes that hold one value per element of a sequence, and its dimension
SEQUENCES = {"instances/": "N", "events/collisions/": "K"}
ENCODINGS = ("none", "png", "zlib", "text", "class_label", "bbox")
DTYPES = ("uint8", "uint16", "int32", "int64", "float32", "bool", "str")
SOURCE_KINDS = ("scene_name", "layer", "range", "meta", "camera", "instance", "collision", "npz")
#: conversions a feature may name in ``convert``
CONVERSIONS = {
    "hex_to_rgb": "colour hex string '#rrggbb' → float32 (3,) in [0, 1]",
    "floor": "number → its floor (e.g. a fractional collision frame → the frame it falls in)",
    "negative_to_uint16_max": "−1 (no instance) → 65535, as upstream's uint16 instance indices",
    "split_index": "per-view split names (a list of {'split': name} or of names) → their "
                   "indices in (train, val, test)",
}
#: ``names`` of a class label whose names are collected from the scenes when packing
NAMES_FROM_SCENES = ("<sorted values found when packing>",)
#: version of the schema contract (bumped when a feature changes meaning, never for additions)
SCHEMA_VERSION = "1.0.0"


class SchemaError(ValueError):
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
            raise SchemaError(f"{what}: encoding {self.encoding!r} is not one of {ENCODINGS}")
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
        if (self.encoding == "class_label") != bool(self.names):
            raise SchemaError(f"{what}: class labels need names and encoding 'class_label'")
        if self.encoding == "png" and (self.shape[:1] != ("T",) or len(self.shape) != 4
                                       or self.dtype not in ("uint8", "uint16")):
            raise SchemaError(f"{what}: png features are (T, H, W, C) uint8 / uint16")
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
#: schemas by recipe name
REGISTRY: dict[str, Schema] = {}
#: modules that declare the built-in recipes' schemas (imported on first lookup)
BUILTIN_SCHEMA_MODULES = ("kubric.recipes.bench", "kubric.recipes.movi_schema",
                          "kubric.recipes.multiview_schema",
                          "kubric.recipes.vbr_schema")


def register_schema(schema: Schema) -> Schema:
    """Make ``schema`` findable by :func:`get_schema` under ``schema.name``; returns it."""
    if not isinstance(schema, Schema):
        raise TypeError(f"register_schema: expected a Schema, got {type(schema).__name__}")
    REGISTRY[schema.name] = schema
    return schema


def builtin_schemas() -> dict[str, Schema]:
    """The schemas the built-in schema modules declare, by name — not those other code (a test,
    a user's module) registered in this process, so generated docs never depend on what ran
    before."""
    found: dict[str, Schema] = {}
    for module in BUILTIN_SCHEMA_MODULES:
        for value in vars(importlib.import_module(module)).values():
            for item in (value.values() if isinstance(value, dict) else (value,)):
                if isinstance(item, Schema) and REGISTRY.get(item.name) is item:
                    found[item.name] = item
    return found


def get_schema(name: str) -> Schema:
    """The schema of recipe ``name``: a registered schema, or the ``schema`` attribute of the
    recipe :func:`kubric.pipeline.get_recipe` finds for ``name`` (``module:Class`` too).
    Raises :class:`SchemaError` (one line) when there is none."""
    if isinstance(name, Schema):
        return name
    for module in BUILTIN_SCHEMA_MODULES:
        importlib.import_module(module)
    if name in REGISTRY:
        return REGISTRY[name]
    known = ", ".join(sorted(REGISTRY))
    try:
        from kubric.pipeline.recipe import get_recipe
        schema = getattr(get_recipe(name), "schema", None)
    except (ValueError, ImportError):
        schema = None
    if isinstance(schema, Schema):
        return schema
    raise SchemaError(f"unknown recipe schema {name!r} (schemas: {known})")


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


__all__ = ["CONVERSIONS", "DIMS", "Feature", "LAYERS", "LayerFormat", "NAMES_FROM_SCENES",
           "REGISTRY", "Schema", "builtin_schemas", "layer_channels",
           "SchemaError", "SEQUENCES", "dims_markdown", "get_schema", "register_schema",
           "schema_markdown"]
