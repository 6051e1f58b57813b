"""Deterministic, numpy-aware JSON and pickle files.

:func:`to_jsonable` converts a value tree into plain JSON types:

* numpy scalars → ``int`` / ``float`` / ``bool``; numpy arrays and anything with ``__array__``
  (e.g. :class:`kubric.core.quaternion.Quaternion`) → nested lists;
* tuples (including :class:`kubric.core.color.Color`) and lists → lists;
* ``set`` / ``frozenset`` → sorted lists (values of mixed types are ordered by type name, then
  ``repr``) so the output does not depend on hash order;
* :class:`pathlib.PurePath` → ``str``; :class:`enum.Enum` → its ``value``;
* dict keys → ``str`` (``True`` → ``"true"``, ``None`` → ``"null"``, numbers as JSON writes them).

:func:`write_json` writes with ``sort_keys=True`` and ``indent=2`` and a trailing newline, so two
runs on equal data give byte-identical files. Non-finite floats are written as ``NaN`` /
``Infinity`` (what Python's ``json`` reads back; strict JSON parsers reject them).
"""

from __future__ import annotations

import enum
import json
import pathlib
import pickle
from collections.abc import Mapping
from typing import Any

import numpy as np

from kubric.errors import InputError
from kubric.io.paths import PathLike, as_path, atomic_write_bytes, read_bytes

JSON_INDENT = 2


def _key_to_str(key: Any, where: str) -> str:
    if isinstance(key, str):
        return key
    if isinstance(key, bool | np.bool_):
        return "true" if key else "false"
    if key is None:
        return "null"
    if isinstance(key, int | np.integer):
        return str(int(key))
    if isinstance(key, float | np.floating):
        return json.dumps(float(key))
    if isinstance(key, pathlib.PurePath):
        return str(key)
    if isinstance(key, enum.Enum):
        return _key_to_str(key.value, where)
    raise TypeError(
        f"JSON object key at {where} must be a str, number, bool or None, got "
        f"{type(key).__name__} {key!r}"
    )


def _sorted_set(values, where: str) -> list:
    items = [to_jsonable(v, f"{where}[*]") for v in values]
    try:
        return sorted(items)
    except TypeError:
        return sorted(items, key=lambda v: (type(v).__name__, repr(v)))


def to_jsonable(value: Any, where: str = "data") -> Any:
    """Return ``value`` converted to plain JSON types (see the module docstring).

    ``where`` names the position in the tree for error messages (e.g. ``data["camera"][2]``).
    Raises ``TypeError`` naming the position and type of a value that has no JSON form.
    """
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    if isinstance(value, np.generic):
        if isinstance(value, np.bool_):
            return bool(value)
        if isinstance(value, np.integer | np.floating):
            return value.item()
        if isinstance(value, np.str_):
            return str(value)
        raise TypeError(f"{where}: numpy scalar of dtype {value.dtype} has no JSON form")
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biuf" and value.dtype != object:
            raise TypeError(
                f"{where}: numpy array of dtype {value.dtype} has no JSON form "
                "(allowed: bool, integer, float, object arrays of JSON-able values)"
            )
        if value.dtype == object:
            return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(value.tolist())]
        return value.tolist()
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            key = _key_to_str(k, where)
            if key in out:
                raise ValueError(f"{where}: two keys both convert to the JSON key {key!r}")
            out[key] = to_jsonable(v, f"{where}[{key!r}]")
        return out
    if isinstance(value, list | tuple):
        return [to_jsonable(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, set | frozenset):
        return _sorted_set(value, where)
    if isinstance(value, pathlib.PurePath):
        return str(value)
    if isinstance(value, enum.Enum):
        return to_jsonable(value.value, where)
    if hasattr(value, "__array__"):
        return to_jsonable(np.asarray(value), where)
    raise TypeError(
        f"{where}: value of type {type(value).__name__} has no JSON form (allowed: None, bool, "
        "int, float, str, numpy scalars/arrays, objects with __array__, dict, list, tuple, set, "
        f"pathlib paths, enums); got {value!r:.200}"
    )


def dumps_json(data: Any) -> str:
    """Deterministic JSON text of ``data`` (sorted keys, indent 2, trailing newline)."""
    text = json.dumps(to_jsonable(data), sort_keys=True, indent=JSON_INDENT, allow_nan=True)
    return text + "\n"


def write_json(data: Any, filename: PathLike) -> None:
    """Write ``data`` as deterministic JSON (UTF-8), atomically."""
    atomic_write_bytes(dumps_json(data).encode("utf-8"), filename)


def read_json(filename: PathLike) -> Any:
    """Read a JSON file (UTF-8); ``NaN`` / ``Infinity`` are accepted."""
    path = as_path(filename)
    text = read_bytes(path).decode("utf-8")
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(f"{str(path)!r} is not valid JSON: {err}") from err


def write_pkl(data: Any, filename: PathLike) -> None:
    """Pickle ``data`` (highest protocol) to ``filename``, atomically."""
    atomic_write_bytes(pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL), filename)


def read_pkl(filename: PathLike) -> Any:
    """Unpickle ``filename``. Only read pickles you trust: unpickling can run code."""
    return pickle.loads(read_bytes(filename))

