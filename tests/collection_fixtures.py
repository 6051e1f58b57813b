"""Fixtures for the collection readers: meshes in the collections' original layouts, tiny HDR/EXR
images and a local HTTP server on 127.0.0.1 that answers like the collections' APIs."""

from __future__ import annotations

import io
import threading
import zipfile
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np

# A box: per face (outward normal axis, sign) four corners in counter-clockwise order seen from
# outside, UVs (0,0) (1,0) (1,1) (0,1) across each face.
_FACES = [((1, 0, 0), [(1, -1, -1), (1, 1, -1), (1, 1, 1), (1, -1, 1)]),
          ((-1, 0, 0), [(-1, 1, -1), (-1, -1, -1), (-1, -1, 1), (-1, 1, 1)]),
          ((0, 1, 0), [(1, 1, -1), (-1, 1, -1), (-1, 1, 1), (1, 1, 1)]),
          ((0, -1, 0), [(-1, -1, -1), (1, -1, -1), (1, -1, 1), (-1, -1, 1)]),
          ((0, 0, 1), [(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]),
          ((0, 0, -1), [(-1, 1, -1), (1, 1, -1), (1, -1, -1), (-1, -1, -1)])]


def box_obj(half=(0.15, 0.1, 0.1), mtllib="model.mtl", material="material_0",
            vertices_override=None) -> str:
    """A textured box OBJ (z up, metres); 24 vertices with UVs, 12 triangles."""
    lines = [f"mtllib {mtllib}"] if mtllib else []
    verts = []
    for _, corners in _FACES:
        verts += [np.multiply(c, half) for c in corners]
    if vertices_override is not None:
        verts = vertices_override(np.asarray(verts, dtype=float))
    lines += ["v " + " ".join(f"{x:.6g}" for x in v) for v in verts]
    lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1"] * 6
    lines += [f"usemtl {material}"] if mtllib else []
    for k in range(6):
        a, b, c, d = (4 * k + i + 1 for i in range(4))
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}", f"f {a}/{a} {c}/{c} {d}/{d}"]
    return "\n".join(lines) + "\n"


def mtl_text(texture="texture.png", material="material_0") -> str:
    return f"newmtl {material}\nKd 1 1 1\nmap_Kd {texture}\n"


def two_colour_png(size=16) -> bytes:
    """Left half (u < 0.5) red, right half blue."""
    from PIL import Image

    img = np.zeros((size, size, 3), np.uint8)
    img[:, : size // 2] = (220, 20, 20)
    img[:, size // 2:] = (20, 20, 220)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def gso_files(name: str, category: str | None = "Toys", obj: str | None = None,
              texture: bytes | None = None, description="a small box") -> dict[str, bytes]:
    """The files of one GSO model as distributed (paths inside its zip)."""
    pbtxt = f'name: "{name}"\n' + (f'categories {{\n  first: "{category}"\n}}\n' if category
                                   else "")
    return {
        "meshes/model.obj": (obj or box_obj()).encode(),
        "meshes/model.mtl": mtl_text().encode(),
        "materials/textures/texture.png": two_colour_png() if texture is None else texture,
        "model.config": (f"<?xml version='1.0'?>\n<model>\n  <name>{name}</name>\n"
                         f"  <version>1.0</version>\n  <sdf version='1.6'>model.sdf</sdf>\n"
                         f"  <author><name>Google</name></author>\n"
                         f"  <description>\n    {description}\n  </description>\n</model>\n"
                         ).encode(),
        "model.sdf": b"<?xml version='1.0'?><sdf version='1.6'><model name='m'/></sdf>\n",
        "metadata.pbtxt": pbtxt.encode(),
        "thumbnails/0.jpg": b"\xff\xd8\xff\xd9",
    }


def write_zip(path: Path, files: dict[str, bytes], symlinks: dict[str, str] | None = None) -> Path:
    """A zip of ``files``; ``symlinks``: member name → link target (Unix symlink mode)."""
    with zipfile.ZipFile(path, "w") as zf:
        for member, data in files.items():
            zf.writestr(member, data)
        for member, target in (symlinks or {}).items():
            info = zipfile.ZipInfo(member)
            info.external_attr = (0o120777 << 16)
            zf.writestr(info, target)
    return path


def write_hdr(path: Path, rgb: np.ndarray) -> Path:
    """A flat (uncompressed) Radiance RGBE .hdr of a (H, W, 3) float image."""
    rgb = np.asarray(rgb, dtype=np.float64)
    h, w, _ = rgb.shape
    peak = rgb.max(axis=2)
    exp = np.where(peak > 1e-32, np.floor(np.log2(np.maximum(peak, 1e-32))) + 1, 0)
    scale = np.where(peak > 1e-32, 256.0 / np.exp2(exp), 0)
    rgbe = np.zeros((h, w, 4), np.uint8)
    rgbe[..., :3] = np.clip(np.floor(rgb * scale[..., None]), 0, 255)
    rgbe[..., 3] = np.where(peak > 1e-32, exp + 128, 0)
    head = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode()
    path.write_bytes(head + rgbe.tobytes())
    return path


def write_exr(path: Path, rgb: np.ndarray) -> Path:
    """A float32 RGB .exr (OpenEXR)."""
    import OpenEXR

    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))
    return path


class LocalServer:
    """A threaded HTTP server on 127.0.0.1 serving ``routes`` (path with query → bytes).

    Honours ``Range: bytes=N-`` with 206. ``cut_once``: paths whose first answer announces the
    full length but sends only half and closes the connection. ``requests`` records
    ``(path, range header or None)`` in order.
    """

    def __init__(self, routes: dict[str, bytes], cut_once=()):
        self.routes = dict(routes)
        self.cut_once = set(cut_once)
        self.requests: list[tuple[str, str | None]] = []
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, *args):
                pass

            def do_GET(self):
                rng = self.headers.get("Range")
                server.requests.append((self.path, rng))
                body = server.routes.get(self.path)
                if body is None:
                    self.send_response(404)
                    self.send_header("Content-Length", "0")
                    self.end_headers()
                    return
                start = int(rng.split("=")[1].split("-")[0]) if rng else 0
                if start >= len(body) and rng:
                    self.send_response(416)
                    self.send_header("Content-Length", "0")
                    self.end_headers()
                    return
                part = body[start:]
                self.send_response(206 if rng else 200)
                self.send_header("Content-Length", str(len(part)))
                self.end_headers()
                if self.path in server.cut_once:
                    server.cut_once.discard(self.path)
                    self.wfile.write(part[: len(part) // 2])
                    self.wfile.flush()
                    self.close_connection = True
                    return
                self.wfile.write(part)

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        self.thread = threading.Thread(target=self.httpd.serve_forever, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.httpd.shutdown()
        self.httpd.server_close()


def run_worker(recipe: str, seed: int, out, options) -> None:
    """Run ``kubric worker RECIPE --seed SEED --out OUT --set ...`` in a fresh process; fail the
    test with its stderr tail if it fails."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "-m", "kubric", "worker", recipe, "--seed", str(seed), "--out",
           str(out)]
    for opt in options:
        cmd += ["--set", opt]
    proc = subprocess.run(cmd, cwd=root, capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
