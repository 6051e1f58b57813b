"""Google Scanned Objects (GSO) → asset source (``kubric assets gso``).

GSO is distributed through Gazebo Fuel (collection "Scanned Objects by Google Research", owner
``GoogleResearch``, licence CC-BY 4.0), one zip per object holding ``meshes/model.obj`` +
``model.mtl``, ``materials/textures/texture.png``, ``model.config``, ``model.sdf``,
``metadata.pbtxt`` and ``thumbnails/``. Meshes are in metres, z up.

Input: a folder of such zips and/or unpacked model folders (any depth). Categories and
descriptions come from the **catalogue**: the model listing of Fuel's public API
(``GET {base}/1.0/models?page=N&per_page=100&q=collections:<collection>``; each page is a JSON
list of models with ``name``, ``description``, ``categories``, ``filesize``, ``thumbnail_url``,
...; the pages end with an empty list, an empty body or 404), saved as one JSON list. Where the
catalogue has no entry, ``model.config``'s ``<description>`` and the category fields of
``metadata.pbtxt`` are used. ``download_gso`` fetches the listing and every zip
(``{base}/1.0/{owner}/models/{name}.zip``) resumably; tests run the same code against a local
server, only ``base_url`` differs.

Each zip is extracted with :func:`~kubric.assets.archive.safe_extract_zip` into a scratch folder
inside the output folder (removed at the end), checked (the OBJ exists, its texture is a
readable image) and converted by :mod:`kubric.asset_tools.converter` (texture kept, watertight copy,
convex decomposition, mass and inertia at density 1). A model that fails any step is listed with
its reason in ``conversion_report.json``; the others are converted.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import urllib.parse
from pathlib import Path

from kubric.asset_tools.converter import ConvertJob, convert_jobs
from kubric.assets.archive import safe_extract_zip
from kubric.assets.download import DownloadError, fetch_file, get_json
from kubric.errors import InputError

NAME = "GSO"
VERSION = "1.0"
LICENSE = "CC-BY-4.0 (Google Scanned Objects, Google LLC; https://creativecommons.org/licenses/by/4.0/)"
FUEL_URL = "https://fuel.gazebosim.org"
OWNER = "GoogleResearch"
COLLECTION = "Scanned Objects by Google Research"
CATALOGUE_NAME = "gso_catalogue.json"
PER_PAGE = 100
_SCRATCH = ".gso_unpacked"


def listing_url(base_url: str, page: int, per_page: int = PER_PAGE,
                collection: str = COLLECTION) -> str:
    """URL of one page of the collection's model listing (pages count from 1)."""
    query = urllib.parse.quote(f"collections:{collection}")
    return f"{base_url.rstrip('/')}/1.0/models?page={page}&per_page={per_page}&q={query}"


def model_zip_url(base_url: str, name: str, owner: str = OWNER) -> str:
    """URL of one model's zip."""
    return (f"{base_url.rstrip('/')}/1.0/{urllib.parse.quote(owner)}/models/"
            f"{urllib.parse.quote(name)}.zip")


def download_catalogue(base_url: str, dest: str | os.PathLike, max_pages: int = 10000) -> list:
    """Fetch every listing page into one JSON list at ``dest`` (written atomically)."""
    models: list = []
    for page in range(1, max_pages + 1):
        url = listing_url(base_url, page)
        got = get_json(url, missing_ok=True)
        if not got:
            break
        if not isinstance(got, list) or not all(isinstance(m, dict) and "name" in m for m in got):
            raise DownloadError(f"GET {url}: expected a JSON list of models with a 'name', got "
                                f"{str(got)[:120]!r}")
        models.extend(got)
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(dest.name + ".tmp")
    tmp.write_text(json.dumps(models, indent=1, sort_keys=True))
    os.replace(tmp, dest)
    return models


def download_gso(src_dir: str | os.PathLike, base_url: str = FUEL_URL, limit: int | None = None,
                 progress: bool = True) -> tuple[list, list]:
    """Download the catalogue (unless ``src_dir`` has one) and the zips into ``src_dir``.

    Zips already there are kept; a cut transfer resumes from its ``.part`` file. Returns
    ``(catalogue, errors)`` with ``errors`` = ``[{"id", "source", "reason"}]`` per failed model.
    """
    src = Path(src_dir)
    src.mkdir(parents=True, exist_ok=True)
    cat_path = src / CATALOGUE_NAME
    catalogue = json.loads(cat_path.read_text()) if cat_path.is_file() else \
        download_catalogue(base_url, cat_path)
    names = sorted({str(m["name"]) for m in catalogue})
    if limit is not None:
        names = names[:limit]
    if progress:
        from tqdm import tqdm
        names = tqdm(names, desc="downloading GSO", unit="zip")
    errors = []
    for name in names:
        url = model_zip_url(base_url, name)
        try:
            fetch_file(url, src / f"{_safe(name)}.zip")
        except DownloadError as err:
            errors.append({"id": _safe(name), "source": url, "reason": str(err)})
    return catalogue, errors


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def load_catalogue(path: str | os.PathLike) -> dict[str, dict]:
    """``{asset id: {"description", "categories"}}`` from a saved listing (a list of models, or
    a list of pages, each a list of models)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise InputError(f"GSO catalogue {str(path)!r} is not readable JSON: {err}") from None
    if isinstance(data, list) and data and all(isinstance(p, list) for p in data):
        data = [m for page in data for m in page]
    if not isinstance(data, list) or not all(isinstance(m, dict) and "name" in m for m in data):
        raise InputError(f"GSO catalogue {str(path)!r}: expected a JSON list of models, each with "
                         "'name' (the Fuel models API listing)")
    out = {}
    for model in data:
        cats = model.get("categories") or []
        out[_safe(str(model["name"]))] = {
            "description": str(model.get("description") or ""),
            "categories": [str(c) for c in cats] if isinstance(cats, list) else [str(cats)]}
    return out


def find_models(src_dir: str | os.PathLike) -> dict[str, Path]:
    """``{asset id: zip file or unpacked model folder}`` under ``src_dir`` (sorted)."""
    src = Path(src_dir)
    if not src.is_dir():
        raise FileNotFoundError(f"GSO folder {str(src)!r} does not exist")
    found: dict[str, Path] = {}
    candidates = [p for p in src.rglob("*.zip") if p.is_file()]
    candidates += [p.parent.parent for p in src.rglob("meshes/model.obj")
                   if _SCRATCH not in p.parts]
    for path in sorted(candidates):
        asset_id = _safe(path.stem if path.suffix == ".zip" else path.name)
        if asset_id in found:
            if found[asset_id].suffix == ".zip" or path.suffix != ".zip":
                continue  # an unpacked folder next to its own zip: keep one
        found[asset_id] = path
    return dict(sorted(found.items()))


_CONFIG_DESC = re.compile(r"<description>(.*?)</description>", re.S)
_PBTXT_CATEGORY = re.compile(r'(?:categor(?:y|ies)\s*(?::\s*|\{[^}]*?\b(?:first|value|name)\s*:\s*))'
                             r'"([^"]*)"', re.I)
_PBTXT_KEYED = re.compile(r'key\s*:\s*"categor(?:y|ies)"\s*value\s*:\s*"([^"]*)"', re.I)


def read_model_metadata(model_dir: Path) -> dict:
    """Description (``model.config``) and categories (``metadata.pbtxt``) of an unpacked model."""
    meta: dict = {}
    config = model_dir / "model.config"
    if config.is_file():
        match = _CONFIG_DESC.search(config.read_text(errors="replace"))
        if match and match.group(1).strip():
            meta["description"] = " ".join(match.group(1).split())
    pbtxt = model_dir / "metadata.pbtxt"
    if pbtxt.is_file():
        text = pbtxt.read_text(errors="replace")
        cats = _PBTXT_KEYED.findall(text) + _PBTXT_CATEGORY.findall(text)
        cats = [c for c in dict.fromkeys(cats) if c]
        if cats:
            meta["categories"] = cats
    return meta


def check_texture(obj_path: Path, copy_missing: bool = True) -> None:
    """Make the OBJ's textures findable and readable: each ``map_Kd`` of its MTL files must be an
    image. GSO keeps it in ``materials/textures/`` while the MTL names it next to the mesh, so
    with ``copy_missing`` a missing one is copied there from that folder. Raises ``ValueError``
    naming the file."""
    from PIL import Image, UnidentifiedImageError

    folder = obj_path.parent
    for line in obj_path.read_text(errors="replace").splitlines():
        tok = line.split(maxsplit=1)
        if len(tok) != 2 or tok[0] != "mtllib":
            continue
        mtl = folder / tok[1].strip()
        if not mtl.is_file():
            raise InputError(f"material file {tok[1].strip()!r} named by {obj_path.name} is missing")
        for mline in mtl.read_text(errors="replace").splitlines():
            mt = mline.split()
            if not mt or mt[0] != "map_Kd":
                continue
            rel = mt[-1]
            tex = folder / rel
            if not tex.is_file():
                alt = folder.parent / "materials" / "textures" / Path(rel).name
                if not (copy_missing and alt.is_file()):
                    raise InputError(f"texture {rel!r} named by {mtl.name} is missing")
                shutil.copyfile(alt, tex)
            try:
                with Image.open(tex) as im:
                    im.verify()
            except (UnidentifiedImageError, OSError, SyntaxError) as err:
                raise InputError(f"texture {rel!r} is not a readable image ({err})") from None


def prepare_model(asset_id: str, path: Path, scratch: Path) -> tuple[Path, dict]:
    """Unpack (zip) and check one model; returns ``(meshes/model.obj, metadata from its files)``."""
    if path.suffix == ".zip":
        model_dir = safe_extract_zip(path, scratch / asset_id, asset_id)
        inner = [p.parent.parent for p in model_dir.rglob("meshes/model.obj")]
        if len(inner) == 1:
            model_dir = inner[0]
    else:
        model_dir = scratch / asset_id
        shutil.copytree(path, model_dir, symlinks=True)
        links = [p for p in model_dir.rglob("*") if p.is_symlink()]
        if links:
            raise InputError(f"model folder holds symbolic link {str(links[0])!r}; links are refused")
    obj = model_dir / "meshes" / "model.obj"
    if not obj.is_file():
        raise InputError("no meshes/model.obj in the model")
    check_texture(obj)
    return obj, read_model_metadata(model_dir)


def build_gso(src_dir: str | os.PathLike, out_dir: str | os.PathLike,
              catalogue: str | os.PathLike | None = None, workers: int | None = None,
              limit: int | None = None, progress: bool = True, download: bool = False,
              base_url: str = FUEL_URL, name: str = NAME) -> dict:
    """Convert the GSO models under ``src_dir`` into the source ``out_dir``; returns the report.

    ``catalogue``: the saved model listing (default: ``src_dir/gso_catalogue.json`` if present).
    ``download``: first fetch the listing and the zips from ``base_url`` into ``src_dir``.
    """
    src = Path(src_dir)
    errors: list = []
    if download:
        _, errors = download_gso(src, base_url, limit=limit, progress=progress)
    if catalogue is None and (src / CATALOGUE_NAME).is_file():
        catalogue = src / CATALOGUE_NAME
    listing = load_catalogue(catalogue) if catalogue is not None else {}
    models = find_models(src)
    failed = {e["id"] for e in errors}
    ids = [i for i in models if i not in failed]
    if limit is not None:
        ids = ids[:limit]
    if not ids and not errors:
        raise InputError(f"no GSO models (zips or folders with meshes/model.obj) under {str(src)!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    scratch = out / _SCRATCH
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir()
    jobs = []
    try:
        for asset_id in ids:
            try:
                obj, own = prepare_model(asset_id, models[asset_id], scratch)
            except Exception as err:  # noqa: BLE001 - every failure becomes a report line
                errors.append({"id": asset_id, "source": str(models[asset_id]),
                               "reason": f"{type(err).__name__}: {err}"})
                continue
            info = {**own, **{k: v for k, v in listing.get(asset_id, {}).items() if v}}
            cats = info.get("categories") or []
            meta = {"description": info.get("description", ""), "categories": cats,
                    "collection": "Google Scanned Objects",
                    "catalogue": "fuel listing" if asset_id in listing else "model files"}
            if cats:
                meta["category"] = cats[0]
            jobs.append(ConvertJob(asset_id, str(obj), LICENSE, metadata=meta))
        return convert_jobs(jobs, out, name, VERSION, workers=workers, progress=progress,
                            skipped=errors)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
