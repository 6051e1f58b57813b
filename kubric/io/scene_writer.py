"""The one writer of a scene directory: what a recipe's :class:`~kubric.io.schema.Schema` declares.

:func:`write_scene` is how every recipe writes its scene (the names are those of
:mod:`kubric.io.scene_dir`):

1. before writing anything, :func:`check_scene_content` checks that every feature's source is
   there (a layer the schema reads but the recipe did not render, a missing metadata field: a
   one-line :class:`~kubric.io.schema.SchemaError`);
2. it writes the layers with the schema's layer formats (standard and the recipe's own),
   ``data_ranges.json``, ``metadata.json``, ``events.json``, the recipe's other files
   (``files``, see :func:`write_scene`) and ``schema.json``: the scene's schema, recipe,
   options and declared files (:mod:`kubric.io.stored_schema`), from which every reader learns
   how to read the scene without importing its recipe;
3. it checks that the directory holds nothing undeclared (a file a recipe wrote around the
   writer fails here, by name);
4. it then reads the written directory back through :class:`~kubric.io.scene_reader.SceneReader`
   — the packer's own reader, every conversion and cast it applies — so a scene that would not
   pack fails when it is written, naming the feature, not when it is packed.

``_SUCCESS`` is not written here: the worker writes it last (:mod:`kubric.pipeline.worker`).
"""

from __future__ import annotations

import io
import pathlib
import shutil
from collections.abc import Mapping

import numpy as np

from kubric.io.json_io import write_json
from kubric.io.layers import write_image_dict
from kubric.io.paths import PathLike, as_path, atomic_write_bytes
from kubric.io.scene_dir import EVENTS_FILE, METADATA_FILE, SCHEMA_FILE
from kubric.io.scene_reader import SceneError, SceneReader, element_value, lookup
from kubric.io.schema import Schema, SchemaError, get_schema
from kubric.io.stored_schema import OWN_FILES, schema_document, undeclared_files, undeclared_message


def check_scene_content(schema: Schema, layers: Mapping[str, np.ndarray], metadata: Mapping,
                        events: Mapping) -> None:
    """Raise :class:`SchemaError` (one line) when a feature's source is missing."""
    meta = metadata.get("metadata", {}) if isinstance(metadata, Mapping) else None
    if not isinstance(meta, Mapping) or "resolution" not in meta or "num_frames" not in meta:
        raise SchemaError(f"schema {schema.name!r}: metadata.json['metadata'] must give "
                          "'resolution' [width, height] and 'num_frames' (every reader needs them)")
    try:
        width, height = (int(v) for v in meta["resolution"])
        dims = (int(meta["num_frames"]), height, width)
    except (TypeError, ValueError):
        raise SchemaError(f"schema {schema.name!r}: metadata resolution "
                          f"{meta['resolution']!r} / num_frames {meta['num_frames']!r} are not "
                          "[width, height] and a count") from None
    for name, layer in layers.items():
        if np.shape(layer)[:3] != dims:
            raise SchemaError(f"schema {schema.name!r}: layer {name!r} has (T, H, W) "
                              f"{np.shape(layer)[:3]}, the metadata says {dims}")
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


def _write_file(path: pathlib.Path, content) -> None:
    """One of a recipe's other files (see :func:`write_scene`'s ``files``)."""
    if isinstance(content, pathlib.Path):
        if not content.exists():
            raise SchemaError(f"write_scene: file {path.name!r}: {str(content)!r} does not exist")
        shutil.move(str(content), str(path))
    elif callable(content):
        content(path)
        if not path.exists():
            raise SchemaError(f"write_scene: file {path.name!r}: its writer "
                              f"{getattr(content, '__name__', content)!r} wrote nothing there")
    elif isinstance(content, bytes | bytearray):
        atomic_write_bytes(bytes(content), path)
    elif path.suffix == ".npz":
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **content)
        atomic_write_bytes(buffer.getvalue(), path)
    elif isinstance(content, Mapping | list):
        write_json(content, path)
    else:
        raise TypeError(f"write_scene: file {path.name!r}: expected bytes, a JSON document, "
                        "(for .npz) a dict of arrays, a pathlib.Path to move in or a function "
                        f"of the path, got {type(content).__name__}")


def _check_names(schema: Schema, files: Mapping[str, object]) -> None:
    for name in files:
        if not isinstance(name, str) or not name or name in OWN_FILES or name.startswith(".") \
                or "/" in name or "\\" in name:
            raise SchemaError(f"schema {schema.name!r}: write_scene file name {name!r} must be "
                              f"a plain name, not hidden, not one of {list(OWN_FILES)}")


def resolved_for_check(schema: Schema, reader: SceneReader) -> Schema:
    """``schema`` with the class labels whose names are collected when packing resolved from this
    one scene (so every value of the scene is a known name)."""
    names = {}
    for f in schema.features:
        if f.names_from_scenes:
            values = sorted({str(v) for v in reader.raw_values(f)})
            if values:
                names[f.name] = values
    return schema.with_names(names) if names else schema


def check_written(schema: Schema | str, scene) -> None:
    """Read scene directory ``scene`` back as the packer will (every feature, every conversion);
    :class:`SchemaError` (one line, naming the schema and the feature) when it does not pack."""
    schema = get_schema(schema)
    reader = SceneReader(scene, schema)
    try:
        reader.schema = resolved_for_check(schema, reader)  # same files, read once
        reader.check_each()  # one layer in memory at a time
    except (SceneError, SchemaError) as err:
        raise SchemaError(f"schema {schema.name!r}: the scene written does not pack: "
                          f"{str(err).replace(repr(str(scene)) + ' ', '')}") from None


def write_scene(schema: Schema | str, out_dir: PathLike, layers: Mapping[str, np.ndarray],
                metadata: Mapping, events: Mapping | None = None,
                files: Mapping[str, object] | None = None, max_write_threads: int = 16) -> dict:
    """Write one scene directory as ``schema`` declares it (see the module doc) into
    ``out_dir``: layers, ``data_ranges.json``, ``metadata.json``, ``events.json`` (default: no
    collisions), ``files`` and ``schema.json``; then check it in full.

    ``files`` ({name: content}) are the scene's other files and folders, each one a plain name
    recorded in ``schema.json``: a dict / list → JSON; a dict of arrays for a ``.npz`` name → a
    numpy archive; bytes as they are; a ``pathlib.Path`` → that file or folder, made elsewhere
    (e.g. a saved ``scene.bullet``), moved in; a function ``f(path)`` → called, after the layers
    and documents are in place, to write the file or folder at ``path`` (an export that reads
    the scene, e.g. vbr's ``lasr/``). Returns the ranges written to ``data_ranges.json``."""
    schema = get_schema(schema)
    events = {"collisions": []} if events is None else events
    files = dict(files or {})
    _check_names(schema, files)
    check_scene_content(schema, layers, metadata, events)
    out_dir = as_path(out_dir)
    ranges = write_image_dict(layers, out_dir, max_write_threads=max_write_threads,
                              formats=schema.layers)
    write_json(metadata, out_dir / METADATA_FILE)
    write_json(events, out_dir / EVENTS_FILE)
    later = {k: v for k, v in files.items() if callable(v) and not isinstance(v, pathlib.Path)}
    for name, content in files.items():
        if name not in later:
            _write_file(out_dir / name, content)
    for name, content in later.items():  # these may read the scene written so far
        _write_file(out_dir / name, content)
    write_json(schema_document(schema, metadata, files), out_dir / SCHEMA_FILE)
    extra = undeclared_files(out_dir, schema, metadata["metadata"]["num_frames"], files)
    if extra:
        raise SchemaError(undeclared_message(schema.name, extra, files))
    check_written(schema, out_dir)
    return ranges
