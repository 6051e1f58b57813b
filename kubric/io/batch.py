"""Upstream Kubric's batch writers with their keyword arguments (``kubric.file_io``).

* :func:`multi_write_image` — ``write_fn(image, path, **kwargs)`` for every image of a batch, the
  path being ``path_template`` formatted with the 0-based image index, on up to
  ``max_write_threads`` threads. Any writer taking ``(array, filename)`` works (``write_png``,
  ``write_palette_png`` with ``palette=``, ``write_tiff``, ...).
* :func:`write_flow_batch` — a (T, H, W, 2) float flow as 16-bit PNGs, scaled with ONE min/max over
  the batch (``round((v - min) / (max - min) * 65535)``, the scene format's flow encoding) and that
  ``{"min", "max"}`` merged into ``<directory>/<range_file>`` under the key ``name``; so a flow
  written with ``name="forward_flow"`` and any ``file_template`` decodes with
  ``read_scaled_png(path, ranges["forward_flow"])``. :func:`write_forward_flow_batch` /
  :func:`write_backward_flow_batch` are the same with upstream's names and templates.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from kubric.io import png_io
from kubric.io.json_io import read_json, write_json
from kubric.io.layers import frame_filename
from kubric.io.paths import PathLike, as_path


def multi_write_image(data, path_template: str, write_fn: Callable = png_io.write_png,
                      max_write_threads: int = 16, **kwargs) -> list[str]:
    """Write image ``i`` of ``data`` (a (B, H, W, C) array or a sequence of images) to
    ``path_template.format(i)`` with ``write_fn(image, path, **kwargs)``; returns the paths in
    index order. The first writer exception is re-raised."""
    if not isinstance(path_template, str):
        raise TypeError(f"multi_write_image: path_template must be a str such as "
                        f"'rgb_{{:05d}}.png', got {type(path_template).__name__}")
    if isinstance(max_write_threads, bool) or not isinstance(max_write_threads, int) \
            or max_write_threads < 1:
        raise ValueError(f"multi_write_image: max_write_threads must be an int ≥ 1, got "
                         f"{max_write_threads!r}")
    if not callable(write_fn):
        raise TypeError(f"multi_write_image: write_fn must be callable, got {write_fn!r}")
    if isinstance(data, np.ndarray) and data.ndim < 3:
        raise ValueError(f"multi_write_image: data must be a batch of images (B, H, W[, C]), got "
                         f"shape {data.shape}")
    images = list(data)
    if not images:
        raise ValueError("multi_write_image: data holds no images")
    paths = [frame_filename(path_template, i) for i in range(len(images))]

    def write(item):
        image, path = item
        write_fn(image, path, **kwargs)

    with ThreadPoolExecutor(max_workers=min(max_write_threads, len(images))) as pool:
        for _ in pool.map(write, zip(images, paths, strict=True)):  # re-raises the first exception
            pass
    return paths


def write_flow_batch(data, directory: PathLike, file_template: str = "flow_{:05d}.png",
                     name: str = "flow", max_write_threads: int = 16,
                     range_file: str = "data_ranges.json") -> dict[str, dict[str, float]]:
    """Write a (T, H, W, 2) float flow batch (see module doc); returns ``{name: {"min", "max"}}``
    as merged into ``<directory>/<range_file>``."""
    what = f"write_flow_batch(name={name!r})"
    if not isinstance(name, str) or not name:
        raise ValueError(f"write_flow_batch: name must be a non-empty str (the key in "
                         f"{range_file!r}), got {name!r}")
    if not isinstance(range_file, str) or not range_file:
        raise ValueError(f"write_flow_batch: range_file must be a file name, got {range_file!r}")
    arr = np.asarray(data)
    if arr.ndim != 4 or arr.shape[-1] != 2:
        raise ValueError(f"{what}: data must have shape (T, H, W, 2), got {arr.shape}")
    value_range = png_io.float_range(arr, what)  # float dtype, finite, non-empty
    directory = as_path(directory)
    scaled = png_io.scale_to_uint16(arr, value_range["min"], value_range["max"])
    folder = str(directory).replace("{", "{{").replace("}", "}}")  # only the name is a template
    multi_write_image(scaled, f"{folder}/{file_template}", png_io.write_png, max_write_threads)
    range_path = directory / range_file
    ranges = read_json(range_path) if range_path.exists() else {}
    ranges[name] = value_range
    write_json(ranges, range_path)
    return {name: value_range}


def write_forward_flow_batch(data, directory: PathLike,
                             file_template: str = "forward_flow_{:05d}.png",
                             name: str = "forward_flow", max_write_threads: int = 16,
                             range_file: str = "data_ranges.json") -> dict[str, dict[str, float]]:
    """:func:`write_flow_batch` with upstream's forward-flow name and file template."""
    return write_flow_batch(data, directory, file_template, name, max_write_threads, range_file)


def write_backward_flow_batch(data, directory: PathLike,
                              file_template: str = "backward_flow_{:05d}.png",
                              name: str = "backward_flow", max_write_threads: int = 16,
                              range_file: str = "data_ranges.json"
                              ) -> dict[str, dict[str, float]]:
    """:func:`write_flow_batch` with upstream's backward-flow name and file template."""
    return write_flow_batch(data, directory, file_template, name, max_write_threads, range_file)
