"""``tracks.npz``: one scene's point tracks (the TAP-Vid export is
:mod:`kubric.datasets.exports.tapvid`).

``tracks.npz`` is written by :func:`write_tracks` (atomically: a hidden temporary file renamed
into place) and read by :func:`read_tracks`; it holds exactly the arrays of
:data:`kubric.annotations.tracks.TRACK_FIELDS` (keys, shapes, dtypes and conventions in
:mod:`kubric.annotations.tracks`; docs/tracks.md) plus ``format_version`` (int32, currently 1).
It is an ordinary ``numpy.savez_compressed`` archive: ``np.load(path)`` reads it anywhere.
"""

from __future__ import annotations

import io
import pathlib
import zipfile

import numpy as np

from kubric.annotations.tracks import TRACK_FIELDS
from kubric.errors import InputError
from kubric.io import scene_dir
from kubric.io.paths import atomic_write_bytes

FORMAT_VERSION = 1
TRACKS_FILE = scene_dir.TRACKS_FILE


def tracks_archive(tracks: dict) -> dict[str, np.ndarray]:
    """The arrays of ``tracks.npz`` for the dict of
    :func:`~kubric.annotations.tracks.compute_tracks`: ``format_version`` then every field of
    :data:`~kubric.annotations.tracks.TRACK_FIELDS` (what the scene writer stores)."""
    missing = [k for k in TRACK_FIELDS if k not in tracks]
    if missing:
        raise InputError(f"tracks: missing fields {missing}")
    return {"format_version": np.int32(FORMAT_VERSION),
            **{k: np.asarray(tracks[k]) for k in TRACK_FIELDS}}


def write_tracks(tracks: dict, path) -> pathlib.Path:
    """Write the dict of :func:`~kubric.annotations.tracks.compute_tracks` to ``path`` (outside
    a recipe; a recipe hands :func:`tracks_archive` to the scene writer)."""
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **tracks_archive(tracks))
    return atomic_write_bytes(buffer.getvalue(), path)


def read_tracks(path) -> dict[str, np.ndarray]:
    """Read a ``tracks.npz`` written by :func:`write_tracks` (checks version and fields)."""
    path = pathlib.Path(path)
    if path.is_dir():
        path = path / TRACKS_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no tracks file {str(path)!r} (generate the scene with "
                                "--set tracks=N)")
    try:
        with np.load(path, allow_pickle=False) as data:
            out = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:  # truncated, not a .npz
        raise InputError(f"{str(path)!r} is not a readable tracks file (truncated or not a "
                         f".npz: {' '.join(str(err).split())[:200]})") from None
    version = int(out.pop("format_version", -1))
    if version != FORMAT_VERSION:
        raise InputError(f"{str(path)!r}: tracks format_version {version}, this reader reads "
                         f"{FORMAT_VERSION}")
    missing = [k for k in TRACK_FIELDS if k not in out]
    if missing:
        raise InputError(f"{str(path)!r}: missing fields {missing}")
    return out
