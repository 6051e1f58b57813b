"""File encodings of Kubric's outputs (the public entry point is :mod:`kubric.file_io`).

Modules, one concept each:

* :mod:`kubric.io.paths` — ``as_path`` and atomic writes (temporary file + ``os.replace``).
* :mod:`kubric.io.json_io` — deterministic, numpy-aware JSON and pickle.
* :mod:`kubric.io.png_io` — PNG 8/16-bit encoder (numpy + zlib), palette and scaled PNG, readers.
* :mod:`kubric.io.tiff_io` — float32 TIFF encoder and reader.
* :mod:`kubric.io.layers` — the renderer's layer dict ↔ a scene directory (``write_image_dict``).
* :mod:`kubric.io.schema` — a recipe's output contract (layers + example features), declared once.
* :mod:`kubric.io.scene_writer` — ``write_scene``: a scene directory checked against its schema.
"""
