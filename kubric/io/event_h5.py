"""Event streams in DSEC's ``events.h5`` layout (Gehrig et al., DSEC, 2021), which DSEC's own
loaders and the event-vision code built on them read, plus the ground truth of our simulation.

=====================  ===========  ==========================================================
dataset                dtype        meaning
=====================  ===========  ==========================================================
``events/x``           uint16       pixel column
``events/y``           uint16       pixel row
``events/t``           uint32       µs since ``t_offset``
``events/p``           uint8        polarity, 1 = ON (brighter), 0 = OFF
``ms_to_idx``          uint64       index of the first event with t ≥ 1000·ms, for every ms up
                                    to the last event (DSEC's lookup table)
``t_offset``           int64        µs added to ``events/t`` (0 here: t = 0 at frame_start)
``contrast_thresholds``  float32    (2, H, W) per-pixel (C+, C−) of the simulated sensor
                                    (an addition; DSEC has none)
=====================  ===========  ==========================================================

The file's attributes record the sensor model (``kubric.annotations.event_camera``). Written
with gzip (DSEC uses Blosc, an h5py plugin; gzip needs none). Needs ``h5py``
(``pip install kubric[events]``).
"""

from __future__ import annotations

import io

import numpy as np

from kubric.errors import InputError

#: the scene file of the event stream
EVENTS_H5_FILE = "events.h5"


def ms_to_idx(t_us) -> np.ndarray:
    """DSEC's table: for ms = 0 … floor(max t / 1000), the index of the first event at
    t ≥ 1000·ms (``t_us`` sorted)."""
    t = np.asarray(t_us)
    top = int(t[-1] // 1000) + 1 if t.size else 0
    return np.searchsorted(t, np.arange(top) * 1000, side="left").astype(np.uint64)


def encode_events(events: dict, thresholds, attrs: dict | None = None) -> bytes:
    """The bytes of an ``events.h5`` for ``events`` {"x", "y", "t" (µs, sorted), "p"}."""
    import h5py
    t = np.round(np.asarray(events["t"], np.float64)).astype(np.uint32)
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        group = f.create_group("events")
        for key, value in (("x", events["x"]), ("y", events["y"]), ("t", t),
                           ("p", events["p"])):
            group.create_dataset(key, data=np.asarray(value), compression="gzip")
        f.create_dataset("ms_to_idx", data=ms_to_idx(t), compression="gzip")
        f.create_dataset("t_offset", data=np.int64(0))
        f.create_dataset("contrast_thresholds", data=np.asarray(thresholds, np.float32),
                         compression="gzip")
        for key, value in (attrs or {}).items():
            f.attrs[key] = value
    return buffer.getvalue()


def events_file(camera: str) -> str:
    """The event stream of a camera rig's further camera ``camera``: ``events_NAME.h5``, in
    ``events.h5``'s layout (the reference camera's is ``events.h5``)."""
    return f"events_{camera}.h5"


def read_events(path) -> dict[str, np.ndarray]:
    """An ``events.h5`` (a path or a scene directory) → {"x", "y", "t" (int64 µs, t_offset
    added), "p", "ms_to_idx", "contrast_thresholds", "attrs"}."""
    import pathlib

    import h5py
    path = pathlib.Path(path)
    if path.is_dir():
        path = path / EVENTS_H5_FILE
    try:
        with h5py.File(path, "r") as f:
            out = {k: f["events"][k][()] for k in ("x", "y", "p")}
            out["t"] = f["events"]["t"][()].astype(np.int64) + int(f["t_offset"][()])
            out["ms_to_idx"] = f["ms_to_idx"][()]
            out["contrast_thresholds"] = f["contrast_thresholds"][()]
            out["attrs"] = dict(f.attrs)
    except (OSError, KeyError) as err:
        raise InputError(f"{str(path)!r} is not an events.h5 file: {err}") from None
    return out
