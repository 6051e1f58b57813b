"""The files a glTF asset references, checked before any importer (Blender's, trimesh's) reads it.

A ``.gltf`` (or a ``.glb``'s JSON chunk) names its buffers and images by URI. An importer
follows whatever it is given: ``/etc/passwd`` or ``../../secret.bin`` becomes a mesh's vertices,
``/dev/zero`` grows an import without bound. :func:`check_gltf` allows, as the archive
extraction does (:mod:`kubric.assets.archive`), only

* ``data:`` URIs (embedded bytes), and
* relative paths (percent-decoded) that resolve — symlinks followed — to a **regular file
  inside the source folder** ``root``, of at most :data:`MAX_FILE_BYTES` bytes, and for a
  buffer at least its declared ``byteLength`` (which must not exceed the bound either).

Anything else (absolute paths, ``..`` out of ``root``, URLs, FIFOs, devices, folders, missing
files, a JSON document over :data:`MAX_JSON_BYTES`) is a one-line :class:`GltfReferenceError`
naming the file, the URI and the rule.
"""

from __future__ import annotations

import json
import os
import stat
import struct
import urllib.parse
from pathlib import Path

from kubric.errors import InputError

#: largest referenced buffer or image (bytes)
MAX_FILE_BYTES = 2 << 30
#: largest glTF JSON document read (bytes)
MAX_JSON_BYTES = 64 << 20
GLB_MAGIC = b"glTF"


class GltfReferenceError(InputError):
    """A glTF file referencing something outside its rules (one line)."""


class MalformedGltf(GltfReferenceError):
    """A file that is no glTF document at all (it references nothing)."""


def _regular(path: Path, what: str) -> os.stat_result:
    """``os.stat`` of a regular file (never opened: a FIFO would block)."""
    try:
        st = os.stat(path)
    except OSError as err:
        raise GltfReferenceError(f"{what}: {err.strerror or err}") from None
    if not stat.S_ISREG(st.st_mode):
        raise GltfReferenceError(f"{what}: not a regular file")
    return st


def gltf_document(path) -> dict:
    """The JSON document of a ``.gltf`` or ``.glb`` (one line on a malformed or oversized one)."""
    path = Path(path)
    st = _regular(path, str(path))
    with open(path, "rb") as fh:
        if path.suffix.lower() == ".glb":
            head = fh.read(20)
            if len(head) < 20 or head[:4] != GLB_MAGIC:
                raise MalformedGltf(f"{path}: not a GLB file (no 'glTF' header)")
            length, kind = struct.unpack("<II", head[12:20])
            if kind != 0x4E4F534A or length > min(MAX_JSON_BYTES, st.st_size - 20):
                raise MalformedGltf(f"{path}: GLB JSON chunk of {length} bytes does not fit "
                                         f"the file ({st.st_size} bytes, at most "
                                         f"{MAX_JSON_BYTES} read)")
            data = fh.read(length)
        else:
            if st.st_size > MAX_JSON_BYTES:
                raise GltfReferenceError(f"{path}: {st.st_size} bytes of glTF JSON (at most "
                                         f"{MAX_JSON_BYTES})")
            data = fh.read()
    try:
        doc = json.loads(data)
    except (ValueError, UnicodeDecodeError) as err:
        raise MalformedGltf(f"{path}: not glTF JSON ({err})") from None
    if not isinstance(doc, dict):
        raise MalformedGltf(f"{path}: the glTF document is not a JSON object")
    return doc


def check_gltf(path, root=None, malformed_ok: bool = False) -> list[Path]:
    """Check every URI of the glTF asset ``path`` against the rules of the module doc, with
    ``root`` the source folder (default: the file's folder); returns the referenced files.
    ``malformed_ok``: a file that is no glTF document references nothing (the importer that
    reads it next reports it) instead of an error."""
    path = Path(path)
    root = Path(root if root is not None else path.parent).resolve()
    try:
        doc = gltf_document(path)
    except MalformedGltf:
        if malformed_ok:
            return []
        raise
    found = []
    for kind in ("buffers", "images"):
        items = doc.get(kind, [])
        if not isinstance(items, list):
            raise GltfReferenceError(f"{path}: {kind!r} is not a list")
        for i, item in enumerate(items):
            uri = item.get("uri") if isinstance(item, dict) else None
            if uri is None or (isinstance(uri, str) and uri.startswith("data:")):
                continue
            what = f"{path}: {kind}[{i}] uri {str(uri)[:200]!r}"
            if not isinstance(uri, str) or not uri:
                raise GltfReferenceError(f"{what}: expected a relative file name")
            parsed = urllib.parse.urlsplit(uri)
            if parsed.scheme or parsed.netloc or uri.startswith(("/", "\\")):
                raise GltfReferenceError(f"{what}: only data: URIs and relative file names "
                                         "inside the source folder are read")
            target = (path.parent / urllib.parse.unquote(parsed.path)).resolve()
            if target != root and root not in target.parents:
                raise GltfReferenceError(f"{what}: resolves to {target}, outside the source "
                                         f"folder {root}")
            size = _regular(target, what).st_size
            if size > MAX_FILE_BYTES:
                raise GltfReferenceError(f"{what}: {size} bytes (at most {MAX_FILE_BYTES})")
            declared = item.get("byteLength", 0) if kind == "buffers" else 0
            if not isinstance(declared, int) or not 0 <= declared <= size:
                raise GltfReferenceError(f"{what}: byteLength {declared!r} does not fit the "
                                         f"file's {size} bytes")
            found.append(target)
    return found


__all__ = ["GltfReferenceError", "MAX_FILE_BYTES", "MalformedGltf", "MAX_JSON_BYTES", "check_gltf",
           "gltf_document"]
