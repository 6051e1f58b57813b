"""Asset runtime: what a worker needs at scene-build time (open sources, extract, cache).

``import kubric.assets`` is light (numpy only). The source format is described in
``docs/assets.md``. Runtime modules:

- :mod:`~kubric.assets.asset_source` — :class:`AssetSource`: open a source (``manifest.json``),
  ``create(asset_id, **overrides)``, categories and held-out splits; :func:`cache_dir` —
  ``$KUBRIC_CACHE_DIR`` or ``~/.cache/kubric``.
- :mod:`~kubric.assets.archive` — safe extraction (:func:`safe_extract`, ``safe_extract_zip``)
  and the deterministic archive format (``write_archive``).
- :mod:`~kubric.assets.download` — resumable, checksum-verified HTTP downloads (stdlib only).
- :mod:`~kubric.assets.utils` (also ``kb.assets.utils``, loaded on first access) —
  :func:`~kubric.assets.utils.get_clevr_lights`; :mod:`~kubric.assets.clevr` — the CLEVR facts
  (shapes, colours, sizes, materials, lamps, camera) and KuBasic's shape ids, as plain data.
- :mod:`~kubric.assets.articulated` — multi-link URDFs added to a scene, every link rendered.
- :mod:`~kubric.assets.procedural_character` — a procedural 15-bone tube person
  (``tube_person``) and its walk (``walk_clip``), built in numpy (docs/characters.md).
- :mod:`~kubric.assets.characters` — Character / MotionClip archives → ``kb.Character`` /
  ``kb.MotionClip`` keyword arguments (``AssetSource.create`` uses it).

The offline **build tools** (converters, mesh physics, KuBasic, the GSO / ShapeNet / Poly Haven /
pybullet collections, the asset writer, ``kubric assets``, and the first-use builds of the default
sources: ``kubric.asset_tools.ensure_kubasic`` / ``ensure_hdri_source`` /
``ensure_pybullet_collection`` / ``ensure_humans``) live in :mod:`kubric.asset_tools`, which
imports this package and never the reverse (tests/test_import_layers.py).
"""

from kubric.assets.archive import (
    AssetArchiveError,
    CorruptArchiveError,
    UnsafeArchiveError,
    safe_extract,
)
from kubric.assets.asset_source import AssetSource, ManifestError, cache_dir, validate_manifest


def __getattr__(name):
    """``kubric.assets.utils`` on first access (so ``kb.assets.utils.get_clevr_lights`` works
    after a plain ``import kubric``)."""
    if name == "utils":
        import importlib
        return importlib.import_module("kubric.assets.utils")
    raise AttributeError(f"module 'kubric.assets' has no attribute {name!r}")


__all__ = [
    "AssetSource", "ManifestError", "cache_dir", "validate_manifest", "safe_extract",
    "AssetArchiveError", "CorruptArchiveError", "UnsafeArchiveError",
]
