"""Objaverse 1.0 → asset source (``kubric assets objaverse``), over plain HTTP.

Objaverse 1.0 (Deitke et al. 2023; ~800k Sketchfab models, each under its author's Creative
Commons licence) is served as files of the Hugging Face dataset ``allenai/objaverse`` (base
``https://huggingface.co/datasets/allenai/objaverse/resolve/main``), in the layout the
``objaverse`` package reads and caches under ``~/.objaverse/hf-objaverse-v1/``:

* ``object-paths.json.gz``: ``{uid: "glbs/000-023/<uid>.glb"}`` (the GLB's path);
* ``metadata/<chunk>.json.gz`` (chunk = the middle part of the GLB's path, ``000-000`` …
  ``000-159``): ``{uid: Sketchfab's model record}`` with ``name``, ``viewerUrl``, ``user``
  (``displayName``, ``username``, ``profileUrl``), ``license`` (``by``, ``by-sa``, ``by-nd``,
  ``by-nc``, ``by-nc-sa``, ``by-nc-nd``, ``cc0``), ``categories``, ``tags``, ...;
* ``lvis-annotations.json.gz``: ``{LVIS category: [uid, ...]}`` (47k objects, 1,156 categories);
* ``glbs/<chunk>/<uid>.glb``: the model.

Nothing here imports the ``objaverse`` package: the same files are fetched into the same layout
(``--download-dir``, default ``OUT/.objaverse``; point it at ``~/.objaverse`` to reuse what the
package downloaded). Each file goes through :func:`kubric.assets.download.fetch_file`: a
``.part`` file resumed with HTTP ``Range``, renamed into place only after the checks — the size
and SHA-256 the Hub announces for a Git LFS file (``X-Linked-Size`` / ``X-Linked-Etag`` of a
``HEAD`` request to the ``resolve`` URL, answered with a redirect) and the content itself (a
``.json.gz`` must decompress whole, its CRC included; a ``.glb`` must hold the length its header
declares). A cut or corrupted transfer is refused (reported per object) and fetched again by
the next run, never left where a complete file is expected. Files already in the layout are
used without a request.

Selection: ``uids`` and / or LVIS ``categories``, then ``licenses``, then the first ``count``
in the order of the GLB paths (so licence filtering reads as few metadata chunks as possible).
Each selected GLB is converted by :mod:`kubric.asset_tools.converter` (PBR materials kept,
:mod:`kubric.asset_tools.gltf_pbr`), scaled so that its largest side is ``max_extent`` metres
(Objaverse has no common unit), with collision hulls and mass at density 1. The manifest entry's
``license`` is the SPDX id, the licence URL and the attribution the licence asks for (title,
author, source URL); ``metadata`` holds the LVIS ``category``, ``author``, ``source_url``,
``objaverse_license`` and ``sha256``.
"""

from __future__ import annotations

import difflib
import gzip
import json
import os
import struct
import urllib.error
import urllib.request
from pathlib import Path

from kubric.asset_tools.converter import ConvertJob, convert_jobs
from kubric.assets.download import USER_AGENT, DownloadError, fetch_file, sha256_of
from kubric.errors import InputError, UsageError

NAME = "Objaverse"
VERSION = "1.0"
BASE_URL = "https://huggingface.co/datasets/allenai/objaverse/resolve/main"
LAYOUT = "hf-objaverse-v1"
OBJECT_PATHS = "object-paths.json.gz"
LVIS = "lvis-annotations.json.gz"
#: Objaverse's (Sketchfab's) licence slug → (SPDX id, licence URL)
LICENSES = {
    "cc0": ("CC0-1.0", "https://creativecommons.org/publicdomain/zero/1.0/"),
    "by": ("CC-BY-4.0", "https://creativecommons.org/licenses/by/4.0/"),
    "by-sa": ("CC-BY-SA-4.0", "https://creativecommons.org/licenses/by-sa/4.0/"),
    "by-nd": ("CC-BY-ND-4.0", "https://creativecommons.org/licenses/by-nd/4.0/"),
    "by-nc": ("CC-BY-NC-4.0", "https://creativecommons.org/licenses/by-nc/4.0/"),
    "by-nc-sa": ("CC-BY-NC-SA-4.0", "https://creativecommons.org/licenses/by-nc-sa/4.0/"),
    "by-nc-nd": ("CC-BY-NC-ND-4.0", "https://creativecommons.org/licenses/by-nc-nd/4.0/"),
}
DEFAULT_MAX_EXTENT = 1.0


def parse_licenses(text) -> set[str] | None:
    """``"cc0,cc-by"`` → ``{"cc0", "by"}``; accepts Objaverse's slugs (``by-nc``), ``cc-``
    prefixed ones and SPDX ids (``CC-BY-4.0``), case-insensitive. None / empty → None (all)."""
    if text is None or (isinstance(text, str) and not text.strip()):
        return None
    items = text.split(",") if isinstance(text, str) else list(text)
    by_spdx = {spdx.lower(): slug for slug, (spdx, _) in LICENSES.items()}
    out = set()
    for item in (str(i).strip().lower() for i in items):
        slug = by_spdx.get(item, item[3:] if item.startswith("cc-") else item)
        if slug not in LICENSES:
            raise UsageError(f"unknown licence {item!r}; allowed: "
                             f"{sorted({f'cc-{s}' if s != 'cc0' else s for s in LICENSES})}")
        out.add(slug)
    return out


class _NoRedirect(urllib.request.HTTPRedirectHandler):
    def redirect_request(self, *args, **kwargs):
        return None


def announced(url: str) -> tuple[int | None, str | None]:
    """(size, SHA-256) the server announces for ``url``: a ``HEAD`` request, redirects not
    followed; the Hub's ``X-Linked-Size`` / ``X-Linked-Etag`` (Git LFS files: the etag is the
    content's SHA-256), else a direct answer's ``Content-Length`` and no checksum."""
    opener = urllib.request.build_opener(_NoRedirect)
    req = urllib.request.Request(url, method="HEAD", headers={"User-Agent": USER_AGENT})
    redirected = False
    try:
        resp = opener.open(req, timeout=60)  # noqa: S310 - http(s) only (fetch_file checks)
        headers = resp.headers
        resp.close()
    except urllib.error.HTTPError as err:
        if err.code not in (301, 302, 303, 307, 308):
            raise DownloadError(f"HEAD {url}: HTTP {err.code} {err.reason}") from None
        headers, redirected = err.headers, True
    except (urllib.error.URLError, OSError) as err:
        raise DownloadError(f"HEAD {url}: {err}") from None
    # a redirect's own Content-Length is its body's, not the file's
    size = headers.get("X-Linked-Size") or (None if redirected else headers.get("Content-Length"))
    etag = (headers.get("X-Linked-Etag") or "").strip().strip('"').removeprefix("W/").strip('"')
    sha = etag.lower() if len(etag) == 64 and all(c in "0123456789abcdefABCDEF" for c in etag) \
        else None
    return (int(size) if size and size.isdigit() else None), sha


def check_whole(path: Path) -> None:
    """Content check of a downloaded layout file: ``.gz`` decompresses whole (length and CRC
    trailer), ``.glb`` holds the length its header declares."""
    name = Path(path).name.removesuffix(".part")
    if name.endswith(".gz"):
        with gzip.open(path, "rb") as fh:
            while fh.read(1 << 20):
                pass
    elif name.endswith(".glb"):
        with open(path, "rb") as fh:
            head = fh.read(12)
        if len(head) < 12 or head[:4] != b"glTF":
            raise ValueError("no GLB header")
        declared = struct.unpack("<I", head[8:12])[0]
        if declared != os.path.getsize(path):
            raise ValueError(f"GLB header declares {declared} bytes, the file has "
                             f"{os.path.getsize(path)}")


def fetch(base_url: str, rel: str, cache: Path) -> Path:
    """The layout file ``rel`` in ``cache`` (downloaded and checked if missing)."""
    dest = cache / rel
    if dest.is_file():
        return dest
    url = f"{base_url.rstrip('/')}/{rel}"
    size, sha = announced(url)
    return fetch_file(url, dest, size=size, sha256=sha, check=check_whole)


def read_gz_json(path: Path):
    try:
        with gzip.open(path, "rb") as fh:
            return json.loads(fh.read())
    except (OSError, EOFError, json.JSONDecodeError) as err:
        raise InputError(f"{str(path)!r} is not gzipped JSON: {err}") from None


def _select_candidates(paths: dict, lvis: dict, uids, categories) -> list[str]:
    chosen = None
    if uids:
        unknown = [u for u in uids if u not in paths]
        if unknown:
            raise UsageError(f"{len(unknown)} uid(s) not in {OBJECT_PATHS}, e.g. {unknown[0]!r}")
        chosen = set(uids)
    if categories:
        bad = [c for c in categories if c not in lvis]
        if bad:
            near = difflib.get_close_matches(bad[0], list(lvis), n=5)
            raise UsageError(f"unknown LVIS category {bad[0]!r}; close: {near} (all: the keys "
                             f"of {LVIS})")
        in_cats = {u for c in categories for u in lvis[c] if u in paths}
        chosen = in_cats if chosen is None else chosen & in_cats
    if chosen is None:
        chosen = set(paths)
    return sorted(chosen, key=lambda u: (paths[u], u))


def attribution(uid: str, record: dict) -> dict:
    """The licence text and attribution fields of one object (its Sketchfab record)."""
    slug = str(record.get("license") or "")
    if slug not in LICENSES:
        raise InputError(f"{uid}: licence {slug!r} is not one of {sorted(LICENSES)}")
    spdx, url = LICENSES[slug]
    user = record.get("user") or {}
    author = str(user.get("displayName") or user.get("username") or "unknown author")
    title = str(record.get("name") or uid)
    source = str(record.get("viewerUrl") or f"https://sketchfab.com/3d-models/{uid}")
    return {"license": f"{spdx} ({url}); \"{title}\" by {author}, {source}",
            "objaverse_license": slug, "license_url": url, "author": author,
            "author_url": str(user.get("profileUrl") or ""), "title": title,
            "source_url": source}


def select(base_url: str, cache: Path, uids=None, categories=None, licenses=None,
           count: int | None = None) -> tuple[list[dict], dict]:
    """The selected objects ``[{"uid", "path", "record", "category"}]`` (in GLB-path order) and
    ``{uid: LVIS category}``; reads (and downloads) only the metadata chunks it needs."""
    if count is not None and count < 1:
        raise UsageError(f"count must be at least 1, got {count!r}")
    if not uids and not categories and count is None:
        raise UsageError("select objects with uids, LVIS categories or a count (refusing to "
                         "convert all of Objaverse)")
    paths = read_gz_json(fetch(base_url, OBJECT_PATHS, cache))
    lvis = read_gz_json(fetch(base_url, LVIS, cache))
    if not isinstance(paths, dict) or not isinstance(lvis, dict):
        raise InputError(f"{OBJECT_PATHS} and {LVIS} must each hold a JSON object")
    category_of = {u: c for c, members in lvis.items() for u in members}
    chunks: dict[str, dict] = {}
    picked = []
    for uid in _select_candidates(paths, lvis, uids, categories):
        rel = paths[uid]
        chunk = rel.split("/")[1] if rel.count("/") >= 2 else ""
        if chunk not in chunks:
            chunks[chunk] = read_gz_json(fetch(base_url, f"metadata/{chunk}.json.gz", cache))
        record = chunks[chunk].get(uid)
        if record is None:
            raise InputError(f"{uid}: no record in metadata/{chunk}.json.gz")
        if licenses is not None and record.get("license") not in licenses:
            continue
        picked.append({"uid": uid, "path": rel, "record": record,
                       "category": category_of.get(uid)})
        if count is not None and len(picked) == count:
            break
    return picked, category_of


def build_objaverse(out_dir, uids=None, categories=None, licenses=None, count=None,
                    download_dir=None, base_url: str = BASE_URL, workers: int | None = None,
                    max_extent: float = DEFAULT_MAX_EXTENT, progress: bool = True,
                    name: str = NAME) -> dict:
    """Select, download and convert Objaverse objects into the source ``out_dir`` (see the
    module doc); returns the conversion report (failed downloads are its ``skipped``)."""
    out = Path(out_dir)
    cache = Path(download_dir).expanduser() if download_dir else out / ".objaverse"
    cache = cache / LAYOUT
    wanted = parse_licenses(licenses) if not isinstance(licenses, set) else licenses
    picked, _ = select(base_url, cache, uids, categories, wanted, count)
    if not picked:
        raise InputError("no Objaverse object matches the selection")
    jobs, errors = [], []
    items = picked
    if progress:
        from tqdm import tqdm
        items = tqdm(picked, desc="downloading Objaverse", unit="glb")
    for item in items:
        uid, rel = item["uid"], item["path"]
        try:
            credit = attribution(uid, item["record"])
            glb = fetch(base_url, rel, cache)
        except (DownloadError, InputError) as err:
            errors.append({"id": uid, "source": f"{base_url.rstrip('/')}/{rel}",
                           "reason": str(err)})
            continue
        meta = {k: v for k, v in credit.items() if k != "license"}
        meta.update({"description": f"{credit['title']} (Objaverse {uid})",
                     "collection": "Objaverse 1.0", "sha256": sha256_of(glb),
                     "sketchfab_categories": [str(c.get("name")) for c in
                                              item["record"].get("categories") or []
                                              if isinstance(c, dict)]})
        if item["category"]:
            meta["category"] = item["category"]
        jobs.append(ConvertJob(uid, str(glb), credit["license"], metadata=meta,
                               max_extent=max_extent))
    return convert_jobs(jobs, out, name, VERSION, workers=workers, progress=progress,
                        skipped=errors)
