"""CC0 PBR material sets → a material source (``kubric assets materials polyhaven|ambientcg``).

The source layout is :mod:`kubric.assets.material_source`'s (``materials.json`` + one folder per
material). Every file goes through :func:`kubric.assets.download.fetch_file`: a ``.part`` file
resumed with HTTP ``Range``, checked against the listed size (and MD5 where the service lists
one) before it is renamed; a truncated or corrupted file is deleted and the material reported as
skipped, never listed. A material is written into ``materials.json`` only when all its files are
complete, so a re-run resumes where the last one stopped and skips what is done.

* **Poly Haven** (base ``https://api.polyhaven.com``): ``GET /assets?t=textures`` →
  ``{id: {"name", "authors": {name: role}, "categories", ...}}``; ``GET /files/{id}`` →
  ``{MAP: {RES: {FORMAT: {"url", "size", "md5"}}}}`` with the maps ``Diffuse`` (base colour),
  ``Rough``, ``Metal``, ``nor_gl`` (OpenGL normal), ``Displacement``; format ``jpg``, else
  ``png``. Size and MD5 checked.
* **ambientCG** (base ``https://ambientCG.com/api/v2``): ``GET
  /full_json?type=Material&include=downloadData&limit=N`` → ``{"foundAssets": [{"assetId",
  "displayName", "downloadFolders": {"default": {"downloadFiletypeCategories": {"zip":
  {"downloads": [{"attribute": "1K-JPG", "downloadLink", "fileName", "size"}]}}}}}]}``; the ZIP
  holds ``{id}_{RES}_Color.jpg``, ``_Roughness``, ``_Metalness``, ``_NormalGL``,
  ``_Displacement``. Size checked, and every member's CRC (``zipfile.testzip``): ambientCG lists
  no checksum.

Both publish their sets under CC0 1.0; the licence, the authors (Poly Haven) or publisher and the
page of each set are recorded per material and carried into every scene that uses it.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

from kubric.asset_tools.polyhaven import write_report
from kubric.asset_tools.writer import dumps
from kubric.assets.download import DownloadError, fetch_file, get_json, md5_of
from kubric.assets.material_source import MANIFEST
from kubric.errors import InputError

SERVICES = ("polyhaven", "ambientcg")
API_URLS = {"polyhaven": "https://api.polyhaven.com", "ambientcg": "https://ambientCG.com/api/v2"}
RESOLUTIONS = ("1k", "2k", "4k", "8k")
LICENSES = {"polyhaven": "CC0-1.0 (Poly Haven, https://polyhaven.com/license)",
            "ambientcg": "CC0-1.0 (ambientCG, https://docs.ambientcg.com/license/)"}
#: our map name → Poly Haven's map key / ambientCG's file suffix
POLYHAVEN_MAPS = {"base_color": "Diffuse", "roughness": "Rough", "metallic": "Metal",
                  "normal": "nor_gl", "displacement": "Displacement"}
AMBIENTCG_MAPS = {"base_color": "Color", "roughness": "Roughness", "metallic": "Metalness",
                  "normal": "NormalGL", "displacement": "Displacement"}
_DOWNLOADS = ".downloads"


def _safe(asset_id: str) -> str:
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in str(asset_id))


def _polyhaven_entry(base, asset_id, info, resolution, out) -> dict:
    files = get_json(f"{base}/files/{asset_id}")
    safe, maps, listed = _safe(asset_id), {}, {}
    for ours, key in POLYHAVEN_MAPS.items():
        by_res = files.get(key) if isinstance(files, dict) else None
        if not isinstance(by_res, dict) or resolution not in by_res:
            if ours == "base_color":
                have = sorted(by_res) if isinstance(by_res, dict) else []
                raise InputError(f"{asset_id}: no {resolution!r} base colour map (available: "
                                 f"{have})")
            continue
        spec = by_res[resolution].get("jpg") or by_res[resolution].get("png")
        if not isinstance(spec, dict) or not all(k in spec for k in ("url", "size", "md5")):
            raise InputError(f"{asset_id}: map {key!r} at {resolution!r} has no jpg/png file "
                             "with url/size/md5")
        suffix = Path(spec["url"]).suffix.lower() or ".jpg"
        rel = f"{safe}/{safe}_{ours}{suffix}"
        fetch_file(spec["url"], out / rel, size=int(spec["size"]), md5=spec["md5"])
        maps[ours], listed[rel] = rel, {"size": int(spec["size"]), "md5": spec["md5"]}
    authors = sorted((info.get("authors") or {}).keys())
    return {"maps": maps, "files": listed, "license": LICENSES["polyhaven"],
            "attribution": f"Poly Haven; authors: {', '.join(authors) or 'unknown'}",
            "source_url": f"https://polyhaven.com/a/{asset_id}",
            "description": str(info.get("name") or asset_id)}


def _ambientcg_entry(asset, resolution, out, downloads) -> dict:
    asset_id = str(asset["assetId"])
    attribute = f"{resolution.upper()}-JPG"
    try:
        zips = asset["downloadFolders"]["default"]["downloadFiletypeCategories"]["zip"]
        spec = next(d for d in zips["downloads"] if d.get("attribute") == attribute)
    except (KeyError, TypeError, StopIteration):
        raise InputError(f"{asset_id}: no {attribute} ZIP download listed") from None
    safe = _safe(asset_id)
    archive = fetch_file(spec["downloadLink"], downloads / f"{safe}_{attribute}.zip",
                         size=int(spec["size"]))
    try:
        with zipfile.ZipFile(archive) as zf:
            bad = zf.testzip()
            if bad is not None:
                raise DownloadError(f"{spec['downloadLink']}: member {bad!r} fails its CRC")
            names = zf.namelist()
            maps, listed = {}, {}
            for ours, suffix in AMBIENTCG_MAPS.items():
                member = next((n for n in names if Path(n).stem.endswith(f"_{suffix}")), None)
                if member is None:
                    if ours == "base_color":
                        raise InputError(f"{asset_id}: the ZIP has no *_{suffix} image")
                    continue
                rel = f"{safe}/{safe}_{ours}{Path(member).suffix.lower()}"
                (out / rel).parent.mkdir(parents=True, exist_ok=True)
                (out / rel).write_bytes(zf.read(member))
                maps[ours] = rel
                listed[rel] = {"size": (out / rel).stat().st_size, "md5": md5_of(out / rel)}
    except zipfile.BadZipFile as err:
        raise DownloadError(f"{spec['downloadLink']}: not a ZIP file ({err})") from None
    finally:
        archive.unlink(missing_ok=True)
    return {"maps": maps, "files": listed, "license": LICENSES["ambientcg"],
            "attribution": "ambientCG (Lennart Demes)",
            "source_url": f"https://ambientcg.com/view?id={asset_id}",
            "description": str(asset.get("displayName") or asset_id)}


def _complete(entry: dict, out: Path) -> bool:
    return all((out / rel).is_file() and (out / rel).stat().st_size == info["size"]
               and md5_of(out / rel) == info["md5"] for rel, info in entry["files"].items())


def build_materials(service: str, out_dir, resolution: str = "1k", limit: int | None = None,
                    base_url: str | None = None, name: str | None = None) -> dict:
    """Download ``service``'s CC0 PBR sets into the material source ``out_dir``; returns the
    report ``{"name", "total", "converted", "reused", "skipped": [{"id", "reason"}]}``."""
    if service not in SERVICES:
        raise InputError(f"material service {service!r}; allowed: {list(SERVICES)}")
    if resolution not in RESOLUTIONS:
        raise InputError(f"resolution must be one of {list(RESOLUTIONS)}, got {resolution!r}")
    if limit is not None and limit < 1:
        raise InputError(f"limit must be at least 1, got {limit!r}")
    base = (base_url or API_URLS[service]).rstrip("/")
    out = Path(out_dir)
    downloads = out / _DOWNLOADS
    downloads.mkdir(parents=True, exist_ok=True)
    old = {}
    if (out / MANIFEST).is_file():
        old = json.loads((out / MANIFEST).read_text()).get("materials", {})
    if service == "polyhaven":
        listing = get_json(f"{base}/assets?t=textures")
        if not isinstance(listing, dict):
            raise DownloadError(f"GET {base}/assets?t=textures: expected a JSON object")
        items = [(k, listing[k]) for k in sorted(listing)][:limit]
    else:
        query = "type=Material&include=downloadData" + (f"&limit={limit}" if limit else "")
        found = get_json(f"{base}/full_json?{query}")
        assets = found.get("foundAssets") if isinstance(found, dict) else None
        if not isinstance(assets, list):
            raise DownloadError(f"GET {base}/full_json?{query}: expected {{\"foundAssets\": [...]}}")
        items = sorted(((str(a.get("assetId")), a) for a in assets), key=lambda x: x[0])[:limit]
    entries, skipped, reused = {}, [], 0
    for asset_id, info in items:
        safe = _safe(asset_id)
        if safe in old and _complete(old[safe], out):
            entries[safe] = old[safe]
            reused += 1
            continue
        try:
            entries[safe] = (_polyhaven_entry(base, asset_id, info, resolution, out)
                             if service == "polyhaven" else
                             _ambientcg_entry(info, resolution, out, downloads))
        except (DownloadError, InputError, KeyError, TypeError, ValueError) as err:
            skipped.append({"id": safe, "reason": f"{type(err).__name__}: {err}"})
    name = name or {"polyhaven": "PolyHavenMaterials", "ambientcg": "AmbientCGMaterials"}[service]
    (out / MANIFEST).write_text(dumps({"name": name, "version": "1.0", "service": service,
                                       "resolution": resolution, "materials": entries}))
    return write_report(out, name, entries, skipped, reused, downloads)
