"""Asset sources: manifests + archives, safe extraction, and the builders of our own sources.

``import kubric.assets`` is light (numpy only); trimesh, PyBullet and bpy are imported inside the
functions that need them. The source format is described in ``docs/assets.md``.

- :class:`AssetSource` — open a source (``manifest.json``), ``create(asset_id, **overrides)``.
- :func:`cache_dir` — ``$KUBRIC_CACHE_DIR`` or ``~/.cache/kubric``.
- ``kubric.assets.utils`` (also ``kb.assets.utils``, loaded on first access) —
  :func:`~kubric.assets.utils.get_clevr_lights`.
- :func:`ensure_kubasic`, :func:`ensure_hdri_source`, :func:`ensure_pybullet_collection` — the
  sources this project builds on the user's machine, built into the cache on first use.
- Collection readers (offline build tools, ``kubric assets gso|shapenet|polyhaven``):
  ``kubric.assets.gso``, ``kubric.assets.shapenet``, ``kubric.assets.polyhaven`` (downloads
  through ``kubric.assets.download``); multi-link URDFs: ``kubric.assets.articulated``.
"""

from kubric.assets.archive import (
    AssetArchiveError,
    CorruptArchiveError,
    UnsafeArchiveError,
    safe_extract,
)
from kubric.assets.asset_source import AssetSource, ManifestError, cache_dir, validate_manifest


def ensure_kubasic(cache=None, workers=None):
    """KuBasic source, built into ``cache_dir()/KuBasic`` on first use (see kubric.assets.kubasic)."""
    from kubric.assets.kubasic import ensure_kubasic as _ensure
    return _ensure(cache, workers=workers)


def ensure_hdri_source(cache=None):
    """HDRI backgrounds from the bpy wheel's world HDRIs, built on first use (kubric.assets.hdri)."""
    from kubric.assets.hdri import ensure_hdri_source as _ensure
    return _ensure(cache)


def ensure_pybullet_collection(limit=None, cache=None, workers=None):
    """pybullet_data objects as a source (kubric.assets.pybullet_collection)."""
    from kubric.assets.pybullet_collection import ensure_pybullet_collection as _ensure
    return _ensure(limit=limit, cache=cache, workers=workers)


def __getattr__(name):
    """``kubric.assets.utils`` on first access (so ``kb.assets.utils.get_clevr_lights`` works
    after a plain ``import kubric``)."""
    if name == "utils":
        import importlib
        return importlib.import_module("kubric.assets.utils")
    raise AttributeError(f"module 'kubric.assets' has no attribute {name!r}")


__all__ = [
    "AssetSource", "ManifestError", "cache_dir", "validate_manifest", "safe_extract",
    "AssetArchiveError", "CorruptArchiveError", "UnsafeArchiveError", "ensure_kubasic",
    "ensure_hdri_source", "ensure_pybullet_collection",
]
