"""``kubric export FORMAT SCENES --out ...`` for every format of
:data:`kubric.datasets.exports.FORMATS` (docs/exports.md). ``kubric tracks export`` (the old
spelling of ``kubric export tapvid``) is kept only to print one line naming the new command."""

from __future__ import annotations

import argparse
import sys

from kubric.datasets.exports import FORMATS, exporter
from kubric.errors import KubricError
from kubric.io.output_check import check_output, scene_folders

SCENES_HELP = "a folder of scene_* directories, or one scene directory"
DATASET_HELP = "a packed dataset (kubric pack), or a folder of scene_* directories"
#: the formats exporting a packed dataset (kubric.datasets.exports.hub)
HUB = ("hf", "webdataset")


def _error(what: str, message, code: int = 2) -> int:
    print(f"kubric export {what}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return code


def _run(name: str, args, **kwargs):
    """``FORMATS[name](SCENES, OUT, **kwargs)`` with its expected errors as one line, exiting
    with the error's status (docs/exit-codes.md: 2 for a bad option or output, 1 for bad
    input)."""
    try:
        check_output(args.out, scene_folders(args.scenes_dir), [args.scenes_dir],
                     command=f"kubric export {name}")
        return exporter(name)(args.scenes_dir, args.out, **kwargs), 0
    except (KubricError, OSError) as err:  # ExportError is one
        refused = isinstance(err, FileExistsError)  # an output it will not replace: as --out
        return None, _error(name, err, err.exit_code if isinstance(err, KubricError)
                            else 2 if refused else 1)


def cmd_coco(args) -> int:
    summary, code = _run("coco", args, progress=not args.no_progress,
                         compressed=not args.uncompressed_rle, sources=args.source)
    if summary:
        print(summary.format())
    return code


def cmd_bop(args) -> int:
    if not 0 < args.depth_scale < float("inf"):
        return _error("bop", f"--depth-scale must be a finite number > 0 (millimetres per depth "
                      f"unit), got {args.depth_scale}")
    summary, code = _run("bop", args, split=args.split, depth_scale=args.depth_scale,
                         progress=not args.no_progress, sources=args.source)
    if summary:
        print(summary.format())
    return code


def cmd_export(args) -> int:
    """Any format without options of its own: the export function's result is its summary
    (an object with ``format()``, a (path, count) pair, or None)."""
    name = args.export_format
    result, code = _run(name, args)
    if hasattr(result, "format"):
        print(result.format())
    elif isinstance(result, tuple) and len(result) == 2:
        print(f"wrote {result[1]} scene(s) as {name} to {result[0]}")
    return code


def cmd_lasr(args) -> int:
    try:
        chosen = None if args.instances is None else \
            [int(v) for v in args.instances.split(",") if v.strip()]
    except ValueError:
        return _error("lasr", f"--instances {args.instances!r}: expected comma-separated "
                      "instance indices (0-based), e.g. 0,3")
    summary, code = _run("lasr", args, sequence=args.sequence, instances=chosen, root=args.root,
                         camera=args.camera)
    if summary:
        seen = f", camera {summary['camera_name']}" if "camera_name" in summary else ""
        print(f"wrote LASR sequence {summary['sequence']} ({summary['num_frames']} frames"
              f"{seen}) to {args.out}")
    return code


def _hub_summary(name: str, result, out) -> str:
    if name == "hf":
        return (f"wrote {sum(result.values())} scene(s) as Hugging Face Parquet ("
                f"{', '.join(f'{s}: {n}' for s, n in result.items())}) to {out}")
    splits = result["splits"].values()
    return (f"wrote {sum(v['samples'] for v in splits)} sample(s) in "
            f"{sum(len(v['shards']) for v in splits)} WebDataset shard(s) to {out}")


def cmd_hub(args) -> int:
    """``kubric export hf|webdataset`` (the exports of a packed dataset)."""
    name = args.export_format
    shard = {} if getattr(args, "scenes_per_shard", None) is None else \
        {"scenes_per_shard": args.scenes_per_shard}  # None: the export's own default
    own = dict(license_id=args.license, **shard) if name == "hf" else \
        dict(samples_per_shard=args.samples_per_shard, per_frame=args.per_frame)
    result, code = _run(name, args, splits=args.splits, scenes=args.scenes,
                        progress=not args.no_progress, **own)
    if result:
        print(_hub_summary(name, result, args.out))
    return code


#: format → its command, for the formats with options beyond SCENES and --out (the others run
#: :func:`cmd_export`); the texts of every command are its row of FORMATS
COMMANDS = {"coco": cmd_coco, "bop": cmd_bop, "lasr": cmd_lasr, "hf": cmd_hub,
            "webdataset": cmd_hub}
assert set(COMMANDS) <= set(FORMATS), "every command is a registered format"


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
    for name, row in FORMATS.items():
        f = parsers[name] = sub.add_parser(name, help=row.help, description=row.description)
        f.add_argument("scenes_dir", metavar="SCENE" if name == "lasr" else "SCENES",
                       help="one scene directory" if name == "lasr" else
                       DATASET_HELP if name in HUB else SCENES_HELP)
        f.add_argument("--out", required=True, help=row.out_help)
        f.set_defaults(func=COMMANDS.get(name, cmd_export))
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
    for name in HUB:
        hub = parsers[name]
        hub.add_argument("--splits", default="train=0.9,validation=0.1", help="splits of scene "
                         "folders, packed first (as `kubric pack --splits`)")
        hub.add_argument("--scenes", default=None, metavar="SCENES_DIR", help="the scene "
                         "folders a packed dataset was made from: the card's licences, "
                         "attribution and command")
        hub.add_argument("--no-progress", action="store_true", help="no progress bar")
    parsers["hf"].add_argument("--scenes-per-shard", type=int, default=None,
                               help="scenes per Parquet file (default 100: bounds the writer's "
                               "memory; docs/hub.md)")
    parsers["hf"].add_argument("--license", default=None, help="the Hub licence id (default: "
                               "the assets' own when all are CC0 / CC-BY 4.0, else other)")
    parsers["webdataset"].add_argument("--samples-per-shard", type=int, default=1000)
    parsers["webdataset"].add_argument("--per-frame", action="store_true",
                                       help="one sample per frame (RGB as PNG)")
    lasr = parsers["lasr"]
    lasr.add_argument("--instances", default=None, help="comma-separated instance indices "
                      "(0-based) forming the object (default: every instance)")
    lasr.add_argument("--root", type=int, default=None, help="instance of the Cameras frame")
    lasr.add_argument("--sequence", default=None, help="sequence name (default RECIPE_SEED)")
    lasr.add_argument("--camera", type=int, default=0, metavar="C", help="a camera-rig scene's "
                      "camera to export, by index (default 0: the reference camera)")

    tracks = subparsers.add_parser("tracks", help="(removed: use `kubric export tapvid`)")
    tracks.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    tracks.set_defaults(func=cmd_tracks_export)


__all__ = ["add_parser"]
