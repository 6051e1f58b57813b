"""The asset-source manifest format and the cache folder, shared by local and remote sources.

Manifest (compatible with upstream Kubric's)::

    {"name": str, "version": str, "data_dir": str (optional, default: the manifest's folder),
     "assets": {asset_id: {"id", "asset_type", "license", "kwargs", "metadata", "path"?}}}

:func:`validate_manifest` checks a loaded manifest, naming the first problem in one line.
"""

from __future__ import annotations

import os
from pathlib import Path

from kubric.errors import KubricError

ASSET_TYPES = ("FileBasedObject", "Texture", "Character", "MotionClip")
ENTRY_FIELDS = ("id", "asset_type", "license", "kwargs", "metadata")
MANIFEST_FIELDS = ("name", "assets")
ASSET_DIR = "{asset_dir}"


class ManifestError(KubricError, ValueError):
    """A manifest that is missing a field, has a wrong type or an unknown asset type."""


def cache_dir() -> Path:
    """Where generated and extracted assets live: ``$KUBRIC_CACHE_DIR`` or ``~/.cache/kubric``."""
    env = os.environ.get("KUBRIC_CACHE_DIR")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "kubric"


def _require_fields(value, fields, where: str, not_object: str) -> None:
    if not isinstance(value, dict):
        raise ManifestError(f"{where}: {not_object}, got {type(value).__name__}")
    for field in fields:
        if field not in value:
            raise ManifestError(f"{where}: missing required field {field!r} "
                                f"(required: {list(fields)})")


def validate_manifest(manifest, where: str = "manifest") -> dict:
    """Check the structure of a loaded manifest; raise :class:`ManifestError` naming the problem."""
    _require_fields(manifest, MANIFEST_FIELDS, where, "must be a JSON object")
    assets = manifest["assets"]
    if not isinstance(assets, dict):
        raise ManifestError(f"{where}: 'assets' must be an object {{id: entry}}, "
                            f"got {type(assets).__name__}")
    for key, entry in assets.items():
        here = f"{where}: asset {key!r}"
        _require_fields(entry, ENTRY_FIELDS, here, "entry must be an object")
        if entry["id"] != key:
            raise ManifestError(f"{here}: 'id' is {entry['id']!r}, must equal its key {key!r}")
        if entry["asset_type"] not in ASSET_TYPES:
            raise ManifestError(f"{here}: unknown asset_type {entry['asset_type']!r}; "
                                f"allowed: {list(ASSET_TYPES)}")
        for field in ("kwargs", "metadata"):
            if not isinstance(entry[field], dict):
                raise ManifestError(f"{here}: {field!r} must be an object, "
                                    f"got {type(entry[field]).__name__}")
        if "path" in entry and not isinstance(entry["path"], str):
            raise ManifestError(f"{here}: 'path' must be a string, got {entry['path']!r}")
    return manifest
