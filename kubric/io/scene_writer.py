"""Write a scene directory as a recipe's :class:`~kubric.io.schema.Schema` declares it.

:func:`write_scene` checks the rendered layers and the ``metadata.json`` / ``events.json``
content against the schema *before* writing anything (a field the schema reads but the recipe
did not produce is a one-line :class:`~kubric.io.schema.SchemaError`), then writes the layers with
the schema's layer formats and the two JSON files. ``_SUCCESS`` is not written here: the worker
writes it last (:mod:`kubric.pipeline.worker`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from kubric.io.json_io import write_json
from kubric.io.layers import write_image_dict
from kubric.io.paths import PathLike, as_path
from kubric.io.schema import Feature, Schema, SchemaError, get_schema

METADATA_FILE, EVENTS_FILE = "metadata.json", "events.json"


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


def check_scene_content(schema: Schema, layers: Mapping[str, np.ndarray], metadata: Mapping,
                        events: Mapping) -> None:
    """Raise :class:`SchemaError` (one line) when a feature's source is missing."""
    tables = {"meta": (metadata.get("metadata", {}), "metadata.json['metadata']"),
              "camera": (metadata.get("camera", {}), "metadata.json['camera']")}
    for f in schema.features:
        kind, arg = f.source_kind, f.source_arg
        if kind in ("layer", "range"):
            layer = arg.split("[", 1)[0]
            if layer not in layers:
                raise SchemaError(f"schema {schema.name!r}: feature {f.name!r} needs layer "
                                  f"{layer!r}, which the recipe did not render (has "
                                  f"{sorted(layers)})")
        elif kind in tables:
            lookup(tables[kind][0], arg, f"schema {schema.name!r} feature {f.name!r}: "
                   + tables[kind][1])
        elif kind == "instance":
            for n, inst in enumerate(metadata.get("instances", [])):
                element_value(f, inst, f"schema {schema.name!r} feature {f.name!r}: instance {n}")
        elif kind == "collision":
            for k, event in enumerate(events.get("collisions", [])):
                element_value(f, event, f"schema {schema.name!r} feature {f.name!r}: "
                              f"collision {k}")


def write_scene(schema: Schema | str, out_dir: PathLike, layers: Mapping[str, np.ndarray],
                metadata: Mapping, events: Mapping | None = None,
                max_write_threads: int = 16) -> dict:
    """Check ``layers`` / ``metadata`` / ``events`` against ``schema`` and write them into
    ``out_dir`` (layer files, ``data_ranges.json``, ``metadata.json``, ``events.json``).
    Returns the ranges written to ``data_ranges.json``."""
    schema = get_schema(schema)
    events = {"collisions": []} if events is None else events
    check_scene_content(schema, layers, metadata, events)
    out_dir = as_path(out_dir)
    ranges = write_image_dict(layers, out_dir, max_write_threads=max_write_threads,
                              formats=schema.layers)
    write_json(metadata, out_dir / METADATA_FILE)
    write_json(events, out_dir / EVENTS_FILE)
    return ranges
