"""``kubric view PATH [--port 8000] [--host 127.0.0.1]``: browse scenes in a local web page."""

from __future__ import annotations

import sys

from kubric.viewer.server import serve
from kubric.viewer.service import ViewerService
from kubric.viewer.source import DirectorySource


def cmd_view(args) -> int:
    if not 0 <= args.port <= 65535:
        print(f"kubric view: error: --port {args.port}: allowed 0..65535", file=sys.stderr)
        return 2
    try:
        source = DirectorySource(args.path)
    except NotADirectoryError as err:  # bad input: exit status 1 (docs/exit-codes.md)
        print(f"kubric view: error: {err}", file=sys.stderr)
        return 1
    if not source.names():
        print(f"kubric view: error: {args.path!r} holds no scene directories (scene_*/ with "
              "metadata.json)", file=sys.stderr)
        return 1
    return serve(ViewerService(source), args.host, args.port)


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("view", help="browse a scene directory or a folder of scenes in a "
                              "local web page", description="Serve a read-only web page (scene "
                              "list, layers, overlays, pixel probe, instance details, 3D paths) "
                              "for a scene directory or a folder of scenes.")
    p.add_argument("path", help="a scene directory or a folder of scene_* directories")
    p.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 = any free port)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this "
                   "machine only)")
    p.set_defaults(func=cmd_view)


__all__ = ["add_parser"]
