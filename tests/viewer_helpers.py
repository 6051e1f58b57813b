"""Shared by the viewer tests: a synthetic scene directory written with kubric.io, a server on a
free port in a background thread, and raw HTTP requests."""

from __future__ import annotations

import contextlib
import http.client
import json
import threading

import numpy as np

from kubric import file_io
from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.viewer.server import make_server
from kubric.viewer.service import ViewerService
from kubric.viewer.source import DirectorySource

T, H, W = 3, 12, 16
#: the camera of the synthetic scene: at (0, 0, 10) looking straight down (-z world)
CAMERA_TO_WORLD = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 10], [0, 0, 0, 1]])
FOCAL_PX = 20.0


def synthetic_scene(directory, seed=3, success=True):
    """A scene directory with one square object (label 1) moving right by one pixel a frame."""
    rng = np.random.default_rng(seed)
    depth = np.full((T, H, W, 1), BACKGROUND_DEPTH, np.float32)
    seg = np.zeros((T, H, W, 1), np.uint32)
    for t in range(T):
        depth[t, :, :, 0] = 10.0 + rng.random((H, W)).astype(np.float32)
        seg[t, 3:8, 4 + t:9 + t] = 1
        depth[t, 0, 0] = BACKGROUND_DEPTH
    flow = rng.normal(size=(T, H, W, 2)).astype(np.float32)
    layers = {"rgba": rng.integers(0, 255, (T, H, W, 4), dtype=np.uint8), "depth": depth,
              "segmentation": seg, "forward_flow": flow,
              "normal": np.tile(np.float32([0, 0, 1]), (T, H, W, 1))}
    file_io.write_image_dict(layers, directory)
    k = [[FOCAL_PX, 0, W / 2], [0, FOCAL_PX, H / 2], [0, 0, 1]]
    meta = {"flags": {"recipe": "movi_a", "seed": seed, "resolution": [W, H], "samples": 2,
                      "denoise": False, "kubasic_source": None},
            "metadata": {"seed": seed, "resolution": [W, H], "num_frames": T, "frame_start": 1,
                         "frame_rate": 12},
            "camera": {"intrinsics_pixels": k, "matrices_world": [CAMERA_TO_WORLD.tolist()] * T,
                       "positions": [[0, 0, 10]] * T, "resolution": [W, H]},
            "instances": [{"asset_id": "cube", "positions": [[t, 0, 0.5] for t in range(T)],
                           "visibility": [25, 25, 25], "bbox_frames": [0, 1, 2],
                           "bboxes": [[3 / H, (4 + t) / W, 8 / H, (9 + t) / W] for t in range(T)]}]}
    file_io.write_json(meta, directory / "metadata.json")
    file_io.write_json({"collisions": [{"instances": [0, -1], "frame": 1.5, "force": 2.0}]},
                       directory / "events.json")
    if success:
        (directory / "_SUCCESS").write_text("")
    return layers, meta


@contextlib.contextmanager
def serving(path, service_class=ViewerService, **kwargs):
    """(host, port) of a viewer (a ``service_class``) serving ``path``, in a background thread."""
    service = service_class(DirectorySource(path), **kwargs)
    server = make_server(service, "127.0.0.1", 0)
    thread = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    try:
        yield server.server_address[:2], service
    finally:
        server.shutdown()
        server.server_close()


def request(address, target, method="GET"):
    """(status, content type, body bytes) of a raw request (``target`` is sent unchanged)."""
    conn = http.client.HTTPConnection(*address, timeout=10)
    try:
        conn.putrequest(method, target, skip_accept_encoding=True)
        conn.putheader("Content-Length", "0")
        conn.endheaders()
        response = conn.getresponse()
        return response.status, response.getheader("Content-Type"), response.read()
    finally:
        conn.close()


def get_json(address, target):
    status, _, body = request(address, target)
    return status, json.loads(body)
