"""HDRI sources: a folder of ``.hdr`` / ``.exr`` environment maps → Texture assets.

Each image becomes an asset ``{"asset_type": "Texture", "kwargs": {"filename":
"{asset_dir}/texture.exr", "mapping": "environment"}}``: equirectangular, usable by the renderer
as world lighting and as the texture of a dome backdrop. The default source is built from the
CC0 world HDRIs that the ``bpy`` wheel ships (``bpy/<version>/datafiles/studiolights/world``),
found without importing bpy.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

from kubric.asset_tools.writer import package_texture, write_manifest
from kubric.assets.asset_source import AssetSource, build_once, cache_dir
from kubric.errors import InputError

NAME_DEFAULT = "HDRIs"
VERSION = "1.2"  # 1.1: each archive's sha256 in the manifest; 1.2: without studio.exr
#: bpy's world HDRIs left out of the default source: ``studio`` is a lighting rig (a dark room
#: with soft boxes), not a background — ground-projected it gives MOVi-C–F black surroundings
#: and radial streaks on the floor; the seven left are outdoor and interior scenes
NOT_BACKGROUNDS = ("studio",)
EXTENSIONS = (".hdr", ".exr")
BPY_WORLD_LICENSE = ("CC0-1.0 (Greg Zaal, Poly Haven; shipped with Blender in "
                     "datafiles/studiolights/world)")


EXR_MAGIC = b"\x76\x2f\x31\x01"


def image_size(path: Path) -> list[int]:
    """[width, height] of an OpenEXR or Radiance HDR image, read from its header; ValueError
    naming the file when it is not one (a text file named ``.hdr``, a truncated download)."""
    bad = f"HDRI {str(path)!r} is not a valid {path.suffix.lower()} image"
    if path.suffix.lower() == ".exr":
        with open(path, "rb") as fh:
            if fh.read(4) != EXR_MAGIC:
                raise InputError(f"{bad} (no OpenEXR signature)")
        try:
            import OpenEXR
            with OpenEXR.File(str(path), header_only=True) as f:
                (x0, y0), (x1, y1) = f.header()["dataWindow"]
        except Exception as err:  # noqa: BLE001 - OpenEXR raises bare RuntimeErrors
            raise InputError(f"{bad} ({' '.join(str(err).split())})") from None
        return [int(x1 - x0 + 1), int(y1 - y0 + 1)]
    with open(path, "rb") as fh:
        if not fh.readline().startswith(b"#?"):
            raise InputError(f"{bad} (no Radiance '#?' signature)")
        for _ in range(64):
            line = fh.readline()
            if not line:
                break
            parts = line.decode("ascii", errors="replace").split()
            if len(parts) == 4 and parts[0] in ("-Y", "+Y") and parts[2] in ("+X", "-X"):
                if not (parts[1].isdigit() and parts[3].isdigit()):
                    break
                if not fh.read(4):
                    raise InputError(f"{bad} (no pixel data after the header)")
                return [int(parts[3]), int(parts[1])]
    raise InputError(f"{bad} (no resolution line in the header)")


def build_hdri_source(src_dir: str | os.PathLike, out_dir: str | os.PathLike,
                      name: str = NAME_DEFAULT, license: str | None = None,
                      exclude: tuple[str, ...] = ()) -> Path:
    """Turn every ``.hdr`` / ``.exr`` in ``src_dir`` (not recursive; file stems in ``exclude``
    left out) into a Texture asset.

    Ids are the lower-cased file stems. ``license`` defaults to the first line of a
    ``license.txt`` next to the images, else raises (an asset must state its licence).
    Returns the manifest path.
    """
    src = Path(src_dir)
    if not src.is_dir():
        raise FileNotFoundError(f"HDRI source folder {str(src)!r} does not exist")
    images = sorted(p for p in src.iterdir() if p.suffix.lower() in EXTENSIONS and p.is_file()
                    and p.stem.lower() not in exclude)
    if not images:
        raise InputError(f"HDRI source folder {str(src)!r} holds no {list(EXTENSIONS)} files")
    if license is None:
        lic_file = next((p for p in src.iterdir() if p.name.lower() in ("license.txt",
                                                                         "license")), None)
        if lic_file is None:
            raise InputError(f"no licence given for the HDRIs in {str(src)!r}: pass license= "
                             "(--license) or put a license.txt next to the images")
        license = lic_file.read_text().strip().splitlines()[0]
    sizes = {path: image_size(path) for path in images}  # every image checked before writing
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries = {}
    for path in images:
        asset_id = "".join(c if c.isalnum() or c in "-_" else "_" for c in path.stem.lower())
        if asset_id in entries:
            raise InputError(f"two HDRIs map to the id {asset_id!r} in {str(src)!r}")
        meta = {"category": "hdri", "description": f"environment map {path.name}",
                "source_file": path.name}
        meta["resolution"] = sizes[path]
        entries[asset_id] = package_texture(asset_id, path, out, license=license, metadata=meta)
    return write_manifest(out / "manifest.json", name, VERSION, entries)


def bpy_world_hdri_dir() -> Path:
    """The bpy wheel's ``datafiles/studiolights/world`` folder (bpy is not imported)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None:
        raise ModuleNotFoundError("bpy is not installed: no bundled world HDRIs to build from")
    roots = list(spec.submodule_search_locations or [])
    if not roots and spec.origin:
        roots = [str(Path(spec.origin).parent)]
    for root in roots:
        hits = sorted(Path(root).glob("*/datafiles/studiolights/world"))
        if hits:
            return hits[-1]
    raise FileNotFoundError(f"no */datafiles/studiolights/world folder under {roots}")


def ensure_hdri_source(cache: str | os.PathLike | None = None):
    """The bpy wheel's HDRIs but :data:`NOT_BACKGROUNDS` as an :class:`AssetSource` in
    ``<cache>/HDRIs-<VERSION>`` (built on first use; a new version builds a new folder)."""
    root = Path(cache) if cache is not None else cache_dir()
    target = build_once(root / f"{NAME_DEFAULT}-{VERSION}", lambda tmp: build_hdri_source(
        bpy_world_hdri_dir(), tmp, license=BPY_WORLD_LICENSE, exclude=NOT_BACKGROUNDS))
    return AssetSource(target)
