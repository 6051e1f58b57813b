"""The one check of an output location against the inputs it is made from, shared by every
writer of derived data (``kubric export FORMAT``, ``kubric pack``).

A writer refuses, before it writes anything (one line naming ``--out`` and the input):

* an output **equal to an input** (a scene folder or the folder of scenes), **inside a scene**
  (``--out SCENE/metadata.json`` would replace the scene's own files while it keeps
  ``_SUCCESS``), or **holding an input** (``--out SCENES`` or a folder above it: the writer's
  folders would mix with, or replace, the scenes). A file or folder beside the scenes inside
  the folder of scenes (``SCENES/coco.json``) is allowed: it is not a scene and no reader takes
  it for one. Paths are compared resolved, so a symlink to a scene counts as the scene.
* a **URL** (``s3://…``) where the writer writes local files only — otherwise ``s3://b/x``
  would become a local folder named ``s3:`` — and a local path whose first part looks like a
  URL scheme that lost its ``//`` (``s3:/b/x``).
"""

from __future__ import annotations

import os
import pathlib
import re

from kubric.errors import UsageError
from kubric.io import scene_dir, storage

_SCHEME_PART = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.\-]*:$")


class OutputError(UsageError):
    """An output location a writer refuses (exit status 2)."""


def _resolved(path) -> pathlib.Path:
    return pathlib.Path(os.path.abspath(pathlib.Path(path).expanduser())).resolve()


def _url_overlap(out: str, inputs) -> str | None:
    out = storage.normalise(out)
    for item in inputs:
        item = str(item)
        if not storage.is_url(item):
            continue
        item = storage.normalise(item)
        if out == item or out.startswith(item + "/") or item.startswith(out + "/"):
            return item
    return None


def check_output(out, scenes=(), roots=(), urls: bool = False, flag: str = "--out",
                 command: str = "this command") -> None:
    """Raise :class:`OutputError` (one line) when ``out`` may not receive the output of a
    writer reading the scene folders ``scenes`` found in the folders ``roots`` (module doc).
    ``urls``: the writer writes URLs (``kubric pack``); otherwise a URL ``out`` is refused."""
    raw = os.fspath(out) if isinstance(out, os.PathLike) else str(out)
    if storage.is_url(raw):
        if not urls:
            raise OutputError(f"{flag} {raw!r}: {command} writes local files only (give a "
                              "local path; `kubric pack` writes URLs)")
        overlap = _url_overlap(raw, [*scenes, *roots])
        if overlap is not None:
            raise OutputError(f"{flag} {raw!r} overlaps the input {overlap!r}; give an output "
                              "outside the scenes")
        return
    first = pathlib.PurePath(raw).parts[:1]
    if first and _SCHEME_PART.match(first[0]):
        raise OutputError(f"{flag} {raw!r} looks like a URL without its '//' (a local folder "
                          f"named {first[0]!r} would be written); give a local path")
    target = _resolved(raw)
    local = [(p, True) for p in scenes if not storage.is_url(str(p))] + \
        [(p, False) for p in roots if not storage.is_url(str(p))]
    for item, is_scene in local:
        path = _resolved(item)
        inside = path in target.parents
        if target == path or path in target.parents and is_scene or target in path.parents:
            where = "is" if target == path else "is inside" if inside else "holds"
            kind = "the scene" if is_scene else "the input folder"
            raise OutputError(f"{flag} {raw!r} {where} {kind} {str(item)!r}; an output must "
                              "lie outside every scene it is made from")


def scene_folders(root) -> list[pathlib.Path]:
    """The folders under local ``root`` that are, or were meant to be, scenes (``root`` itself
    when it is one): what :func:`check_output` keeps an output out of."""
    root = pathlib.Path(root)
    if not root.is_dir():
        return []
    if scene_dir.looks_like_scene(root) and scene_dir.is_complete(root):
        return [root]
    return [p for p in sorted(root.iterdir()) if p.is_dir() and scene_dir.looks_like_scene(p)]


__all__ = ["OutputError", "check_output", "scene_folders"]
