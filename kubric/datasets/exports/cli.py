"""``kubric export FORMAT SCENES --out ...`` for every format of
:data:`kubric.datasets.exports.FORMATS` (docs/exports.md). ``kubric tracks export`` (the old
spelling of ``kubric export tapvid``) is kept only to print one line naming the new command."""

from __future__ import annotations

import argparse
import sys

from kubric.datasets.exports import FORMATS, exporter
from kubric.errors import KubricError

SCENES_HELP = "a folder of scene_* directories, or one scene directory"


def _error(what: str, message) -> int:
    print(f"kubric export {what}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return 2


def _run(name: str, args, **kwargs):
    """``FORMATS[name](SCENES, OUT, **kwargs)`` with its expected errors as one line (exit 2)."""
    try:
        return exporter(name)(args.scenes_dir, args.out, **kwargs), 0
    except (KubricError, OSError) as err:  # ExportError is one
        return None, _error(name, err)


def cmd_coco(args) -> int:
    summary, code = _run("coco", args, progress=not args.no_progress,
                         compressed=not args.uncompressed_rle, sources=args.source)
    if summary:
        print(summary.format())
    return code


def cmd_bop(args) -> int:
    if not args.depth_scale > 0:
        return _error("bop", f"--depth-scale must be > 0 (millimetres per depth unit), got "
                      f"{args.depth_scale}")
    summary, code = _run("bop", args, split=args.split, depth_scale=args.depth_scale,
                         progress=not args.no_progress, sources=args.source)
    if summary:
        print(summary.format())
    return code


def cmd_tapvid(args) -> int:
    result, code = _run("tapvid", args)
    if result:
        print(f"wrote {result[1]} scene(s) in TAP-Vid layout to {result[0]}")
    return code


def cmd_nerf(args) -> int:
    result, code = _run("nerf", args)
    if result:
        print(f"wrote {result[1]} multi-view scene(s) in NeRF's layout to {result[0]}")
    return code


def cmd_lasr(args) -> int:
    try:
        chosen = None if args.instances is None else \
            [int(v) for v in args.instances.split(",") if v.strip()]
    except ValueError:
        return _error("lasr", f"--instances {args.instances!r}: expected comma-separated "
                      "instance indices (0-based), e.g. 0,3")
    summary, code = _run("lasr", args, sequence=args.sequence, instances=chosen, root=args.root)
    if summary:
        print(f"wrote LASR sequence {summary['sequence']} ({summary['num_frames']} frames) to "
              f"{args.out}")
    return code


#: format → (help, description, --out help, command)
COMMANDS = {
    "coco": ("COCO instance annotations (one image per frame / view)",
             "One JSON file: images (file_name relative to SCENES), instance annotations with RLE "
             "masks, boxes [x, y, w, h] in pixels, areas and categories from the recipe's labels.",
             "output file (.json)", cmd_coco),
    "bop": ("BOP 6D object-pose dataset (models, poses, masks, depth)",
            "BOP's layout: OUT/models (PLY in mm, models_info.json) and OUT/SPLIT/SCENE_ID/ with "
            "rgb, depth, mask, mask_visib, scene_camera.json, scene_gt.json, scene_gt_info.json.",
            "output folder (the BOP dataset root)", cmd_bop),
    "tapvid": ("point tracks in TAP-Vid's pickle layout",
               "Pickle {scene name: {video, points, occluded, target_points, query_points}} "
               "(TAP-Vid's tapvid_davis.pkl layout) of every scene's tracks.npz.",
               "output file (.pkl)", cmd_tapvid),
    "nerf": ("multi-view scenes as NeRF / instant-ngp / nerfstudio folders",
             "OUT/SCENE/ with transforms_{train,val,test}.json and the files their views name "
             "(RGBA PNGs, depth, segmentation, ...), nothing else.",
             "output folder (must not exist)", cmd_nerf),
    "lasr": ("one scene as a LASR / ViSER video sequence (DAVIS layout)",
             "OUT/DAVIS/{JPEGImages,Annotations,FlowFW,FlowBW,Cameras,CamerasWorld}/"
             "Full-Resolution/SEQ/ and OUT/configs/SEQ.config for one scene directory.",
             "the LASR folder to create", cmd_lasr),
}
assert list(COMMANDS) == list(FORMATS), "every registered format has its command"


def cmd_tracks_export(args) -> int:
    print("kubric tracks export: error: removed; use `kubric export tapvid SCENES --out "
          "FILE.pkl`", file=sys.stderr)
    return 2


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("export", help="export scenes to " + ", ".join(FORMATS),
                              description="Export the complete scene directories of a folder "
                              "(or one scene) to another tool's format; docs/exports.md.")
    sub = p.add_subparsers(dest="export_format", metavar="FORMAT", required=True)
    parsers = {}
    for name, (short, description, out_help, func) in COMMANDS.items():
        f = parsers[name] = sub.add_parser(name, help=short, description=description)
        f.add_argument("scenes_dir", metavar="SCENE" if name == "lasr" else "SCENES",
                       help="one scene directory" if name == "lasr" else SCENES_HELP)
        f.add_argument("--out", required=True, help=out_help)
        f.set_defaults(func=func)
    for name, source_help in (("coco", "asset source whose categories name the objects "
                               "(default: the one the scenes' options name; repeatable)"),
                              ("bop", "asset source holding the objects' meshes (default: the "
                               "sources the scenes' options name, and KuBasic; repeatable)")):
        parsers[name].add_argument("--source", action="append", default=[],
                                   metavar="ASSET_SOURCE", help=source_help)
        parsers[name].add_argument("--no-progress", action="store_true", help="no progress bar")
    parsers["coco"].add_argument("--uncompressed-rle", action="store_true", help="write RLE "
                                 "counts as lists of ints instead of COCO's compressed strings")
    parsers["bop"].add_argument("--split", default="train_pbr", help="split folder name "
                                "(default train_pbr)")
    parsers["bop"].add_argument("--depth-scale", type=float, default=1.0, help="millimetres per "
                                "unit of the 16-bit depth PNGs (default 1.0: up to 65.535 m)")
    lasr = parsers["lasr"]
    lasr.add_argument("--instances", default=None, help="comma-separated instance indices "
                      "(0-based) forming the object (default: every instance)")
    lasr.add_argument("--root", type=int, default=None, help="instance of the Cameras frame")
    lasr.add_argument("--sequence", default=None, help="sequence name (default RECIPE_SEED)")

    tracks = subparsers.add_parser("tracks", help="(removed: use `kubric export tapvid`)")
    tracks.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    tracks.set_defaults(func=cmd_tracks_export)


__all__ = ["add_parser"]
