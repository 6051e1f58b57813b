"""A local server that answers like the Hugging Face Hub serving ``allenai/objaverse``, and the
files of a tiny Objaverse in its layout (object paths, metadata chunks, LVIS annotations, GLBs).

Hub behaviour reproduced (as ``huggingface_hub`` relies on it): ``HEAD`` or ``GET`` of
``/resolve/main/<path>`` answers ``302`` to the file's LFS address with ``X-Linked-Size`` and
``X-Linked-Etag: "<sha256>"``; the LFS address (here ``/lfs/<path>``) serves the bytes,
honouring ``Range: bytes=N-`` with 206.
"""

from __future__ import annotations

import gzip
import hashlib
import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from collection_fixtures import LocalServer
from gltf_fixtures import textured_glb

PREFIX = "/datasets/allenai/objaverse/resolve/main"


def sketchfab_record(uid: str, license_slug: str, name: str, author: str) -> dict:
    """The fields of a Sketchfab model record that Objaverse's metadata chunks hold."""
    return {"uri": f"https://api.sketchfab.com/v3/models/{uid}", "uid": uid, "name": name,
            "viewerUrl": f"https://sketchfab.com/3d-models/{uid}",
            "user": {"uid": "u" + uid, "username": author.lower(), "displayName": author,
                     "profileUrl": f"https://sketchfab.com/{author.lower()}"},
            "license": license_slug, "categories": [{"name": "Furniture & Home"}],
            "tags": [], "faceCount": 38, "vertexCount": 64}


def objaverse_files(tmp: Path, objects: dict) -> dict[str, bytes]:
    """Files (layout path → bytes) for ``objects`` = ``{uid: (chunk, licence, LVIS category or
    None, scale)}``; each GLB is the four-part textured fixture times its scale, every second
    one (in uid order) stored under Sketchfab's z-up root node."""
    paths, lvis, chunks, files = {}, {}, {}, {}
    for k, (uid, (chunk, lic, cat, scale)) in enumerate(sorted(objects.items())):
        rel = f"glbs/{chunk}/{uid}.glb"
        paths[uid] = rel
        files[rel] = textured_glb(tmp / f"{uid}.glb", scale=scale,
                                  sketchfab_root=k % 2 == 1).read_bytes()
        chunks.setdefault(chunk, {})[uid] = sketchfab_record(uid, lic, f"Thing {uid}",
                                                             f"Author{uid.upper()}")
        if cat:
            lvis.setdefault(cat, []).append(uid)
    files["object-paths.json.gz"] = gzip.compress(json.dumps(paths).encode())
    files["lvis-annotations.json.gz"] = gzip.compress(json.dumps(lvis).encode())
    for chunk, records in chunks.items():
        files[f"metadata/{chunk}.json.gz"] = gzip.compress(json.dumps(records).encode())
    return files


class HubServer(LocalServer):
    """``files`` (layout path → bytes) served under :data:`PREFIX` as the Hub does.

    ``cut_once``: layout paths whose first transfer announces the whole length, sends half and
    closes; ``corrupt_once``: paths whose first transfer sends the right length with one byte
    changed. ``requests``: ``(method, path, Range header)`` in order.
    """

    def __init__(self, files: dict[str, bytes], cut_once=(), corrupt_once=()):
        # (LocalServer's own routes are not used: its start / stop are)
        self.files = dict(files)
        self.sha = {rel: hashlib.sha256(data).hexdigest() for rel, data in self.files.items()}
        self.cut_once, self.corrupt_once = set(cut_once), set(corrupt_once)
        self.requests: list[tuple[str, str, str | None]] = []
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def _empty(self, code, headers=()):
                self.send_response(code)
                for key, value in headers:
                    self.send_header(key, value)
                self.send_header("Content-Length", "0")
                self.end_headers()

            def _resolve(self):
                rel = self.path[len(PREFIX) + 1:] if self.path.startswith(PREFIX + "/") else None
                if rel not in server.files:
                    return self._empty(404)
                sha = server.sha[rel]
                self._empty(302, [("Location", f"/lfs/{rel}"),
                                  ("X-Linked-Size", str(len(server.files[rel]))),
                                  ("X-Linked-Etag", f'"{sha}"')])

            def do_HEAD(self):
                server.requests.append(("HEAD", self.path, None))
                self._resolve()

            def do_GET(self):
                rng = self.headers.get("Range")
                server.requests.append(("GET", self.path, rng))
                if not self.path.startswith("/lfs/"):
                    return self._resolve()
                rel = self.path[len("/lfs/"):]
                if rel not in server.files:
                    return self._empty(404)
                body = server.files[rel]
                start = int(rng.split("=")[1].split("-")[0]) if rng else 0
                if rng and start >= len(body):
                    return self._empty(416)
                part = body[start:]
                self.send_response(206 if rng else 200)
                self.send_header("Content-Length", str(len(part)))
                self.end_headers()
                if rel in server.cut_once:
                    server.cut_once.discard(rel)
                    self.wfile.write(part[: len(part) // 2])
                    self.wfile.flush()
                    self.close_connection = True
                    return
                if rel in server.corrupt_once:
                    server.corrupt_once.discard(rel)
                    part = part[:40] + bytes([part[40] ^ 0xFF]) + part[41:]
                self.wfile.write(part)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}{PREFIX}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def fetched(self, rel: str) -> int:
        """How many times the bytes of layout file ``rel`` were requested."""
        return sum(1 for m, p, _ in self.requests if m == "GET" and p == f"/lfs/{rel}")



def objaverse_source(root: Path, objects: dict) -> tuple[Path, dict]:
    """``root/objaverse``: an asset source built by ``build_objaverse`` from ``objects`` (as
    :func:`objaverse_files` takes them) served by a local :class:`HubServer`; returns (the
    folder, its manifest's assets)."""
    from kubric.asset_tools.objaverse import build_objaverse

    with HubServer(objaverse_files(root, objects)) as hub:
        report = build_objaverse(root / "objaverse", count=len(objects), base_url=hub.url,
                                 workers=1, progress=False)
    assert report["converted"] == len(objects), report
    return root / "objaverse", json.loads((root / "objaverse" / "manifest.json").read_text())[
        "assets"]
