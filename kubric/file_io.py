"""Reading and writing Kubric's output files: every layer encoding and its inverse.

This is the public facade (``kb.write_png``, ``kb.write_image_dict``, ...); the code lives in
:mod:`kubric.io` (one module per format). Formats follow ``docs/scene-format.md``:

* PNG 8/16-bit with 1–4 channels (2 channels padded to 3) — :func:`write_png` / :func:`read_png`;
* label PNG: 8-bit palette, 16-bit grey beyond 255 labels, never wrapping —
  :func:`write_palette_png` / :func:`read_palette_png`;
* scaled 16-bit PNG returning its ``{"min", "max"}`` — :func:`write_scaled_png` /
  :func:`read_scaled_png`;
* float32 TIFF — :func:`write_tiff` / :func:`read_tiff`;
* deterministic numpy-aware JSON and pickle — :func:`write_json`, :func:`read_json`,
  :func:`write_pkl`, :func:`read_pkl`;
* a whole scene's layer dict ↔ directory, with ``data_ranges.json`` — :func:`write_image_dict` /
  :func:`read_image_dict` / :func:`read_layer` / :func:`read_segmentation`;
* upstream's batch writers ``write_<layer>_batch`` (the flow ones with ``name=`` and
  ``range_file=``) and :func:`multi_write_image` (:mod:`kubric.io.batch`).

Every writer accepts ``str`` or :class:`pathlib.Path`, creates missing parent directories and
writes atomically (temporary file in the same directory, then :func:`os.replace`).
"""

from kubric.io.json_io import dumps_json, read_json, read_pkl, to_jsonable, write_json, write_pkl
from kubric.io.layers import (
    BATCH_WRITERS,
    DATA_RANGES_FILE,
    LAYERS,
    read_image_dict,
    read_layer,
    read_segmentation,
    write_image_dict,
)
from kubric.io.paths import as_path, atomic_write_bytes
from kubric.io.png_io import (
    decode_png,
    default_palette,
    encode_png,
    read_palette_png,
    read_png,
    read_scaled_png,
    write_palette_png,
    write_png,
    write_scaled_png,
)
from kubric.io.tiff_io import decode_tiff, encode_tiff, read_tiff, write_tiff

# upstream's write_rgba_batch, write_depth_batch, write_segmentation_batch, ...
globals().update(BATCH_WRITERS)
# ... and the flow writers with upstream's name= / range_file= keywords, multi_write_image
from kubric.io.batch import (  # noqa: E402,F401  (in __all__ through BATCH_WRITERS' names)
    multi_write_image,
    write_backward_flow_batch,
    write_flow_batch,
    write_forward_flow_batch,
)

__all__ = sorted(BATCH_WRITERS) + ["multi_write_image"] + [
    "DATA_RANGES_FILE", "LAYERS", "as_path", "atomic_write_bytes", "decode_png", "decode_tiff",
    "default_palette", "dumps_json", "encode_png", "encode_tiff", "read_image_dict", "read_json",
    "read_layer", "read_palette_png", "read_pkl", "read_png", "read_scaled_png",
    "read_segmentation", "read_tiff", "to_jsonable", "write_image_dict", "write_json",
    "write_palette_png", "write_pkl", "write_png", "write_scaled_png", "write_tiff",
]
