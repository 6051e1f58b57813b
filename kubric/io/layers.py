"""The renderer's layer dict ↔ a scene directory (docs: ``docs/scene-format.md``).

Input to :func:`write_image_dict`: ``{layer name: (T, H, W, C) array}`` as returned by
``Blender.render()``; every layer must share T, H and W. Frame ``i`` (0-based) of a layer goes to
``<directory>/<template>.format(i)`` with these default templates and encodings (each encoding
is a layer kind of :mod:`kubric.io.encodings`, which does the work; the standard layers are
declared once, here, in :data:`LAYERS` — the renderers' :data:`RENDERED_LAYERS` and the viewer's
list derive from it):

=====================  ============================  ===  ======================================
layer                  file                          C    encoding
=====================  ============================  ===  ======================================
rgba                   ``rgba_{:05d}.png``           4    uint8 → 8-bit RGBA PNG
rgb                    ``rgb_{:05d}.png``            3    uint8 → 8-bit RGB PNG
depth, z               ``depth_{:05d}.tiff``         1    float → float32 TIFF (metres)
segmentation           ``segmentation_{:05d}.png``   1    integer labels → 8-bit palette PNG if
                                                          the scene's largest label ≤ 255, else
                                                          16-bit grey (> 65535 raises)
forward_flow,          ``forward_flow_{:05d}.png``   2    float → 16-bit RGB, channel 2 = 0,
backward_flow, flow                                       ``round((v - min) / (max - min) *
                                                          65535)`` with ONE min/max per layer per
                                                          scene, stored in ``data_ranges.json``
normal                 ``normal_{:05d}.png``         3    float in [-1, 1] → ``round((n + 1) / 2
                                                          * 65535)`` 16-bit RGB
object_coordinates,    ``uv_{:05d}.png`` ...         3    float in [0, 1] → ``round(x * 65535)``
uv                                                        16-bit RGB
defocus                ``defocus_{:05d}.tiff``       1    float → float32 TIFF (pixels: the
                                                          circle of confusion's diameter,
                                                          kubric.annotations.exposure)
exposure_flow          ``exposure_flow_{:05d}.png``  2    as forward_flow: the surface's motion
                                                          from shutter open to close
=====================  ============================  ===  ======================================

normal / object_coordinates / uv may also be given already quantised, as uint8 or uint16 samples
of their interval (as upstream Kubric accepted): they are stored as they are, 8- or 16-bit, and
read back as floats (a uint8 sample k of uv means k / 255; of normal, k / 255 · 2 − 1).
Floats for normal / object_coordinates / uv may exceed their interval by float noise up to
:data:`RANGE_TOLERANCE` (clipped); larger excursions, NaN and inf raise. ``data_ranges.json``
gets ``{"min", "max"}`` for every scaled layer and also for ``depth`` and ``z`` (an addition for
readers that quantise depth); an existing ``data_ranges.json`` is updated, not replaced.

:func:`read_image_dict` is the inverse: it finds the frames of every layer present, checks they
are numbered 0..T-1 and returns the same dict (flows float32 C = 2, normal / object_coordinates /
uv float32, depth / z float32, segmentation uint32, rgba uint8), exact up to the quantisation step
of each encoding (1/65535 of the range; normals 2/65535).
"""

from __future__ import annotations

import dataclasses
import re
import string
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from kubric.errors import InputError
from kubric.io import encodings, png_io
from kubric.io.encodings import RANGE_TOLERANCE, LayerKind, layer_kind  # noqa: F401
from kubric.io.json_io import read_json, write_json
from kubric.io.paths import PathLike, as_path, atomic_write_bytes, read_bytes

DATA_RANGES_FILE = "data_ranges.json"


@dataclasses.dataclass(frozen=True)
class LayerFormat:
    """How one layer is stored: default file template, channel count, encoding kind (the name
    of a :class:`kubric.io.encodings.LayerKind`, or the kind or its class: stored as its name)."""

    template: str
    channels: int
    kind: str  # a name of kubric.io.encodings.LAYER_KINDS

    def __post_init__(self):
        if isinstance(self.kind, LayerKind) or (isinstance(self.kind, type)
                                                 and issubclass(self.kind, LayerKind)):
            object.__setattr__(self, "kind", self.kind.name)

    @property
    def type(self) -> LayerKind:
        """The registered :class:`~kubric.io.encodings.LayerKind` of :attr:`kind`."""
        return layer_kind(self.kind)


#: The standard layers, declared once: name → (file template, channels, kind, what the viewer
#: calls it, how backends render it: "colour" (path traced), "exact" (one value per pixel
#: centre, docs/conventions.md) or None: upstream's file names ``rgb`` and ``flow``, read and
#: written but never rendered).
_STANDARD = (
    ("rgba", "rgba_{:05d}.png", 4, "image8", "RGB", "colour"),
    ("rgb", "rgb_{:05d}.png", 3, "image8", "RGB", None),
    ("depth", "depth_{:05d}.tiff", 1, "tiff", "depth (m)", "exact"),
    ("z", "z_{:05d}.tiff", 1, "tiff", "z (m)", "exact"),
    ("segmentation", "segmentation_{:05d}.png", 1, "labels", "segmentation", "exact"),
    ("forward_flow", "forward_flow_{:05d}.png", 2, "scaled", "forward flow (px)", "exact"),
    ("backward_flow", "backward_flow_{:05d}.png", 2, "scaled", "backward flow (px)", "exact"),
    ("flow", "flow_{:05d}.png", 2, "scaled", "flow (px)", None),
    ("normal", "normal_{:05d}.png", 3, "signed_unit", "normals", "exact"),
    ("object_coordinates", "object_coordinates_{:05d}.png", 3, "unit", "object coordinates",
     "exact"),
    ("uv", "uv_{:05d}.png", 3, "unit", "UV", "exact"),
    ("defocus", "defocus_{:05d}.tiff", 1, "tiff", "defocus (px)", None),
    ("exposure_flow", "exposure_flow_{:05d}.png", 2, "scaled", "exposure flow (px)", None),
    # a stereo rig's left image (kubric.recipes.rig_options, kubric.annotations.rig_views)
    ("disparity", "disparity_{:05d}.tiff", 1, "tiff", "disparity (px)", None),
    # opt-in ground truth from the scene model (kubric.renderer.scene_model_layers), written only
    # when a recipe's extra_layers asks (docs/conventions.md)
    ("amodal_segmentation", "amodal_segmentation_{:05d}.png", 4, "bitmask",
     "amodal segmentation (instances covering)", None),
    ("forward_scene_flow", "forward_scene_flow_{:05d}.tiff", 3, "vector",
     "forward scene flow (m, world)", None),
    ("backward_scene_flow", "backward_scene_flow_{:05d}.tiff", 3, "vector",
     "backward scene flow (m, world)", None),
    ("forward_scene_flow_camera", "forward_scene_flow_camera_{:05d}.tiff", 3, "vector",
     "forward scene flow (m, camera)", None),
    ("backward_scene_flow_camera", "backward_scene_flow_camera_{:05d}.tiff", 3, "vector",
     "backward scene flow (m, camera)", None),
    ("occlusion_boundaries", "occlusion_boundaries_{:05d}.png", 1, "edge_bits",
     "occlusion boundaries", None),
    ("material_ids", "material_ids_{:05d}.png", 1, "labels", "material ids", None),
    ("part_ids", "part_ids_{:05d}.png", 1, "labels", "part ids", None),
)
#: the standard layers' formats
LAYERS: dict[str, LayerFormat] = {name: LayerFormat(template, channels, kind)
                                  for name, template, channels, kind, _, _ in _STANDARD}
#: what the viewer calls each standard layer (a recipe's own layers: their name)
LAYER_LABELS: dict[str, str] = {row[0]: row[4] for row in _STANDARD}
#: the layers a rendering backend may be asked for (kubric.renderer.base.ALL_LAYERS)
RENDERED_LAYERS: tuple[str, ...] = tuple(row[0] for row in _STANDARD if row[5])
#: the exact annotation layers among them (kubric.renderer.base.ANNOTATION_LAYERS)
EXACT_LAYERS: tuple[str, ...] = tuple(row[0] for row in _STANDARD if row[5] == "exact")
#: every layer kind, by name (kubric.io.encodings.LAYER_KINDS)
LAYER_KINDS = encodings.LAYER_KINDS
#: the kinds whose layers get {"min", "max"} in data_ranges.json
RANGE_KINDS = tuple(name for name, kind in LAYER_KINDS.items() if kind.records_range)


def frame_filename(template: str, index: int) -> str:
    """``template`` formatted with frame ``index``; accepts ``{:05d}`` and ``{i:05d}`` fields."""
    try:
        return template.format(index, i=index)
    except (IndexError, KeyError, ValueError) as err:
        raise ValueError(f"file template {template!r} must have one field such as '{{:05d}}' or "
                         f"'{{i:05d}}' for the frame index: {err}") from None


def _template_regex(template: str) -> re.Pattern:
    parts = []
    for literal, field, _, _ in string.Formatter().parse(template):
        parts.append(re.escape(literal))
        if field is not None:
            parts.append(r"(\d+)")
    return re.compile("".join(parts) + r"\Z")


def layer_table(formats: Mapping[str, LayerFormat] | None = None) -> dict[str, LayerFormat]:
    """The standard :data:`LAYERS` plus ``formats`` (a recipe schema's own layers)."""
    table = dict(LAYERS)
    for name, fmt in dict(formats or {}).items():
        if not isinstance(fmt, LayerFormat) or fmt.kind not in LAYER_KINDS:
            raise ValueError(f"layer {name!r}: expected a LayerFormat with kind in "
                             f"{tuple(LAYER_KINDS)}, got {fmt!r}")
        table[name] = fmt
    return table


def _templates(file_templates: Mapping[str, str] | None, table: Mapping[str, LayerFormat]
               ) -> dict[str, str]:
    templates = {name: fmt.template for name, fmt in table.items()}
    for name, template in dict(file_templates or {}).items():
        if name not in table:
            raise ValueError(f"file_templates: unknown layer {name!r}; known: {sorted(table)}")
        frame_filename(template, 0)
        templates[name] = template
    return templates


# -------------------------------------------------------------------------------- encoding
def _prepare_layer(name: str, fmt: LayerFormat, data, ranges: dict
                   ) -> tuple[np.ndarray, Callable]:
    """Validate one (T, H, W, C) layer; return its per-frame samples and the frame encoder (its
    kind's); its range, if it has one, goes to ``ranges``."""
    what = f"write_image_dict: layer {name!r}"
    arr = np.asarray(data)
    if arr.ndim != 4 or arr.shape[-1] != fmt.channels or 0 in arr.shape:
        raise ValueError(f"{what}: expected shape (T, H, W, {fmt.channels}), got {arr.shape}")
    encode, value_range = fmt.type.encoder(arr, what)
    if value_range is not None:
        ranges[name] = value_range
    return arr, encode


def write_image_dict(data_dict: Mapping[str, np.ndarray], directory: PathLike,
                     file_templates: Mapping[str, str] | None = None,
                     max_write_threads: int = 16,
                     formats: Mapping[str, LayerFormat] | None = None) -> dict[str, dict[str, float]]:
    """Write every layer of ``data_dict`` into ``directory`` (see module docstring).

    ``formats`` adds layers beyond :data:`LAYERS` (a recipe schema's ``layers``).

    All layers are validated before any file is written; each file is written atomically by up to
    ``max_write_threads`` threads (zlib releases the GIL). Returns the ranges written to
    ``data_ranges.json``.
    """
    directory = as_path(directory)
    if max_write_threads < 1:
        raise ValueError(f"max_write_threads must be ≥ 1, got {max_write_threads}")
    table = layer_table(formats)
    unknown = sorted(set(data_dict) - set(table))
    if unknown:
        raise ValueError(f"write_image_dict: unknown layer(s) {unknown}; known: {sorted(table)}")
    templates = _templates(file_templates, table)
    ranges: dict[str, dict[str, float]] = {}
    prepared = {name: _prepare_layer(name, table[name], data, ranges)
                for name, data in data_dict.items()}
    shapes = {name: samples.shape[:3] for name, (samples, _) in prepared.items()}
    if len(set(shapes.values())) > 1:
        raise ValueError(f"write_image_dict: layers disagree on (T, H, W): {shapes}")
    jobs = [(samples[i], encode, directory / frame_filename(templates[name], i))
            for name, (samples, encode) in prepared.items() for i in range(samples.shape[0])]
    directory.mkdir(parents=True, exist_ok=True)

    def run(job):
        frame, encode, path = job
        atomic_write_bytes(encode(frame), path)

    if jobs:
        with ThreadPoolExecutor(max_workers=min(max_write_threads, len(jobs))) as pool:
            for _ in pool.map(run, jobs):  # re-raises the first exception
                pass
    if ranges:
        range_path = directory / DATA_RANGES_FILE
        merged = read_json(range_path) if range_path.exists() else {}
        merged.update(ranges)
        write_json(merged, range_path)
    return ranges


# -------------------------------------------------------------------------------- decoding
def _frame_paths(directory, template: str) -> list:
    """The frame files of ``template`` (which may start with sub-directories) in index order."""
    subdir, _, basename = template.rpartition("/")
    if "{" in subdir:
        raise ValueError(f"file template {template!r}: the frame index must be in the file name, "
                         "not in a directory name")
    folder = directory / subdir if subdir else directory
    pattern = _template_regex(basename)
    found = {}
    for path in (folder.iterdir() if folder.is_dir() else ()):
        match = pattern.match(path.name)
        if match and frame_filename(basename, int(match.group(1))) == path.name:
            found[int(match.group(1))] = path
    missing = sorted(set(range(len(found))) - set(found))
    if missing:
        raise InputError(f"{str(directory)!r}: frames of {template!r} must be numbered "
                         f"0..{len(found) - 1}; missing indices {missing[:10]}")
    return [found[i] for i in range(len(found))]


def _decode_frame(name: str, fmt: LayerFormat, path, value_range, raw: bool = False
                  ) -> np.ndarray:
    """One file's samples (``raw``: as stored) or their decode by the layer's kind."""
    what = repr(str(path))
    samples = fmt.type.read(read_bytes(path), what)
    if samples.shape[-1] < fmt.channels:
        raise InputError(f"{what}: layer {name!r} needs {fmt.channels} channels, the file has "
                         f"{samples.shape[-1]}")
    samples = samples[..., :fmt.channels]  # (a 2-channel layer's zero third channel dropped)
    return samples if raw else fmt.type.from_file(samples, value_range,
                                                  f"{what}: layer {name!r}")


def _layer_range(directory, name: str, value_range, fmt: LayerFormat):
    """The (min, max) that decodes a layer whose files need one (scaled): ``value_range`` or
    data_ranges.json's entry."""
    if not fmt.type.range_in_file:
        return value_range
    if value_range is None:
        range_path = directory / DATA_RANGES_FILE
        ranges = read_json(range_path) if range_path.exists() else {}
        if name not in ranges:
            raise InputError(f"{str(range_path)!r} has no range for layer {name!r}")
        value_range = ranges[name]
    return png_io.range_pair(value_range, f"read_layer({name!r})")


def read_frame(directory: PathLike, name: str, index: int, file_templates: Mapping[str, str]
               | None = None, value_range=None,
               formats: Mapping[str, LayerFormat] | None = None) -> np.ndarray:
    """Frame ``index`` (0-based) of one layer as an (H, W, C) array, decoded like
    :func:`read_layer` (which reads all frames); only that one file is read. ``formats`` adds
    layers beyond :data:`LAYERS` (a recipe schema's ``layers``)."""
    directory = as_path(directory)
    table = layer_table(formats)
    if name not in table:
        raise ValueError(f"read_frame: unknown layer {name!r}; known: {sorted(table)}")
    path = directory / frame_filename(_templates(file_templates, table)[name], int(index))
    if not path.is_file():
        raise FileNotFoundError(f"{str(directory)!r} has no frame {index} of layer {name!r}")
    fmt = table[name]
    return _decode_frame(name, fmt, path, _layer_range(directory, name, value_range, fmt))


def read_layer(directory: PathLike, name: str, file_templates: Mapping[str, str] | None = None,
               value_range=None, formats: Mapping[str, LayerFormat] | None = None,
               raw: bool = False) -> np.ndarray:
    """Read all frames of one layer from a scene directory as a (T, H, W, C) array.

    Scaled layers (flows) use ``value_range`` or else the entry in ``data_ranges.json``.
    ``formats`` adds layers beyond :data:`LAYERS`. ``raw=True`` returns the stored samples
    undecoded: uint16 for the 16-bit layers, labels as stored (uint8 / uint16).
    """
    directory = as_path(directory)
    table = layer_table(formats)
    if name not in table:
        raise ValueError(f"read_layer: unknown layer {name!r}; known: {sorted(table)}")
    fmt = table[name]
    paths = _frame_paths(directory, _templates(file_templates, table)[name])
    if not paths:
        raise FileNotFoundError(f"{str(directory)!r} has no frames of layer {name!r}")
    if not raw:
        value_range = _layer_range(directory, name, value_range, fmt)
    frames = [_decode_frame(name, fmt, p, value_range, raw) for p in paths]
    if len({f.shape for f in frames}) > 1:
        raise InputError(f"{str(directory)!r}: frames of layer {name!r} differ in shape")
    return np.stack(frames)


def read_image_dict(directory: PathLike, layers: Iterable[str] | None = None,
                    file_templates: Mapping[str, str] | None = None,
                    formats: Mapping[str, LayerFormat] | None = None) -> dict[str, np.ndarray]:
    """Decode a scene directory's layers back into the renderer's (T, H, W, C) layer dict.

    ``layers``: names to read (each must be present); None reads every known layer (of
    :data:`LAYERS` and ``formats``) that has at least one frame file.
    """
    directory = as_path(directory)
    if not directory.is_dir():
        raise NotADirectoryError(f"read_image_dict: {str(directory)!r} is not a directory")
    table = layer_table(formats)
    templates = _templates(file_templates, table)
    if layers is None:
        layers = [n for n in table if _frame_paths(directory, templates[n])]
    return {name: read_layer(directory, name, file_templates, formats=formats)
            for name in layers}


def read_segmentation(directory: PathLike, file_template: str | None = None) -> np.ndarray:
    """All segmentation frames of a scene directory, (T, H, W, 1) uint32 labels."""
    templates = None if file_template is None else {"segmentation": file_template}
    return read_layer(directory, "segmentation", templates)


# -------------------------------------------------------------------------------- batch writers
def _batch_writer(layer: str):
    default = LAYERS[layer].template

    def write_batch(data, directory: PathLike, file_template: str = default,
                    max_write_threads: int = 16) -> dict[str, dict[str, float]]:
        return write_image_dict({layer: data}, directory, {layer: file_template},
                                max_write_threads)
    write_batch.__name__ = f"write_{layer}_batch"
    write_batch.__doc__ = (f"Write a (T, H, W, C) ``{layer}`` layer as ``{default}`` files "
                           "(upstream's batch writer; same encoding as :func:`write_image_dict`).")
    return write_batch


#: upstream's per-layer batch writers: name → function
BATCH_WRITERS = {f"write_{layer}_batch": _batch_writer(layer) for layer in LAYERS}
BATCH_WRITERS["write_coordinates_batch"] = BATCH_WRITERS["write_object_coordinates_batch"]
