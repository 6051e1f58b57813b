"""The TAP-Vid export (``kubric export tapvid SCENES --out FILE.pkl``): the point tracks
(``tracks.npz``, :mod:`kubric.annotations.track_files`) of every complete scene as one pickle.

It holds a dict ``{scene name: video dict}`` (:func:`export_tapvid`) in the layout of TAP-Vid's
``tapvid_davis.pkl`` (TAP-Vid's loaders accept it) with three extra keys; a camera-rig scene adds
one entry ``"SCENE:NAME"`` per further camera NAME (:func:`rig_examples`):

==============  ==============  =======  ========================================================
key             shape           dtype    meaning
==============  ==============  =======  ========================================================
video           (T, H, W, 3)    uint8    the RGB frames
points          (N, T, 2)       float32  (x, y) **normalised to [0, 1]**: pixel position / (W, H)
                                         (TAP-Vid's pickle convention; its loaders multiply by
                                         the frame size, giving raster coordinates in which the
                                         centre of pixel (r, c) is (c + 0.5, r + 0.5))
occluded        (N, T)          bool     True = occluded
target_points   (N, T, 2)       float32  (x, y) in raster pixels (= points · (W, H)), the
                                         ``target_points`` of TAP-Vid's training/eval batches
query_points    (N, 3)          float32  (t, y, x): frame index and raster pixel position
licenses        list of dicts            every asset the video shows and its licence
                                         (:mod:`kubric.datasets.exports.licences`: kind, asset,
                                         license, source, attribution, url, description)
==============  ==============  =======  ========================================================
"""

from __future__ import annotations

import pathlib
import pickle

import numpy as np

from kubric.annotations.track_files import TRACKS_FILE, read_tracks
from kubric.datasets.exports import licences
from kubric.datasets.exports.scenes import find_scenes
from kubric.errors import InputError
from kubric.io.json_io import read_json
from kubric.io.layers import read_layer
from kubric.io.paths import atomic_write_bytes
from kubric.io.scene_dir import METADATA_FILE
from kubric.io.stored_schema import stored_schema


def tapvid_example(tracks: dict, video: np.ndarray) -> dict[str, np.ndarray]:
    """One scene in TAP-Vid's layout (module doc)."""
    video = np.asarray(video)
    if video.ndim != 4 or video.shape[-1] not in (3, 4) or video.dtype != np.uint8:
        raise InputError(f"video must be uint8 (T, H, W, 3 or 4), got {video.dtype} {video.shape}")
    w, h = (int(v) for v in tracks["resolution"])
    t = len(tracks["frames"])
    if video.shape[:3] != (t, h, w):
        raise InputError(f"video shape {video.shape[:3]} does not match the tracks' "
                         f"(T, H, W) = {(t, h, w)}")
    target = np.asarray(tracks["target_points"], dtype=np.float32)
    return {
        "video": np.ascontiguousarray(video[..., :3]),
        "points": (target / np.array([w, h], dtype=np.float32)).astype(np.float32),
        "occluded": np.asarray(tracks["occluded"], dtype=bool),
        "target_points": target,
        "query_points": np.asarray(tracks["query_points"], dtype=np.float32),
    }


def scene_dirs_with_tracks(root) -> list[pathlib.Path]:
    """Complete scene directories under ``root`` (or ``root`` itself), each with tracks.npz;
    ValueError (one line) when there is none or a complete scene lacks its tracks."""
    candidates = find_scenes(root)[0]
    lacking = [p.name for p in candidates if not (p / TRACKS_FILE).is_file()]
    if lacking:
        raise InputError(f"scene {lacking[0]!r} has no {TRACKS_FILE} ({len(lacking)} of "
                         f"{len(candidates)} scenes lack it; generate them with --set tracks=N "
                         f"into a new --out, or into this one with --overwrite)")
    return candidates


def rig_examples(scene: pathlib.Path) -> dict[str, dict]:
    """``{"SCENE:NAME": video dict}`` of each further camera NAME of a camera-rig scene
    (``cameras=stereo|ring|random``: ``tracks_NAME.npz`` and the layer ``NAME_rgba``, the same surface
    points as the reference camera's tracks); empty for a one-camera scene."""
    paths = sorted(scene.glob("tracks_*.npz"))
    schema = stored_schema(scene) if paths else None
    out = {}
    for path in paths:
        name = path.stem[len("tracks_"):]
        if schema is not None and f"{name}_rgba" in schema.layers:
            out[f"{scene.name}:{name}"] = tapvid_example(
                read_tracks(path), read_layer(scene, f"{name}_rgba", formats=schema.layers))
    return out


def export_tapvid(root, out) -> tuple[pathlib.Path, int]:
    """Write every complete scene under ``root`` as one TAP-Vid pickle ``out``; returns
    (path, number of scenes)."""
    scenes = scene_dirs_with_tracks(root)
    data = {}
    for scene in scenes:
        tracks = read_tracks(scene / TRACKS_FILE)
        assets = licences.as_json(licences.scene_licences(read_json(scene / METADATA_FILE)))
        videos = {scene.name: tapvid_example(tracks, read_layer(scene, "rgba")),
                  **rig_examples(scene)}
        data.update({name: {**video, licences.KEY: assets} for name, video in videos.items()})
    payload = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)
    return atomic_write_bytes(payload, out), len(data)
