"""File encodings of Kubric's outputs (the public entry point is :mod:`kubric.file_io`).

Modules, one concept each:

* :mod:`kubric.io.paths` — ``as_path`` and atomic writes (temporary file + ``os.replace``).
* :mod:`kubric.io.json_io` — deterministic, numpy-aware JSON and pickle.
* :mod:`kubric.io.png_io` — PNG 8/16-bit and palette encoder (numpy + zlib), scaled PNG; reading
  via libpng (imagecodecs) and Pillow (palette).
* :mod:`kubric.io.palette` — the label colours of segmentation PNGs and contact sheets.
* :mod:`kubric.io.tiff_io` — float32 TIFF encoder; reading via libtiff (imagecodecs).
* :mod:`kubric.io.layers` — the renderer's layer dict ↔ a scene directory (``write_image_dict``).
* :mod:`kubric.io.schema` — a recipe's output contract (layers + example features), declared once.
* :mod:`kubric.io.scene_writer` — ``write_scene``: a scene directory checked against its schema.
* :mod:`kubric.io.stored_schema` — a scene's ``schema.json`` (how every reader reads the scene)
  and the check that every file of a scene is declared.
"""
