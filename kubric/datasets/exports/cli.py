"""``kubric export coco|bop|tapvid SCENES --out ...``: scene directories in other tools' formats
(docs/exports.md). ``kubric export tapvid`` is ``kubric tracks export --format tapvid`` (both
spellings work)."""

from __future__ import annotations

import sys

from kubric.annotations.track_files import export_tapvid
from kubric.datasets.exports.bop import export_bop
from kubric.datasets.exports.coco import export_coco
from kubric.datasets.exports.scenes import ExportError


def _error(what: str, message) -> int:
    print(f"kubric export {what}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def cmd_coco(args) -> int:
    try:
        summary = export_coco(args.scenes_dir, args.out, progress=not args.no_progress,
                              compressed=not args.uncompressed_rle, sources=args.source)
    except ExportError as err:
        return _error("coco", err)
    print(summary.format())
    return 0


def cmd_bop(args) -> int:
    if not args.depth_scale > 0:
        return _error("bop", f"--depth-scale must be > 0 (millimetres per depth unit), got "
                      f"{args.depth_scale}")
    try:
        summary = export_bop(args.scenes_dir, args.out, split=args.split,
                             depth_scale=args.depth_scale, progress=not args.no_progress,
                             sources=args.source)
    except ExportError as err:
        return _error("bop", err)
    print(summary.format())
    return 0


def cmd_tapvid(args) -> int:
    try:
        path, count = export_tapvid(args.scenes_dir, args.out)
    except (FileNotFoundError, ValueError) as err:
        return _error("tapvid", err)
    print(f"wrote {count} scene(s) in TAP-Vid layout to {path}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("export", help="export scenes to COCO, BOP or TAP-Vid",
                              description="Export the complete scene directories of a folder "
                              "(or one scene) to another tool's format; docs/exports.md.")
    sub = p.add_subparsers(dest="export_format", metavar="FORMAT", required=True)
    scenes_help = "a folder of scene_* directories, or one scene directory"

    formats = {
        "coco": ("COCO instance annotations (one image per frame / view)",
                 "One JSON file: images (file_name relative to SCENES), instance annotations with "
                 "RLE masks, boxes [x, y, w, h] in pixels, areas and categories from the recipe's "
                 "labels.", "output file (.json)", cmd_coco,
                 "asset source whose categories name the objects (default: the one the scenes' "
                 "options name; repeatable)"),
        "bop": ("BOP 6D object-pose dataset (models, poses, masks, depth)",
                "BOP's layout: OUT/models (PLY in mm, models_info.json) and OUT/SPLIT/SCENE_ID/ "
                "with rgb, depth, mask, mask_visib, scene_camera.json, scene_gt.json, "
                "scene_gt_info.json.", "output folder (the BOP dataset root)", cmd_bop,
                "asset source holding the objects' meshes (default: the sources the scenes' "
                "options name, and KuBasic; repeatable)"),
        "tapvid": ("point tracks in TAP-Vid's pickle layout",
                   "Pickle {scene name: {video, points, occluded, target_points, query_points}} "
                   "(TAP-Vid's tapvid_davis.pkl layout); same as `kubric tracks export --format "
                   "tapvid`.", "output file (.pkl)", cmd_tapvid, None),
    }
    parsers = {}
    for name, (short, description, out_help, func, source_help) in formats.items():
        f = parsers[name] = sub.add_parser(name, help=short, description=description)
        f.add_argument("scenes_dir", metavar="SCENES", help=scenes_help)
        f.add_argument("--out", required=True, help=out_help)
        if source_help:
            f.add_argument("--source", action="append", default=[], metavar="ASSET_SOURCE",
                           help=source_help)
            f.add_argument("--no-progress", action="store_true", help="no progress bar")
        f.set_defaults(func=func)
    parsers["coco"].add_argument("--uncompressed-rle", action="store_true", help="write RLE "
                                 "counts as lists of ints instead of COCO's compressed strings")
    parsers["bop"].add_argument("--split", default="train_pbr", help="split folder name "
                                "(default train_pbr)")
    parsers["bop"].add_argument("--depth-scale", type=float, default=1.0, help="millimetres per "
                                "unit of the 16-bit depth PNGs (default 1.0: up to 65.535 m)")

__all__ = ["add_parser"]
