"""Which schema a pack uses, and which scenes fit it (:mod:`kubric.datasets.packer`'s planning).

Without ``--schema`` the schema is the one the scenes store (``schema.json``, written by
:func:`~kubric.io.scene_writer.write_scene`; no recipe is imported); every scene must store the
same (:func:`scenes_schema`). A scene written before scenes stored their schema falls back to
the recipe its ``metadata.json`` names (:func:`kubric.pipeline.recipe.scene_schema`), and the
pack's result says so. With ``--schema`` that schema is used, and each scene must be of it or
name it among its variants (:func:`check_scene_schema`); scenes that are not are skipped by name.
"""

from __future__ import annotations

import pathlib

from kubric.datasets.layout import DatasetError, DatasetUsageError
from kubric.io import scene_dir
from kubric.io.json_io import read_json
from kubric.io.scene_reader import SceneError, SceneReader
from kubric.io.schema import Schema, SchemaError
from kubric.io.stored_schema import read_document
from kubric.pipeline.recipe import SceneSchema, get_recipe, scene_schema, schema_of

#: the keys of a stored schema document that make the schema (not the options or files)
SCHEMA_KEYS = ("name", "version", "description", "features", "layers")


def schema_origin_and_dims(complete: list[pathlib.Path], schema) -> tuple[Schema, dict, str]:
    """(the schema, the frame count / resolution of the first scene that has them, a line
    saying where the schema came from): the schema given (``--schema``: a name or
    ``FILE.py:Class``), else the one every scene has (:func:`scenes_schema`)."""
    if schema is not None:
        try:
            schema = schema_of(schema)
        except SchemaError as err:  # --schema names no schema: a bad option
            raise DatasetUsageError(str(err)) from None
        origin = f"{schema.name} (given)"
    else:
        found = scenes_schema(complete)
        schema = found.schema
        origin = (f"{schema.name}, stored by the scenes ({scene_dir.SCHEMA_FILE})"
                  if found.stored else
                  f"{schema.name}, from the scenes' {found.origin}: written by an older "
                  "kubric, they do not store their schema, so their recipe was imported")
    errors = []
    for scene in complete:
        try:
            return schema, SceneReader(scene, schema).dims, origin
        except (SceneError, DatasetError, OSError) as err:
            errors.append(err)
    raise DatasetError(f"no complete scene has a readable metadata.json (first: {errors[0]})")


def scenes_schema(complete: list[pathlib.Path]) -> SceneSchema:
    """The one schema of the ``complete`` scenes (:func:`~kubric.pipeline.recipe.scene_schema`:
    stored, else their recipe's). :class:`DatasetError` (one line) when a scene's schema is
    unknown or malformed, or two scenes disagree; a scene whose ``metadata.json`` cannot be
    read (and that stores no schema) is left to the encoder, which reports it as corrupt."""
    first: tuple[pathlib.Path, SceneSchema] | None = None
    first_raw = None
    for scene in complete:
        try:
            raw = _stored_part(scene)
            if first is not None and raw is not None and raw == first_raw:
                continue  # the same document as the first's: no need to parse it
            found = scene_schema(scene)
        except SchemaError as err:
            raise DatasetError(f"{err} (pass --schema to pack it anyway)") from None
        except (OSError, ValueError):
            continue
        if first is None:
            first, first_raw = (scene, found), raw
        elif found.schema.to_json() != first[1].schema.to_json():
            raise DatasetError(f"the scenes disagree on their schema: {str(first[0])!r} has "
                               f"{_differs(first[1], found)}, {str(scene)!r} has "
                               f"{_differs(found, first[1])}: pack them separately")
    if first is None:
        raise DatasetError(f"no complete scene has a readable {scene_dir.METADATA_FILE} or "
                           f"{scene_dir.SCHEMA_FILE} (first: {str(complete[0])!r})")
    return first[1]


def _stored_part(scene: pathlib.Path) -> dict | None:
    """The schema's part of the scene's ``schema.json`` as stored (None without one)."""
    doc = read_document(scene)
    return None if doc is None else {k: doc.get(k) for k in SCHEMA_KEYS}


def _differs(a: SceneSchema, b: SceneSchema) -> str:
    """How ``a`` differs from ``b``, in a few words (its name, else its first differing part)."""
    where = f"from {a.origin}"
    if a.schema.name != b.schema.name:
        return f"{a.schema.name!r} ({where})"
    if a.schema.version != b.schema.version:
        return f"{a.schema.name!r} version {a.schema.version} ({where})"
    theirs = {f.name: f for f in b.schema.features}
    for f in a.schema.features:
        if theirs.get(f.name) != f:
            return f"{a.schema.name!r} with feature {f.name!r} " + \
                ("declared otherwise" if f.name in theirs else "added") + f" ({where})"
    extra = sorted(set(theirs) - set(a.schema.names))
    if extra:
        return f"{a.schema.name!r} without features {extra} ({where})"
    return f"{a.schema.name!r} with other layers or description ({where})"


def check_scene_schema(scene: pathlib.Path, schema: Schema) -> None:
    """A scene of another schema than the dataset's is a mismatch, said as such: its stored
    schema (and variants) must name the dataset's; a scene that stores none is judged by its
    recipe's (imported: the fallback for scenes written before scenes stored their schema)."""
    try:
        doc = read_document(scene)
    except SchemaError as err:
        raise SceneError(str(err)) from None
    if doc is not None:
        own = [doc["name"], *(doc.get("variants") or [])]
        recipe = doc.get("recipe", doc["name"])
    else:
        try:
            recipe = read_json(scene / scene_dir.METADATA_FILE)["flags"]["recipe"]
        except (OSError, ValueError, KeyError, TypeError):
            return  # no recipe named: the reader reports what is wrong with the file
        if not isinstance(recipe, str) or recipe == schema.name:
            return
        try:
            cls = get_recipe(recipe)
        except (ValueError, ImportError):
            return  # a recipe unknown here: the reader reports what does not fit
        own = [s.name for s in (cls.schema, *cls.variants) if s is not None]
    if own and schema.name not in own:
        raise SceneError(f"{str(scene)!r} is a scene of recipe {recipe!r}, not of the dataset's "
                         f"schema {schema.name!r} (its schemas: {sorted(own)}; pack it "
                         "separately or pass --schema)")


__all__ = ["SCHEMA_KEYS", "check_scene_schema", "schema_origin_and_dims", "scenes_schema"]
