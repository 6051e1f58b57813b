"""What the viewer's JSON / PNG endpoints answer, on top of a :class:`~kubric.viewer.source.
SceneSource`, with an LRU cache of decoded frames and rendered pictures (so switching frames,
hovering and toggling layers re-read nothing)."""

from __future__ import annotations

import collections
import shlex
import threading

import numpy as np

from kubric.annotations import pictures as render
from kubric.core.camera_geometry import BACKGROUND_DEPTH, pinhole_rays
from kubric.core.lenses import from_camera_record
from kubric.viewer.source import SceneError, SceneSource, event_layer_camera, is_event_layer

#: default cache size in bytes (decoded frames + PNG bytes)
CACHE_BYTES = 512 * 2**20
#: tracks sent to the page (evenly spread)
MAX_TRACKS = 64
#: pictures the server derives from a scene's files beyond its layers
DERIVED_PICTURES = ("outline", "fill", "events")


class LRUCache:
    """A thread-safe mapping capped by the total ``nbytes`` of its values (least recent out)."""

    def __init__(self, max_bytes: int = CACHE_BYTES):
        self.max_bytes = int(max_bytes)
        self._items: collections.OrderedDict = collections.OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get_or_make(self, key, make):
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                self.hits += 1
                return self._items[key]
            self.misses += 1
        value = make()  # outside the lock: other threads keep serving
        size = value.nbytes if isinstance(value, np.ndarray) else len(value)
        with self._lock:
            if key not in self._items:
                self._items[key] = value
                self._bytes += size
            while self._bytes > self.max_bytes and len(self._items) > 1:
                _, old = self._items.popitem(last=False)
                self._bytes -= old.nbytes if isinstance(old, np.ndarray) else len(old)
        return value


    def discard(self, key) -> None:
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= old.nbytes if isinstance(old, np.ndarray) else len(old)


def _scalar(value) -> str:
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ",".join(_scalar(v) for v in value)
    return str(value)


def worker_command(flags: dict, out: str = "OUT") -> str:
    """The ``kubric worker`` command line that regenerates a scene from its ``flags``."""
    if "recipe" not in flags or "seed" not in flags:
        raise SceneError("metadata.json flags lack 'recipe' or 'seed': the scene cannot be "
                         "reproduced from its metadata")
    parts = ["kubric", "worker", str(flags["recipe"]), "--seed", str(flags["seed"]), "--out", out]
    for key, value in flags.items():
        if key not in ("recipe", "seed"):
            parts += ["--set", f"{key}={_scalar(value)}"]
    return shlex.join(parts)


class ViewerService:
    """The answers of the server's endpoints (see :mod:`kubric.viewer.server`)."""

    def __init__(self, source: SceneSource, cache_bytes: int = CACHE_BYTES):
        self.source = source
        self.cache = LRUCache(cache_bytes)

    # ------------------------------------------------------------------ JSON
    def summary(self, name: str) -> dict:
        """The scene's list row; cached once the scene is complete (an incomplete scene's row is
        read again, so a scene being written turns "ok" when its ``_SUCCESS`` appears)."""
        row = self.cache.get_or_make(("summary", name), lambda: _Json(self.source.summary(name)))
        if row.value["error"] is not None:
            self.cache.discard(("summary", name))
        return row.value

    def scene_list(self) -> dict:
        """One row per scene; a scene whose row cannot be made is a row with its error."""
        rows = []
        for name in self.source.names():
            try:
                rows.append(self.summary(name))
            except Exception as err:  # noqa: BLE001 - one bad scene never empties the list
                message = " ".join(str(err).split())[:300] or type(err).__name__
                rows.append({"name": name, "recipe": None, "seed": None, "split": None,
                             "num_instances": None, "num_frames": None, "resolution": None,
                             "layers": [], "has_tracks": False,
                             "error": f"{name}: cannot be listed: {message}"})
        return {"scenes": rows}

    def scene(self, name: str) -> dict:
        summary = self.summary(name)
        if summary["error"] and (summary["recipe"] is None or summary["num_frames"] is None):
            raise SceneError(summary["error"])
        meta = self.source.metadata(name)
        try:
            command = worker_command(meta.get("flags", {}), self.source.output_root(name))
        except SceneError as err:
            command = f"# {err}"
        layers = self.source.vocabulary(name)
        for layer in summary["layers"]:  # events.h5, and a rig's events_NAME.h5
            if is_event_layer(layer):
                layers[layer] = {"label": f"{layer} (ON red, OFF blue)", "kind": "events",
                                 "adjustable_range": False}
        for layer in summary["layers"]:  # the range a depth-like layer is first drawn over
            if layers[layer]["adjustable_range"]:
                try:
                    layers[layer]["range"] = list(render.depth_range(self.frame(name, layer, 0)))
                except SceneError:
                    layers[layer]["range"] = None
        depth_range = layers.get("depth", {}).get("range")
        return {"summary": summary, "metadata": meta, "events": self.source.events(name),
                "worker_command": command, "depth_range": depth_range, "layers": layers,
                "palette": render.label_palette(len(meta.get("instances", [])) + 1).tolist()}

    def tracks(self, name: str) -> dict | None:
        tracks = self.source.tracks(name)
        if tracks is None:
            return None
        n = len(tracks["target_points"])
        picks = np.unique(np.linspace(0, n - 1, min(n, MAX_TRACKS)).round().astype(int)) if n \
            else np.zeros(0, dtype=int)
        return {"num_tracks": n, "indices": picks.tolist(),
                "target_points": np.round(tracks["target_points"][picks], 3).tolist(),
                "occluded": tracks["occluded"][picks].astype(bool).tolist()}

    # ------------------------------------------------------------------ frames
    def frame(self, name: str, layer: str, index: int) -> np.ndarray:
        return self.cache.get_or_make(("frame", name, layer, index),
                                      lambda: self.source.frame(name, layer, index))

    def event_frame(self, name: str, index: int, camera: str | None = None) -> np.ndarray:
        """(H, W, 3) uint8 accumulated events of frame ``index``: those with
        t_{index−1} < t ≤ t_index (t_i = i / frame_rate s, the file frames' times; frame 0: t ≤ 0),
        drawn by :func:`kubric.annotations.pictures.event_picture`; of rig camera ``camera``'s
        stream when given."""
        meta = self.source.metadata(name)
        info = meta.get("metadata", {})
        count, rate = self.summary(name)["num_frames"] or 1, info.get("frame_rate")
        if not 0 <= index < count:
            raise KeyError(f"event frame {index} is outside frames 0..{count - 1}")
        if not isinstance(rate, int | float) or isinstance(rate, bool) or rate <= 0:
            raise SceneError(f"{name}/metadata.json: frame_rate {rate!r} is not a positive "
                             "number: the event frames cannot be timed")
        stream = self.cache.get_or_make(("events", name, camera),
                                        lambda: self._event_array(name, camera))
        x, y, t, p = stream
        w, h = info.get("resolution") or meta["camera"]["resolution"]
        t0, t1 = (index - 1) * 1e6 / rate, index * 1e6 / rate
        lo = 0 if index == 0 else int(np.searchsorted(t, t0, side="right"))
        hi = int(np.searchsorted(t, t1, side="right"))
        return render.event_picture(x[lo:hi], y[lo:hi], p[lo:hi], h, w)

    def _event_array(self, name: str, camera: str | None = None) -> np.ndarray:
        """(4, N) int64 rows x, y, t (µs), p of the scene's event stream (rig camera
        ``camera``'s when given); KeyError when none."""
        events = self.source.event_stream(name, camera)
        if events is None:
            what = f"camera {camera!r}" if camera else "events.h5: --set events=true"
            raise KeyError(f"{name} has no event stream ({what})")
        return np.stack([np.asarray(events[k], np.int64) for k in ("x", "y", "t", "p")]) \
            .reshape(4, -1)

    def picture_png(self, name: str, layer: str, index: int, lo: float | None = None,
                    hi: float | None = None) -> bytes:
        """PNG bytes of a layer frame; ``layer`` may also be one of :data:`DERIVED_PICTURES`
        (segmentation ``outline`` / ``fill`` overlays, accumulated ``events``; a rig camera's
        ``NAME_events``)."""
        def make():
            if layer in ("outline", "fill"):
                labels = self.frame(name, "segmentation", index)
                return render.to_png(render.outline(labels) if layer == "outline"
                                     else render.fill(labels))
            if is_event_layer(layer):  # events.h5, or a rig camera's events_NAME.h5
                return render.to_png(self.event_frame(name, index, event_layer_camera(layer)))
            fmt = self.source.formats(name).get(layer)
            return render.to_png(render.picture(layer, self.frame(name, layer, index), lo, hi,
                                                fmt.kind if fmt is not None else None))
        return self.cache.get_or_make(("png", name, layer, index, lo, hi), make)

    def probe(self, name: str, index: int, col: int, row: int) -> dict:
        """What the files hold at pixel (row, col) of frame ``index``."""
        meta = self.source.metadata(name)
        w, h = meta.get("metadata", {}).get("resolution") or meta["camera"]["resolution"]
        if not (0 <= col < w and 0 <= row < h):
            raise KeyError(f"pixel (row {row}, col {col}) is outside the {w}x{h} image")
        layers = self.summary(name)["layers"]
        out: dict = {"frame": index, "row": row, "col": col}
        if "segmentation" in layers:
            label = int(self.frame(name, "segmentation", index)[row, col, 0])
            instances = meta.get("instances", [])
            out["label"] = label
            out["instance"] = label - 1 if label else None
            out["asset_id"] = instances[label - 1].get("asset_id") if 0 < label <= len(
                instances) else None
        if "rgba" in layers:
            out["rgba"] = self.frame(name, "rgba", index)[row, col].tolist()
        for flow in ("forward_flow", "backward_flow"):
            if flow in layers:
                out[flow] = [float(v) for v in self.frame(name, flow, index)[row, col]]
        if "depth" in layers:
            depth = float(self.frame(name, "depth", index)[row, col, 0])
            hit = depth < BACKGROUND_DEPTH * 0.999
            out["depth"] = depth
            out["background"] = not hit
            out["point"] = _unproject(meta.get("camera", {}), index, col, row, depth) if hit \
                else None
        return out


class _Json:
    """A JSON-able value with a size, for the cache."""

    def __init__(self, value):
        self.value = value

    def __len__(self):
        return 256


def _unproject(camera: dict, index: int, col: int, row: int, depth: float) -> list | None:
    """World point of pixel (row, col) at ``depth`` metres along its pixel-centre ray (camera
    conventions of :mod:`kubric.core.camera_geometry`, through the camera's lens); None for
    cameras without pixel intrinsics (orthographic) and pixels without a lens ray."""
    if "intrinsics_pixels" not in camera or "matrices_world" not in camera:
        return None
    k = np.asarray(camera["intrinsics_pixels"], dtype=np.float64)
    m = np.asarray(camera["matrices_world"][index], dtype=np.float64)
    origin, ray = pinhole_rays(k, m, [col + 0.5, row + 0.5], from_camera_record(camera))
    return None if not np.isfinite(ray).all() else (origin + ray * depth).tolist()
