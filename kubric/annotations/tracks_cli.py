"""``kubric tracks export SCENES_DIR --format tapvid --out FILE``: the point tracks of a dataset
in TAP-Vid's pickle layout (see :mod:`kubric.annotations.track_files`)."""

from __future__ import annotations

import sys

from kubric.annotations.track_files import export_tapvid

FORMATS = ("tapvid",)


def cmd_export(args) -> int:
    if args.format not in FORMATS:
        print(f"kubric tracks export: error: --format {args.format!r}: allowed {FORMATS}",
              file=sys.stderr)
        return 2
    try:
        path, count = export_tapvid(args.scenes_dir, args.out)
    except (FileNotFoundError, ValueError) as err:
        print(f"kubric tracks export: error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {count} scene(s) in TAP-Vid layout to {path}")
    return 0


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("tracks", help="point tracks: export to other layouts")
    sub = p.add_subparsers(dest="tracks_command", metavar="ACTION", required=True)
    e = sub.add_parser("export", help="write the tracks of every complete scene as one file",
                       description="Pickle {scene name: {video, points, occluded, "
                       "target_points, query_points}} (TAP-Vid's tapvid_davis.pkl layout; "
                       "points normalised to [0, 1], the others in raster pixels).")
    e.add_argument("scenes_dir", help="a dataset folder of scene_* directories, or one scene")
    e.add_argument("--format", default="tapvid", help="output layout (only: tapvid)")
    e.add_argument("--out", required=True, help="output file (.pkl); `kubric export tapvid "
                   "SCENES --out FILE` is the same command")
    e.set_defaults(func=cmd_export)


__all__ = ["add_parser"]
