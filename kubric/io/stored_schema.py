"""The schema a scene directory stores about itself: ``schema.json``.

:func:`~kubric.io.scene_writer.write_scene` writes it into every scene, so every reader — the
packer, the viewer, ``kubric inspect``, the exports — learns how to read the scene from the scene
itself, in any process, without importing the recipe that made it (a recipe loaded from a file,
``FILE.py:Class``, is not importable by name elsewhere). The document is
:meth:`Schema.to_json() <kubric.io.schema.Schema.to_json>` (``name``, ``version``,
``description``, ``features``, ``layers``: the formats of the recipe's own layers) plus

==============  =================================================================================
``recipe``      the recipe name the scene's ``metadata.json`` gives (``flags.recipe``)
``variants``    names of the further schemas over the same scenes (``movi_a_tracks``): those a
                pack of these scenes may ask for with ``--schema``
``options``     the options the scene was made with (``flags`` less ``recipe`` and ``seed``)
``files``       the scene's other files and folders the recipe declared to the writer
                (``tracks.npz``, ``transforms_train.json``, ``scene.blend``, ``lasr``, ...)
``layer_order`` the recipe's own layers in its order (the JSON object ``layers`` is written
                with sorted keys; the viewer lists layers in the recipe's order)
==============  =================================================================================

A scene holds only declared files (:func:`undeclared_files`): the scene directory's own
(:mod:`kubric.io.scene_dir`), the frames of the layers its schema knows, and ``files``. The
writer checks this when it writes, the worker again before it marks the scene complete.
Scenes written before this file existed have none: :func:`read_document` returns None and the
caller falls back to the recipe named in ``metadata.json``
(:func:`kubric.pipeline.recipe.scene_schema`).
"""

from __future__ import annotations

import dataclasses
import pathlib
from collections.abc import Iterable, Mapping

from kubric.errors import InputError
from kubric.io.json_io import read_json
from kubric.io.layers import frame_filename
from kubric.io.scene_dir import DATA_RANGES_FILE, EVENTS_FILE, METADATA_FILE, SCHEMA_FILE, SUCCESS_FILE
from kubric.io.schema import Schema, SchemaError

#: {schema name: names of its variants}, filled when a recipe class is registered
#: (:mod:`kubric.pipeline.recipe`), so the writer can record them
VARIANTS: dict[str, tuple[str, ...]] = {}
#: files every scene directory may hold beside its layers
OWN_FILES = (METADATA_FILE, EVENTS_FILE, DATA_RANGES_FILE, SCHEMA_FILE, SUCCESS_FILE)


def register_variants(schema_name: str, variant_names: Iterable[str]) -> None:
    """Record that scenes of ``schema_name`` also pack as ``variant_names``."""
    VARIANTS[schema_name] = tuple(variant_names)


def schema_document(schema: Schema, metadata: Mapping, files: Iterable[str]) -> dict:
    """The ``schema.json`` of a scene of ``schema`` with ``metadata`` (its ``flags`` give the
    recipe and options) and the other declared ``files``."""
    flags = metadata.get("flags", {}) if isinstance(metadata, Mapping) else {}
    flags = flags if isinstance(flags, Mapping) else {}
    return {**schema.to_json(), "recipe": str(flags.get("recipe", schema.name)),
            "variants": list(VARIANTS.get(schema.name, ())),
            "options": {k: v for k, v in flags.items() if k not in ("recipe", "seed")},
            "files": sorted(files), "layer_order": list(schema.layers)}


def read_document(scene) -> dict | None:
    """The ``schema.json`` document of scene directory ``scene`` (a local path), None when it
    has none (a scene written before scenes stored their schema); :class:`SchemaError` (one
    line, naming the file) when it cannot be read or is not a schema document."""
    path = pathlib.Path(scene) / SCHEMA_FILE
    if not path.is_file():
        return None
    try:
        doc = read_json(path)
    except (OSError, InputError, UnicodeDecodeError) as err:
        raise SchemaError(f"{str(path)!r} cannot be read: {err}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("name"), str):
        raise SchemaError(f"{str(path)!r} is not a schema document (expected an object with a "
                          "'name' and 'features')")
    return doc


def document_schema(doc: Mapping, scene=None) -> Schema:
    """The :class:`Schema` of a ``schema.json`` document (:class:`SchemaError`, one line naming
    the scene's file, when it is malformed or of a major version this code does not read)."""
    try:
        schema = Schema.from_json(doc)
    except SchemaError as err:
        where = f"{str(pathlib.Path(scene) / SCHEMA_FILE)!r}: " if scene is not None else ""
        raise SchemaError(f"{where}{err}") from None
    order = doc.get("layer_order")
    if isinstance(order, list) and sorted(order) == sorted(schema.layers):
        schema = dataclasses.replace(schema, layers={k: schema.layers[k] for k in order})
    return schema


def stored_schema(scene) -> Schema | None:
    """The schema scene directory ``scene`` stores, or None when it stores none."""
    doc = read_document(scene)
    return None if doc is None else document_schema(doc, scene)


def declared_names(schema: Schema, num_frames: int, files: Iterable[str]) -> set[str]:
    """Every name a scene of ``schema`` with ``num_frames`` frames (views) may hold: the scene
    directory's own files, each frame of every layer the schema knows (standard and its own),
    and the recipe's declared ``files``."""
    names = set(OWN_FILES) | set(files)
    for fmt in schema.layer_formats.values():
        names.update(frame_filename(fmt.template, i) for i in range(int(num_frames)))
    return names


def undeclared_files(scene, schema: Schema, num_frames: int, files: Iterable[str]) -> list[str]:
    """Sorted names of the entries of scene directory ``scene`` that nothing declares."""
    allowed = declared_names(schema, num_frames, files)
    return sorted(p.name for p in pathlib.Path(scene).iterdir() if p.name not in allowed)


def check_declared(scene) -> None:
    """:class:`SchemaError` (one line) when scene directory ``scene``, which stores its schema,
    holds a file or folder that neither the scene directory, its layers nor its ``files``
    declare (nothing to check in a scene without ``schema.json``)."""
    doc = read_document(scene)
    if doc is None:
        return
    meta = read_json(pathlib.Path(scene) / METADATA_FILE).get("metadata", {})
    extra = undeclared_files(scene, document_schema(doc, scene), meta.get("num_frames", 0),
                             doc.get("files", ()))
    if extra:
        raise SchemaError(undeclared_message(doc["name"], extra, doc.get("files", ())))


def undeclared_message(name: str, extra: list[str], files: Iterable[str]) -> str:
    return (f"schema {name!r}: the scene directory holds {extra}, which nothing declares (a "
            f"scene holds its layers, {list(OWN_FILES)} and the files given to write_scene, "
            f"here {sorted(files)})")


__all__ = ["OWN_FILES", "VARIANTS", "check_declared", "declared_names",
           "document_schema", "read_document", "register_variants", "schema_document",
           "stored_schema", "undeclared_files", "undeclared_message"]
