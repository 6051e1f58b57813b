"""``kubric inspect SCENE_DIR``: a text summary of a scene directory and a contact sheet.

The contact sheet shows, for up to ``max_rows`` evenly spaced frames (rows), the layers RGB,
segmentation (in the colours of the segmentation PNGs, :mod:`kubric.io.palette`), depth (a
viridis-like map over the scene's nearest to farthest surface, background black), forward flow
(the Middlebury wheel: hue = direction, saturation = magnitude relative to the scene's largest)
and normals ((n + 1) / 2) side by side, in the colours of ``kubric view``
(:mod:`kubric.annotations.pictures`). A ``.gif`` path writes an animation instead:
one image per frame with the same columns.
When the scene has ``tracks.npz``, the RGB column shows up to ``MAX_DRAWN_TRACKS`` point tracks
(:func:`draw_tracks`): a coloured trail over the last ``TRAIL_FRAMES`` frames (segments between
visible positions), a filled disc where
the point is visible and a hollow ring where it is occluded (nothing outside the image).
"""

from __future__ import annotations

import pathlib

import numpy as np

from kubric import file_io
from kubric.annotations import pictures
from kubric.annotations.track_files import TRACKS_FILE, read_tracks
from kubric.core.camera_geometry import BACKGROUND_DEPTH
from kubric.errors import InputError, UsageError
from kubric.io import storage
from kubric.io.palette import label_palette
from kubric.io.scene_dir import EVENTS_FILE, METADATA_FILE, complete_scenes, is_complete
from kubric.io.scene_writer import check_scene_content
from kubric.io.schema import SchemaError
from kubric.pipeline.recipe import scene_schema

COLUMNS = ("rgba", "segmentation", "depth", "forward_flow", "normal")
MAX_DRAWN_TRACKS = 64
TRAIL_FRAMES = 8


def colourise(name: str, layer: np.ndarray, background_depth: float | None = None) -> np.ndarray:
    """(T, H, W, C) layer → (T, H, W, 3) uint8 picture (:func:`kubric.annotations.pictures.
    layer_pictures`, the colouriser ``kubric view`` uses too)."""
    if name not in COLUMNS:
        raise InputError(f"no picture for layer {name!r}; allowed: {COLUMNS}")
    return pictures.layer_pictures(name, layer, BACKGROUND_DEPTH if background_depth is None
                                   else background_depth)


def track_colours(n: int) -> np.ndarray:
    """(n, 3) uint8 colour of each drawn track: the label palette without black."""
    return label_palette(n + 1)[1:]


def marker_radius(width: int) -> float:
    return max(2.0, width / 96.0)


def drawn_tracks(num_tracks: int) -> np.ndarray:
    """Indices of the tracks that are drawn (evenly spread, at most MAX_DRAWN_TRACKS)."""
    count = min(num_tracks, MAX_DRAWN_TRACKS)
    return np.unique(np.linspace(0, num_tracks - 1, count).round().astype(int)) if count else \
        np.zeros(0, dtype=int)


def draw_tracks(frames: np.ndarray, tracks: dict) -> np.ndarray:
    """Draw tracks (module doc) on (T, H, W, 3) uint8 frames; returns a copy."""
    from PIL import Image, ImageDraw
    t_count, h, w = frames.shape[:3]
    xy = np.asarray(tracks["target_points"], dtype=np.float64) - 0.5  # PIL: centres at integers
    occluded = np.asarray(tracks["occluded"], dtype=bool)
    reason = np.asarray(tracks.get("occlusion_reason", np.zeros(occluded.shape, np.uint8)))
    shown = (reason & 3) == 0  # not behind the camera, not outside the image
    picks = drawn_tracks(len(xy))
    colours = [tuple(int(v) for v in c) for c in track_colours(len(picks))]
    r = marker_radius(w)
    out = []
    for t in range(t_count):
        original = Image.fromarray(np.ascontiguousarray(frames[t]))
        im = original.copy()
        draw = ImageDraw.Draw(im)
        for colour, n in zip(colours, picks, strict=True):
            first = max(0, t - TRAIL_FRAMES)
            for a in range(first, t):
                if not (occluded[n, a] or occluded[n, a + 1]):
                    draw.line([tuple(xy[n, a]), tuple(xy[n, a + 1])], fill=colour, width=1)
        for colour, n in zip(colours, picks, strict=True):
            if not shown[n, t]:
                continue
            x, y = xy[n, t]
            box = [x - r, y - r, x + r, y + r]
            if occluded[n, t]:  # hollow: the picture (not trails) shows inside the ring
                mask = Image.new("L", im.size, 0)
                ImageDraw.Draw(mask).ellipse(box, fill=255)
                im.paste(original, (0, 0), mask)
                draw.ellipse(box, outline=colour, width=1)
            else:
                draw.ellipse(box, fill=colour)
        out.append(np.asarray(im))
    return np.stack(out)


def summarise(scene_dir: pathlib.Path, layers: dict, metadata: dict, events: dict) -> str:
    meta = metadata.get("metadata", {})
    lines = [f"scene {scene_dir}",
             f"  complete: {is_complete(scene_dir)}  seed: {meta.get('seed')}  "
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
                  max_rows: int = 6, tracks: dict | None = None) -> pathlib.Path:
    """Write the contact sheet (PNG) or animation (GIF) of the available COLUMNS (with
    ``tracks`` drawn on a copy of the RGB, a column of their own after it: the RGB stays clean)."""

    names = [n for n in COLUMNS if n in layers]
    if not names:
        raise InputError(f"no layer to show; expected some of {COLUMNS}")
    pictures = [colourise(n, layers[n], background_depth) for n in names]
    if tracks is not None and names[0] == "rgba":
        names.insert(1, "tracks")
        pictures.insert(1, draw_tracks(pictures[0], tracks))
    t = pictures[0].shape[0]
    scale = tile_scale(pictures[0].shape[2])
    pictures = [p.repeat(scale, axis=1).repeat(scale, axis=2) for p in pictures]  # nearest
    rows = [np.concatenate([p[i] for p in pictures], axis=1) for i in range(t)]
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".gif":
        frames = [labelled(names, [r], [i]) for i, r in enumerate(rows)]
        frames[0].save(path, save_all=True, append_images=frames[1:], duration=120, loop=0)
    else:
        picks = sorted(set(np.linspace(0, t - 1, min(max_rows, t)).round().astype(int)))
        labelled(names, [rows[i] for i in picks], picks).save(path)
    return path


#: contact sheet layout: tiles at least this wide (integer nearest-neighbour upscaling, so that
#: the labels fit), a header this high with the layer names, a gutter with the frame index
MIN_TILE_WIDTH = 96
HEADER = 14
GUTTER = 28


def tile_scale(width: int) -> int:
    """The integer factor a layer ``width`` px wide is enlarged by on a contact sheet."""
    return max(1, -(-MIN_TILE_WIDTH // max(1, width)))


def labelled(names, rows, frames):
    """A PIL image of picture ``rows`` (equal-width tiles, one per name) under a header naming
    each column's layer, each row preceded by its frame index (the files' ``_{index:05d}``)."""
    from PIL import Image, ImageDraw
    body = np.concatenate(rows, axis=0)
    tile_w, row_h = body.shape[1] // len(names), rows[0].shape[0]
    image = Image.new("RGB", (GUTTER + body.shape[1], HEADER + body.shape[0]), "white")
    image.paste(Image.fromarray(body), (GUTTER, HEADER))
    draw = ImageDraw.Draw(image)
    for k, name in enumerate(names):
        label = "rgb" if name == "rgba" else name
        draw.text((GUTTER + k * tile_w + 3, 2), label[:max(1, (tile_w - 4) // 6)], fill="black")
    for r, frame in enumerate(frames):
        draw.text((3, HEADER + r * row_h + 2), str(int(frame)), fill="black")
    return image


def default_sheet(scene_name: str) -> pathlib.Path:
    """Where the contact sheet goes without ``--sheet``: the current directory."""
    return pathlib.Path.cwd() / f"{scene_name}_contact_sheet.png"


def inspect_scene(scene_dir, sheet=None) -> str:
    """Summary text of ``scene_dir``; also writes the contact sheet and names it in the text.

    Read-only on the scene: the sheet goes to ``sheet`` or else to
    ``./{scene name}_contact_sheet.png`` in the current directory, never into the scene directory
    unless ``sheet`` says so (datasets may be read-only; finished scenes stay as written)."""
    scene_dir = pathlib.Path(scene_dir)
    if not scene_dir.is_dir():
        raise FileNotFoundError(f"{str(scene_dir)!r} is not a directory")
    meta_path = scene_dir / METADATA_FILE
    inside = complete_scenes(scene_dir)
    if inside and not meta_path.exists():  # the output folder of generate, not one scene
        raise UsageError(f"{str(scene_dir)!r} is a folder of {len(inside)} scenes, not a scene: "
                         f"inspect one of them, e.g. kubric inspect {scene_dir / inside[0]}")
    metadata = file_io.read_json(meta_path) if meta_path.exists() else {}
    events_path = scene_dir / EVENTS_FILE
    events = file_io.read_json(events_path) if events_path.exists() else {}
    schema, origin = _schema_of(scene_dir)
    layers = file_io.read_image_dict(scene_dir, formats=schema.layers if schema else None)
    if not layers:
        raise InputError(f"{str(scene_dir)!r} holds no image layers")
    sheet = pathlib.Path(sheet) if sheet else default_sheet(scene_dir.resolve().name)
    background = metadata.get("metadata", {}).get("background_depth", BACKGROUND_DEPTH)
    tracks, extra = None, ""
    if (scene_dir / TRACKS_FILE).exists():
        tracks = read_tracks(scene_dir / TRACKS_FILE)
        extra = (f"\n  tracks: {len(tracks['target_points'])} ({int(tracks['is_foreground'].sum())}"
                 f" on objects), occluded {float(tracks['occluded'].mean()):.1%} of "
                 f"point-frames; {len(drawn_tracks(len(tracks['target_points'])))} drawn")
    contact_sheet(layers, background, sheet, tracks=tracks)
    return (summarise(scene_dir, layers, metadata, events) + "\n" + schema_line(
        schema, layers, metadata, events, origin) + extra + f"\n  contact sheet: {sheet}")


def inspect_url(scene_url: str, sheet=None) -> str:
    """:func:`inspect_scene` for a scene at an fsspec URL (e.g. ``s3://bucket/run/scene_…``):
    only a complete scene (``_SUCCESS`` present) is read; it is downloaded into a temporary
    directory. The contact sheet defaults to ``./{scene name}_contact_sheet.png``."""
    import tempfile

    scene_url = storage.normalise(scene_url)
    if not is_complete(scene_url):
        what = "does not exist" if not storage.listdir(scene_url) else \
            "is incomplete (no _SUCCESS: an interrupted or running upload)"
        raise FileNotFoundError(f"{scene_url!r} {what}")
    name = scene_url.rsplit("/", 1)[-1]
    sheet = pathlib.Path(sheet) if sheet else default_sheet(name)
    with tempfile.TemporaryDirectory(prefix="kubric-inspect-") as tmp:
        local = storage.download_dir(scene_url, pathlib.Path(tmp) / name)
        report = inspect_scene(local, sheet.resolve())
    return report.replace(str(local), scene_url, 1)


def _schema_of(scene_dir: pathlib.Path):
    """(the scene's schema or None, where it came from or why there is none): the schema the
    scene stores, else its recipe's (:func:`~kubric.pipeline.recipe.scene_schema`)."""
    try:
        found = scene_schema(scene_dir)
    except (SchemaError, OSError, ValueError) as err:
        return None, str(err)
    return found.schema, found.origin


def schema_line(schema, layers: dict, metadata: dict, events: dict, origin: str = "") -> str:
    """One line: does the scene hold every source of its schema's features?"""
    if schema is None:
        return f"  schema: none known: {origin}"
    where = f" (from {origin})" if origin else ""
    try:
        check_scene_content(schema, layers, metadata, events)
    except SchemaError as err:
        return (f"  schema {schema.name}{where}: {len(schema.features)} features; NOT "
                f"satisfied: {err}")
    return f"  schema {schema.name}{where}: {len(schema.features)} features, every source present"
