"""``kubric inspect SCENE_DIR``: a text summary of a scene directory and a contact sheet.

The contact sheet shows, for up to ``max_rows`` evenly spaced frames (rows), the layers RGB,
segmentation (one colour per label), depth (near = bright, background black), forward flow
(hue = direction, saturation = magnitude relative to the largest) and normals ((n + 1) / 2) side
by side. A ``.gif`` path writes an animation instead: one image per frame with the same columns.
"""

from __future__ import annotations

import colorsys
import pathlib

import numpy as np

COLUMNS = ("rgba", "segmentation", "depth", "forward_flow", "normal")


def _palette(n: int) -> np.ndarray:
    """(n, 3) uint8 colours; label 0 black, then distinct hues."""
    colours = [(0, 0, 0)]
    for k in range(1, n):
        h = (k * 0.618033988749895) % 1.0
        colours.append(tuple(int(255 * c) for c in colorsys.hsv_to_rgb(h, 0.75, 0.95)))
    return np.asarray(colours, dtype=np.uint8)


def hsv_to_rgb(h, s, v) -> np.ndarray:
    """Vectorised HSV (each in [0, 1]) → (..., 3) RGB in [0, 1]."""
    i = np.floor(h * 6.0).astype(np.int64) % 6
    f = h * 6.0 - np.floor(h * 6.0)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack([np.stack(c, axis=-1) for c in
                      ((v, t, p), (q, v, p), (p, v, t), (p, q, v), (t, p, v), (v, p, q))])
    index = np.broadcast_to(i[None, ..., None], (1, *i.shape, 3))
    return np.take_along_axis(table, index, axis=0)[0]


def colourise(name: str, layer: np.ndarray, background_depth: float | None = None) -> np.ndarray:
    """(T, H, W, C) layer → (T, H, W, 3) uint8 picture (see module doc)."""
    if name == "rgba":
        rgb = layer[..., :3].astype(np.float32)
        alpha = layer[..., 3:4].astype(np.float32) / 255.0 if layer.shape[-1] == 4 else 1.0
        return (rgb * alpha).astype(np.uint8)
    if name == "segmentation":
        labels = layer[..., 0].astype(np.int64)
        return _palette(int(labels.max()) + 1)[labels]
    if name == "depth":
        d = layer[..., 0].astype(np.float64)
        hit = d < (background_depth if background_depth is not None else np.inf) * 0.999
        out = np.zeros(d.shape, dtype=np.float64)
        if hit.any():
            near, far = d[hit].min(), d[hit].max()
            out[hit] = 1.0 - 0.8 * (d[hit] - near) / max(far - near, 1e-9)
        return np.repeat((out * 255).astype(np.uint8)[..., None], 3, axis=-1)
    if name in ("forward_flow", "backward_flow"):
        dy, dx = layer[..., 0].astype(np.float64), layer[..., 1].astype(np.float64)
        mag = np.hypot(dx, dy)
        hue = (np.arctan2(dy, dx) / (2 * np.pi)) % 1.0
        sat = mag / max(mag.max(), 1e-9)
        return (hsv_to_rgb(hue, sat, np.ones_like(hue)) * 255).astype(np.uint8)
    if name == "normal":
        return ((np.clip(layer, -1, 1) + 1) / 2 * 255).astype(np.uint8)
    raise ValueError(f"no picture for layer {name!r}; allowed: {COLUMNS}")


def summarise(scene_dir: pathlib.Path, layers: dict, metadata: dict, events: dict) -> str:
    meta = metadata.get("metadata", {})
    lines = [f"scene {scene_dir}",
             f"  complete: {(scene_dir / '_SUCCESS').exists()}  seed: {meta.get('seed')}  "
             f"resolution: {meta.get('resolution')}  frames: {meta.get('num_frames')} "
             f"({meta.get('frame_start')}..{meta.get('frame_end')})  background: "
             f"{meta.get('background')}"]
    for name, arr in layers.items():
        lines.append(f"  {name:<20} {str(arr.shape):<22} {str(arr.dtype):<8} "
                     f"min {float(arr.min()):.4g} max {float(arr.max()):.4g}")
    instances = metadata.get("instances", [])
    lines.append(f"  instances: {len(instances)}")
    for k, inst in enumerate(instances, start=1):
        label = inst.get("shape") or inst.get("asset_id")
        extra = " ".join(str(inst[key]) for key in ("size_label", "color_label", "material")
                         if inst.get(key))
        lines.append(f"    {k:>3}: {label} {extra}  visible px {int(np.sum(inst.get('visibility', 0)))}"
                     f"  boxes in {len(inst.get('bbox_frames', []))} frames")
    positions = np.asarray(metadata.get("camera", {}).get("positions", np.zeros((1, 3))))
    path = float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=-1)))
    lines.append(f"  camera path length: {path:.3f} m;  collisions: "
                 f"{len(events.get('collisions', []))}")
    return "\n".join(lines)


def contact_sheet(layers: dict, background_depth: float | None, path: pathlib.Path,
                  max_rows: int = 6) -> pathlib.Path:
    """Write the contact sheet (PNG) or animation (GIF) of the available COLUMNS."""
    from PIL import Image

    names = [n for n in COLUMNS if n in layers]
    if not names:
        raise ValueError(f"no layer to show; expected some of {COLUMNS}")
    pictures = [colourise(n, layers[n], background_depth) for n in names]
    t = pictures[0].shape[0]
    rows = [np.concatenate([p[i] for p in pictures], axis=1) for i in range(t)]
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        frames = [Image.fromarray(r) for r in rows]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=120, loop=0)
    else:
        picks = sorted(set(np.linspace(0, t - 1, min(max_rows, t)).round().astype(int)))
        Image.fromarray(np.concatenate([rows[i] for i in picks], axis=0)).save(path)
    return path


def inspect_scene(scene_dir, sheet=None) -> str:
    """Summary text of ``scene_dir``; also writes the contact sheet (default
    ``SCENE_DIR/contact_sheet.png``) and names it in the text."""
    from kubric import file_io
    from kubric.core.camera_geometry import BACKGROUND_DEPTH

    scene_dir = pathlib.Path(scene_dir)
    if not scene_dir.is_dir():
        raise FileNotFoundError(f"{str(scene_dir)!r} is not a directory")
    meta_path = scene_dir / "metadata.json"
    metadata = file_io.read_json(meta_path) if meta_path.exists() else {}
    events_path = scene_dir / "events.json"
    events = file_io.read_json(events_path) if events_path.exists() else {}
    schema = _schema_of(metadata)
    layers = file_io.read_image_dict(scene_dir, formats=schema.layers if schema else None)
    if not layers:
        raise ValueError(f"{str(scene_dir)!r} holds no image layers")
    sheet = pathlib.Path(sheet) if sheet else scene_dir / "contact_sheet.png"
    background = metadata.get("metadata", {}).get("background_depth", BACKGROUND_DEPTH)
    contact_sheet(layers, background, sheet)
    return (summarise(scene_dir, layers, metadata, events) + "\n" + schema_line(
        schema, layers, metadata, events) + f"\n  contact sheet: {sheet}")


def _schema_of(metadata: dict):
    """The recipe schema named by ``flags.recipe`` (None when unknown)."""
    from kubric.io.schema import SchemaError, get_schema
    recipe = metadata.get("flags", {}).get("recipe")
    try:
        return get_schema(recipe) if recipe else None
    except SchemaError:
        return None


def schema_line(schema, layers: dict, metadata: dict, events: dict) -> str:
    """One line: does the scene hold every source of its recipe schema's features?"""
    from kubric.io.scene_writer import check_scene_content
    from kubric.io.schema import SchemaError
    if schema is None:
        return "  schema: none known for recipe " + repr(metadata.get("flags", {}).get("recipe"))
    try:
        check_scene_content(schema, layers, metadata, events)
    except SchemaError as err:
        return f"  schema {schema.name}: {len(schema.features)} features; NOT satisfied: {err}"
    return f"  schema {schema.name}: {len(schema.features)} features, every source present"
