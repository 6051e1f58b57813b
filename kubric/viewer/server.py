"""The viewer's HTTP server: standard-library ``ThreadingHTTPServer``, GET / HEAD only, read-only.

Endpoints (all answers are computed by :class:`~kubric.viewer.service.ViewerService`):

=========================================  ===================================================
``/``                                      the page (``static/index.html``)
``/static/FILE``                           the page's own JS / CSS (a fixed list of files)
``/api/scenes``                            the scene list (one summary per scene)
``/api/scene/NAME``                        metadata, events, worker command, palette
``/api/frame/NAME/LAYER/INDEX.png``        one layer frame as a picture (``?lo=&hi=``: the
                                           depth range in metres, or ``hi`` = full-colour flow
                                           magnitude); LAYER ``outline`` / ``fill`` =
                                           segmentation edges / filled objects (RGBA), LAYER
                                           ``events`` = the frame's accumulated events
``/api/probe/NAME/INDEX?row=R&col=C``      the pixel's label, instance, asset, depth, flows,
                                           world point
``/api/tracks/NAME``                       up to 64 point tracks (positions, occlusion)
=========================================  ===================================================

Scenes are named, never addressed by path; a request path containing ``..``, a backslash, a NUL,
an absolute path or an encoded separator inside a component is refused with 400 before any
lookup (also after repeated percent-decoding). Answers are strict JSON (a NaN or infinity in a
scene's files is sent as ``null``). Errors are JSON ``{"error": message}``, naming scenes,
never the server's folders, with 400
(bad request), 404 (unknown scene / layer / frame), 405 (any method but GET / HEAD), 422 (a
scene that cannot be shown: corrupt files, a frame count its files do not back or over
:data:`~kubric.viewer.source.MAX_FRAMES`) or 500 (anything else: every request is
answered with a status, never a dropped connection). The listen backlog is
:data:`LISTEN_BACKLOG` (the standard library's default, 5, drops connections under load).
"""

from __future__ import annotations

import json
import math
import pathlib
import sys
import traceback
import urllib.parse
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from kubric.viewer.service import ViewerService
from kubric.viewer.source import SceneError

STATIC_DIR = pathlib.Path(__file__).parent / "static"
#: pending connections the kernel queues (a page opening fires dozens of requests at once)
LISTEN_BACKLOG = 1024
CONTENT_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                 ".css": "text/css; charset=utf-8", ".png": "image/png"}


class BadRequest(Exception):
    """A request path or query that is refused (400)."""


def split_path(raw: str) -> tuple[list[str], dict[str, str]]:
    """The decoded path components and query of a request target; BadRequest on traversal."""
    parsed = urllib.parse.urlsplit(raw)
    path = parsed.path
    if not path.startswith("/") or path.startswith("//"):
        raise BadRequest(f"request path must start with one '/': {raw[:200]!r}")
    decoded, previous = path, None
    while decoded != previous:  # refuse encoded, doubly encoded ... traversal
        if ".." in decoded or "\\" in decoded or "\x00" in decoded:
            raise BadRequest(f"request path {raw[:200]!r} contains '..', '\\' or NUL")
        decoded, previous = urllib.parse.unquote(decoded), decoded
    parts = [urllib.parse.unquote(p) for p in path.split("/")[1:]]
    for part in parts:
        if "/" in part or part.startswith("~") or ":" in part:
            raise BadRequest(f"request path component {part[:100]!r} is not allowed")
    query = {k: v[-1] for k, v in urllib.parse.parse_qs(parsed.query).items()}
    return parts, query


def _number(query: dict, key: str, kind=float, required=False):
    if key not in query:
        if required:
            raise BadRequest(f"query parameter {key!r} is required")
        return None
    try:
        value = kind(query[key])
    except ValueError:
        value = None
    if value is None or not math.isfinite(value):
        raise BadRequest(f"query parameter {key}={query[key]!r} must be a finite "
                         f"{'whole number' if kind is int else 'number'}")
    return value


def _index(text: str) -> int:
    if not text.isdigit():
        raise BadRequest(f"frame index {text!r} must be a whole number ≥ 0")
    return int(text)


def finite(value):
    """``value`` with every non-finite float (NaN, ±Infinity) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


class Handler(BaseHTTPRequestHandler):
    service: ViewerService  # set by make_server
    quiet = True
    server_version = "kubric-view"

    def log_message(self, format, *args):  # noqa: A002 (BaseHTTPRequestHandler's signature)
        if not self.quiet:
            super().log_message(format, *args)

    def do_HEAD(self):  # noqa: N802
        self.do_GET(head=True)

    def do_GET(self, head: bool = False):  # noqa: N802
        try:
            status, ctype, body = self.route(self.path)
        except BadRequest as err:
            status, ctype, body = self.error(HTTPStatus.BAD_REQUEST, err)
        except KeyError as err:
            status, ctype, body = self.error(HTTPStatus.NOT_FOUND, err.args[0] if err.args else err)
        except SceneError as err:
            status, ctype, body = self.error(HTTPStatus.UNPROCESSABLE_ENTITY, err)
        except Exception as err:  # noqa: BLE001 - answered (500), and the traceback logged
            if not self.quiet:
                traceback.print_exc()
            message = " ".join(str(err).split())[:300] or type(err).__name__
            status, ctype, body = self.error(HTTPStatus.INTERNAL_SERVER_ERROR,
                                             f"{type(err).__name__}: {message}")
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        self.end_headers()
        if not head:
            self.wfile.write(body)

    def _refuse(self):
        status, ctype, body = self.error(HTTPStatus.METHOD_NOT_ALLOWED,
                                         "kubric view is read-only: only GET and HEAD")
        self.send_response(status)
        self.send_header("Allow", "GET, HEAD")
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    do_POST = do_PUT = do_DELETE = do_PATCH = _refuse  # noqa: N815

    def __getattr__(self, name):
        if name.startswith("do_"):  # any other method (OPTIONS, TRACE, ...): 405, not 501
            return self._refuse
        raise AttributeError(name)

    def error(self, status, message):
        """A JSON error; the server's own folder is never shown (scenes are named)."""
        text = str(message)
        root = getattr(self.service.source, "root", None)
        if root is not None:
            text = text.replace(f"{root}/", "").replace(str(root), "<scenes>")
        return status, "application/json", json.dumps({"error": text}).encode()

    @staticmethod
    def json(data):
        """Strict JSON (RFC 8259): a NaN or infinity from a scene's files becomes null."""
        return HTTPStatus.OK, "application/json", json.dumps(finite(data),
                                                             allow_nan=False).encode()

    def route(self, raw: str):
        parts, query = split_path(raw)
        svc = self.service
        if parts in ([""], ["index.html"]):
            parts = ["static", "index.html"]
        match parts:
            case ["static", filename]:
                path = STATIC_DIR / filename
                if filename not in {p.name for p in STATIC_DIR.iterdir()} or not path.is_file():
                    raise KeyError(f"no static file {filename!r}")
                ctype = CONTENT_TYPES.get(path.suffix, "application/octet-stream")
                return HTTPStatus.OK, ctype, path.read_bytes()
            case ["api", "scenes"]:
                return self.json(svc.scene_list())
            case ["api", "scene", name]:
                return self.json(svc.scene(svc.source.check_name(name)))
            case ["api", "tracks", name]:
                return self.json(svc.tracks(svc.source.check_name(name)))
            case ["api", "frame", name, layer, file] if file.endswith(".png"):
                png = svc.picture_png(svc.source.check_name(name), layer, _index(file[:-4]),
                                      _number(query, "lo"), _number(query, "hi"))
                return HTTPStatus.OK, "image/png", png
            case ["api", "probe", name, index]:
                return self.json(svc.probe(svc.source.check_name(name), _index(index),
                                           _number(query, "col", int, True),
                                           _number(query, "row", int, True)))
        raise KeyError(f"no such page or endpoint: {'/'.join(parts)!r}")


class _Server(ThreadingHTTPServer):
    request_queue_size = LISTEN_BACKLOG


def make_server(service: ViewerService, host: str = "127.0.0.1", port: int = 8000,
                quiet: bool = True) -> ThreadingHTTPServer:
    """A server (not yet serving) for ``service``; port 0 picks a free port."""
    handler = type("BoundHandler", (Handler,), {"service": service, "quiet": quiet})
    server = _Server((host, port), handler)
    server.daemon_threads = True
    return server


def serve(service: ViewerService, host: str, port: int) -> int:
    try:
        server = make_server(service, host, port, quiet=False)
    except OSError as err:
        print(f"kubric view: error: cannot listen on {host}:{port}: {err}", file=sys.stderr)
        return 2
    h, p = server.server_address[:2]
    print(f"kubric view: serving {len(service.source.names())} scene(s) from "
          f"{getattr(service.source, 'root', '')} at http://{h}:{p}/ (Ctrl-C stops)", flush=True)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
    return 0
