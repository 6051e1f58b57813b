"""Asset sources: a folder with ``manifest.json`` plus one archive per asset.

Manifest (compatible with upstream Kubric's)::

    {"name": str, "version": str, "data_dir": str (optional, default: the manifest's folder),
     "assets": {asset_id: {"id", "asset_type", "license", "kwargs", "metadata", "path"?}}}

``asset_type`` is ``"FileBasedObject"``, ``"Texture"``, ``"Character"`` or ``"MotionClip"``
(the last two: :mod:`kubric.assets.characters`); ``path`` (default ``<id>.tar.gz``) is
relative to ``data_dir``. String values of ``kwargs`` that start with ``{asset_dir}/`` point into
the extracted archive. Archives are extracted lazily, once, with :func:`safe_extract`, into a
per-source folder of the cache (see :func:`cache_dir`).
"""

from __future__ import annotations

import contextlib
import difflib
import json
import os
import shutil
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from kubric.assets import remote_source
from kubric.assets.archive import build_staged, safe_extract
from kubric.assets.manifest import (  # noqa: F401  (public here too: kubric.assets exports them)
    ASSET_DIR,
    ASSET_TYPES,
    ENTRY_FIELDS,
    MANIFEST_FIELDS,
    ManifestError,
    cache_dir,
    validate_manifest,
)
from kubric.errors import InputError


def _resolve(value, asset_dir: Path):
    if isinstance(value, str) and value.startswith(ASSET_DIR + "/"):
        return str(asset_dir / value[len(ASSET_DIR) + 1:])
    if isinstance(value, dict):
        return {k: _resolve(v, asset_dir) for k, v in value.items()}
    if isinstance(value, list):
        return [_resolve(v, asset_dir) for v in value]
    return value


def _safe_name(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


class AssetSource:
    """A collection of assets described by a ``manifest.json``.

    Args:
      path: the source folder (containing ``manifest.json``) or the manifest file itself, or the
        URL of either (``https://``, ``s3://``, ``gs://``, any fsspec URL): downloaded once per
        machine into the cache, archives on first use (:mod:`kubric.assets.remote_source`).
      scratch_dir: where archives are extracted; default ``cache_dir()/extracted/<name>-<hash>``.

    Attributes:
      name, version: from the manifest. all_asset_ids: sorted ids. db: ``{id: entry}``
      (``_assets`` is the same dict, under the name upstream Kubric's scripts use).

    ``close()`` (or leaving a ``with AssetSource(path) as source:`` block) deletes the folders that
    this instance extracted, unless another ``AssetSource`` on the same extraction folder is still
    open in this or any other process (workers running in parallel share the cache): each open
    instance holds a shared ``flock`` on the folder from its first extraction until ``close()``,
    and only a closer that can take the exclusive lock deletes anything. Folders it found already
    extracted are never deleted by it. Using the source after ``close()`` extracts afresh.
    """

    def __init__(self, path: str | os.PathLike, scratch_dir: str | os.PathLike | None = None):
        self.remote = None  # a RemoteSource for URLs (kubric.assets.remote_source)
        if remote_source.is_remote(path):
            self.remote = remote_source.RemoteSource(path)
            path = self.remote.manifest_path
        path = Path(remote_source.local_path(path)).expanduser()
        manifest_path = path / "manifest.json" if path.is_dir() else path
        if not manifest_path.is_file():
            raise FileNotFoundError(f"AssetSource: no manifest.json at {str(manifest_path)!r}")
        try:
            manifest = json.loads(manifest_path.read_text())
        except json.JSONDecodeError as err:
            raise ManifestError(f"{manifest_path}: not valid JSON: {err}") from None
        validate_manifest(manifest, str(manifest_path))
        self.manifest_path = manifest_path.resolve()
        self.manifest = manifest
        self.name = str(manifest["name"])
        self.version = str(manifest.get("version", ""))
        data_dir = manifest.get("data_dir")
        base = self.manifest_path.parent
        self.data_dir = (base / data_dir).resolve() if data_dir else base
        if self.remote is not None:
            self.data_dir = self.remote.folder / "archives"
        self.db: dict[str, dict] = dict(manifest["assets"])
        if scratch_dir is None:
            import hashlib
            digest = hashlib.sha1(str(self.manifest_path).encode()).hexdigest()[:10]
            scratch_dir = cache_dir() / "extracted" / f"{_safe_name(self.name)}-{digest}"
        self.scratch_dir = Path(scratch_dir)
        self._extracted: list[Path] = []  # folders this instance extracted (removed by close())
        self._hold: int | None = None  # fd of scratch_dir, flock'ed shared while this is open

    @classmethod
    def from_manifest(cls, manifest_path: str | os.PathLike, **kwargs) -> AssetSource:
        """Open the source described by ``manifest_path`` (a file or its folder)."""
        return cls(manifest_path, **kwargs)

    @property
    def _assets(self) -> dict[str, dict]:
        """``{asset_id: manifest entry}`` — alias of :attr:`db` (upstream Kubric's name)."""
        return self.db

    def __enter__(self) -> AssetSource:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()

    def __del__(self) -> None:
        fd, self._hold = getattr(self, "_hold", None), None
        if fd is not None:
            os.close(fd)  # release the lock; a dropped instance deletes nothing

    def __repr__(self) -> str:
        return f"AssetSource({self.name!r}, {len(self.db)} assets, {str(self.data_dir)!r})"

    def __len__(self) -> int:
        return len(self.db)

    def __contains__(self, asset_id) -> bool:
        return asset_id in self.db

    @property
    def all_asset_ids(self) -> list[str]:
        """Every asset id, sorted."""
        return sorted(self.db)

    @property
    def categories(self) -> list[str]:
        """Sorted distinct categories: ``metadata.category`` and the entries of
        ``metadata.categories`` (collections such as GSO list several)."""
        return sorted({c for e in self.db.values() for c in _categories_of(e)})

    def asset_ids_in(self, category: str) -> list[str]:
        """Sorted ids of the assets whose ``metadata.category`` is ``category`` or whose
        ``metadata.categories`` list holds it."""
        return sorted(k for k, e in self.db.items() if category in _categories_of(e))

    def get_test_split(self, fraction: float = 0.1, seed: int = 42,
                       category: str | None = None) -> tuple[list[str], list[str]]:
        """(train ids, held-out ids): ``round(fraction * n)`` of the sorted ids chosen by ``seed``.

        Deterministic for a given manifest, fraction and seed; both lists are sorted. With
        ``category`` the split is made among that category's assets only (an unknown category
        is a ``KeyError`` naming the known ones).
        """
        if not 0.0 <= float(fraction) <= 1.0:
            raise InputError(f"AssetSource.get_test_split: fraction must be in [0, 1], "
                             f"got {fraction!r}")
        if category is None:
            ids = self.all_asset_ids
        else:
            ids = self.asset_ids_in(category)
            if not ids:
                raise KeyError(f"AssetSource {self.name!r} has no asset in category "
                               f"{category!r}; categories: {self.categories}")
        n_test = int(round(float(fraction) * len(ids)))
        rng = np.random.RandomState(seed)
        held = set(rng.choice(ids, size=n_test, replace=False).tolist()) if n_test else set()
        return [i for i in ids if i not in held], sorted(held)

    def asset_ids(self, categories: Iterable[str] | None = None, split: str | None = None,
                  fraction: float = 0.1, seed: int = 42) -> list[str]:
        """Sorted ids in any of ``categories`` (default: all), of ``split`` ``"train"`` or
        ``"test"`` (default: both). The split is made over the whole source (as MOVi-C–F hold
        out 10 % of all sorted ids with a fixed seed), then filtered, so the held-out assets of a
        category are the same whichever categories are asked for."""
        if split not in (None, "train", "test"):
            raise InputError(f"AssetSource.asset_ids: split must be 'train', 'test' or None, "
                             f"got {split!r}")
        ids = self.all_asset_ids
        if split is not None:
            train, test = self.get_test_split(fraction, seed)
            ids = test if split == "test" else train
        if categories is not None:
            wanted = {categories} if isinstance(categories, str) else set(categories)
            unknown = sorted(wanted - set(self.categories))
            if unknown:
                raise KeyError(f"AssetSource {self.name!r} has no categories {unknown}; "
                               f"categories: {self.categories}")
            ids = [i for i in ids if wanted & _categories_of(self.db[i])]
        return ids

    def _entry(self, asset_id: str) -> dict:
        try:
            return self.db[asset_id]
        except (KeyError, TypeError):
            close = difflib.get_close_matches(str(asset_id), self.all_asset_ids, n=3)
            hint = f"; did you mean {close}?" if close else ""
            shown = self.all_asset_ids[:20]
            more = f" (and {len(self.db) - 20} more)" if len(self.db) > 20 else ""
            raise KeyError(f"AssetSource {self.name!r} has no asset {asset_id!r}{hint} "
                           f"Known ids: {shown}{more}") from None

    def archive_path(self, asset_id: str) -> Path:
        """The asset's archive (of a source at a URL: its cached copy, downloaded if needed)."""
        entry = self._entry(asset_id)
        if self.remote is not None:
            return self.remote.archive(self.manifest, asset_id, entry)
        return self.data_dir / entry.get("path", f"{asset_id}.tar.gz")

    def fetch(self, asset_id: str) -> Path:
        """Extract the asset's archive (once; later calls reuse it) and return its folder.

        The folder name includes the archive's size and modification time, so a rebuilt
        archive is extracted afresh instead of reusing a stale copy.
        """
        self._entry(asset_id)
        archive = self.archive_path(asset_id)
        try:
            st = archive.stat()
            stamp = f"-{st.st_size:x}-{st.st_mtime_ns:x}"
        except OSError:
            stamp = ""  # missing: safe_extract raises the error naming the asset
        target = self.scratch_dir / (_safe_name(asset_id) + stamp)
        self._hold_scratch_dir()
        if not target.is_dir():
            if archive.is_file():
                remote_source.verify_checksums(archive, self.db[asset_id], f"asset {asset_id!r} ({archive})")
            safe_extract(archive, target, asset_id)
            self._extracted.append(target)
        return target

    def _hold_scratch_dir(self) -> None:
        """Take (once) a shared lock on the extraction folder, so that no other instance's
        ``close()`` deletes folders while this one may still use them."""
        if self._hold is not None:
            return
        while True:
            self.scratch_dir.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.scratch_dir, os.O_RDONLY)
            _flock(fd, shared=True)
            if os.fstat(fd).st_nlink > 0:  # not removed by a closer while we waited
                self._hold = fd
                return
            os.close(fd)

    def get_asset_kwargs(self, asset_id: str) -> dict:
        """The entry's ``kwargs`` with ``{asset_dir}/...`` resolved (extracts the archive)."""
        entry = self._entry(asset_id)
        return _resolve(entry["kwargs"], self.fetch(asset_id))

    def create(self, asset_id: str, add_metadata: bool = True, **kwargs):
        """A new asset (``FileBasedObject``, ``Texture``, ``kb.Character`` or ``kb.MotionClip``).

        ``kwargs`` override the manifest's (e.g. ``material=``, ``scale=``, ``position=``).
        With ``add_metadata`` (default) the asset's ``metadata`` holds the entry's metadata with
        ``asset_id`` and ``license`` added; with ``add_metadata=False`` nothing of the manifest is
        copied into it. A ``metadata=`` keyword is merged on top either way.
        """
        import kubric.core as core

        if not isinstance(add_metadata, bool):
            raise TypeError(f"AssetSource.create({asset_id!r}): add_metadata must be True or "
                            f"False, got {add_metadata!r}")
        entry = self._entry(asset_id)
        merged = self.get_asset_kwargs(asset_id)
        merged.update(kwargs)
        metadata = {}
        if add_metadata:
            metadata.update(entry["metadata"])
            metadata.update({"asset_id": asset_id, "license": entry["license"]})
        metadata.update(merged.pop("metadata", {}) or {})
        if entry["asset_type"] in ("Character", "MotionClip"):
            from kubric.assets import characters
            files = self.get_asset_kwargs(asset_id)
            make = (characters.create_character if entry["asset_type"] == "Character"
                    else characters.create_motion)
            return make(entry, files, metadata, {k: v for k, v in merged.items()
                                                 if k not in files})
        merged.setdefault("name", _safe_name(asset_id))
        if entry["asset_type"] == "FileBasedObject":
            return core.FileBasedObject(asset_id=asset_id, metadata=metadata, **merged)
        return core.Texture(metadata=metadata, **merged)

    def cleanup(self) -> None:
        """Delete every extracted archive of this source now, whoever else uses them (the source
        itself is kept). Prefer :meth:`close` when other workers may share the cache."""
        fd, self._hold = self._hold, None
        if fd is not None:
            os.close(fd)
        shutil.rmtree(self.scratch_dir, ignore_errors=True)
        self._extracted.clear()

    def close(self) -> None:
        """Release the extraction folder; delete the folders this instance extracted if no other
        instance (in any process) has it open. Idempotent; the source itself is kept."""
        fd, self._hold = self._hold, None
        if fd is None:
            self._extracted.clear()
            return
        try:
            if _flock(fd, shared=False, wait=False):  # nobody else holds it
                while self._extracted:
                    shutil.rmtree(self._extracted.pop(), ignore_errors=True)
                try:
                    self.scratch_dir.rmdir()  # only when nothing else is left in it
                except OSError:
                    pass
            self._extracted.clear()
        finally:
            os.close(fd)  # releases the lock

    def iter_entries(self, asset_ids: Iterable[str] | None = None):
        """Yield ``(id, entry)`` for ``asset_ids`` (default: all, sorted)."""
        for asset_id in (self.all_asset_ids if asset_ids is None else asset_ids):
            yield asset_id, self._entry(asset_id)


def _categories_of(entry: dict) -> set[str]:
    meta = entry["metadata"]
    cats = {str(meta["category"])} if meta.get("category") else set()
    extra = meta.get("categories")
    if isinstance(extra, (list, tuple)):
        cats.update(str(c) for c in extra if c)
    return cats


def _flock(fd: int, shared: bool, wait: bool = True) -> bool:
    """``flock`` ``fd`` shared or exclusive; returns False if ``wait`` is False and it is taken."""
    import fcntl

    mode = fcntl.LOCK_SH if shared else fcntl.LOCK_EX
    try:
        fcntl.flock(fd, mode if wait else mode | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


@contextlib.contextmanager
def build_lock(target: str | os.PathLike):
    """Hold an exclusive ``flock`` on ``<parent>/.<name>.build.lock`` while building ``target``,
    so that concurrent builders of one asset (test workers, ``generate --workers``) build it once:
    the others wait, then find it built. The kernel drops the lock when its holder dies."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(target.parent / f".{target.name}.build.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        _flock(fd, shared=False)
        yield
    finally:
        os.close(fd)  # releases the lock


def build_once(target: str | os.PathLike, build) -> Path:
    """Run ``build(tmp_dir)`` unless ``target/manifest.json`` exists, then rename tmp → target.

    The build happens in a temporary sibling folder, so a crash never leaves a half-built source
    and concurrent builders never see one; they also wait for each other (:func:`build_lock`)
    rather than build it twice. A build (seconds to minutes) says so on stderr when it starts
    and ends.
    """
    target = Path(target)
    if (target / "manifest.json").is_file():
        return target
    with build_lock(target):
        if (target / "manifest.json").is_file():  # another process built it while we waited
            return target
        start = time.monotonic()
        print(f"building the asset source {target.name} into {target.parent} (first use only)",
              file=sys.stderr, flush=True)
        built = build_staged(target, build, complete=lambda t: (t / "manifest.json").is_file())
        print(f"built {target.name} in {time.monotonic() - start:.0f} s", file=sys.stderr,
              flush=True)
    return built
