"""Poly Haven HDRIs → HDRI source (``kubric assets polyhaven``), through Poly Haven's public API.

API (base ``https://api.polyhaven.com``; every request carries a ``User-Agent``, as Poly Haven
asks):

- ``GET /assets?t=hdris`` → ``{asset_id: {"name", "authors": {name: role}, "categories": [...],
  "tags": [...], ...}}``;
- ``GET /files/{asset_id}`` → ``{"hdri": {"1k": {"hdr": {"url", "size", "md5"}, "exr": {...}},
  "2k": ...}, ...}``.

For each HDRI (sorted ids, the first ``limit``) the file at the chosen resolution and format is
downloaded with :func:`kubric.assets.download.fetch_file` (resumable ``.part`` file, size and MD5
checked), packed as a ``Texture`` asset with its licence (CC0, as every Poly Haven asset) and
authors, and deleted again once packed. An asset whose archive already holds the listed MD5 is not
downloaded again. Failures (no such resolution, a wrong size or checksum, a server error) are
reported per asset in ``conversion_report.json``; the others make up the source.
"""

from __future__ import annotations

import os
from pathlib import Path

from kubric.asset_tools.converter import read_entry
from kubric.asset_tools.hdri import image_size
from kubric.asset_tools.writer import dumps, package_texture, write_manifest
from kubric.assets.download import DownloadError, fetch_file, get_json
from kubric.errors import InputError

API_URL = "https://api.polyhaven.com"
NAME = "PolyHavenHDRIs"
VERSION = "1.0"
LICENSE = "CC0-1.0 (Poly Haven, https://polyhaven.com/license)"
FORMATS = ("hdr", "exr")
RESOLUTIONS = ("1k", "2k", "4k", "8k", "16k")
_DOWNLOADS = ".downloads"


def _pick_file(files: dict, asset_id: str, resolution: str, fmt: str) -> dict:
    hdri = files.get("hdri") if isinstance(files, dict) else None
    if not isinstance(hdri, dict) or resolution not in hdri:
        have = sorted(hdri) if isinstance(hdri, dict) else []
        raise InputError(f"{asset_id}: no {resolution!r} HDRI file (available: {have})")
    entry = hdri[resolution].get(fmt) if isinstance(hdri[resolution], dict) else None
    if not isinstance(entry, dict) or not all(k in entry for k in ("url", "size", "md5")):
        raise InputError(f"{asset_id}: no {fmt!r} file with url/size/md5 at {resolution!r}")
    return entry


def build_polyhaven(out_dir: str | os.PathLike, resolution: str = "2k", fmt: str = "hdr",
                    limit: int | None = None, base_url: str = API_URL,
                    progress: bool = True, name: str = NAME) -> dict:
    """Download Poly Haven HDRIs into the source ``out_dir``; returns the report
    ``{"name", "total", "converted", "reused", "skipped": [{"id", "source", "reason"}]}``."""
    if resolution not in RESOLUTIONS:
        raise InputError(f"resolution must be one of {list(RESOLUTIONS)}, got {resolution!r}")
    if fmt not in FORMATS:
        raise InputError(f"format must be one of {list(FORMATS)}, got {fmt!r}")
    if limit is not None and limit < 1:
        raise InputError(f"limit must be at least 1, got {limit!r}")
    base = base_url.rstrip("/")
    listing = get_json(f"{base}/assets?t=hdris")
    if not isinstance(listing, dict) or not all(isinstance(v, dict) for v in listing.values()):
        raise DownloadError(f"GET {base}/assets?t=hdris: expected a JSON object "
                            "{asset_id: {...}}")
    ids = sorted(listing)[:limit] if limit is not None else sorted(listing)
    out = Path(out_dir)
    downloads = out / _DOWNLOADS
    downloads.mkdir(parents=True, exist_ok=True)
    entries, skipped, reused = {}, [], 0
    todo = ids
    if progress:
        from tqdm import tqdm
        todo = tqdm(ids, desc="Poly Haven HDRIs", unit="hdri")
    for asset_id in todo:
        info = listing[asset_id]
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in asset_id)
        archive = out / f"{safe}.tar.gz"
        try:
            spec = _pick_file(get_json(f"{base}/files/{asset_id}"), asset_id, resolution, fmt)
            authors = sorted((info.get("authors") or {}).keys())
            meta = {"category": "hdri", "categories": list(info.get("categories") or []),
                    "tags": list(info.get("tags") or []),
                    "description": str(info.get("name") or asset_id), "authors": authors,
                    "source_url": f"https://polyhaven.com/a/{asset_id}", "md5": spec["md5"],
                    "file_size": int(spec["size"]), "resolution_name": resolution,
                    "source_file": spec["url"].rsplit("/", 1)[-1]}
            old = read_entry(archive) if archive.is_file() else None
            if old is not None and old.get("metadata", {}).get("md5") == spec["md5"]:
                entries[safe] = old
                reused += 1
                continue
            local = fetch_file(spec["url"], downloads / f"{safe}.{fmt}", size=int(spec["size"]),
                               md5=spec["md5"])
            meta["resolution"] = image_size(local)  # ValueError: a download that is no image
            lic = f"{LICENSE}; authors: {', '.join(authors) or 'unknown'}"
            entries[safe] = package_texture(safe, local, out, license=lic, metadata=meta)
            local.unlink()
        except (DownloadError, ValueError, KeyError, TypeError) as err:
            skipped.append({"id": safe, "source": f"{base}/files/{asset_id}",
                            "reason": f"{type(err).__name__}: {err}"})
    write_manifest(out / "manifest.json", name, VERSION, entries)
    return write_report(out, name, entries, skipped, reused, downloads)


def write_report(out: Path, name: str, entries: dict, skipped: list, reused: int,
                 downloads: Path) -> dict:
    """Write and return a download builder's ``conversion_report.json`` ({name, total,
    converted, reused, skipped (by id)}); remove ``downloads`` when nothing is left in it (a
    part file stays for the next run to resume)."""
    report = {"name": name, "total": len(entries) + len(skipped),
              "converted": len(entries) - reused, "reused": reused,
              "skipped": sorted(skipped, key=lambda s: s["id"])}
    (out / "conversion_report.json").write_text(dumps(report))
    if not any(downloads.iterdir()):
        downloads.rmdir()
    return report

