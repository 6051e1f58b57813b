"""Write Character and MotionClip assets (archive + manifest entry), deterministically.

A **Character** archive holds ``character.npz`` (float64/int32/float32 arrays: ``vertices`` (V,3),
``faces`` (F,3), ``uv`` (F,3,2) (absent when the mesh has none), ``bone_parents`` (J,),
``bone_rest`` (J,4,4), ``bone_tails`` (J,3), ``skin_indices``/``skin_weights`` (V,K),
``regressor_indices``/``regressor_weights`` (flat) with ``regressor_offsets`` (N+1,)),
``character.json`` (bone names, keypoint names, rig, body-shape parameters, skin tone, licence)
and the licence files. A **MotionClip** archive holds ``motion.npz`` (``rotations`` (T,J,4) w,x,y,z,
``root_offsets`` (T,3)), ``motion.json`` (bone names, fps, rig, original file, licence) and the
licence/acknowledgement files. The conventions are those of docs/characters.md.

``.npz`` members are written with a fixed timestamp (numpy's own ``savez`` stamps the current
time), so the same inputs give byte-identical archives.
"""

from __future__ import annotations

import io
import os
import zipfile
from pathlib import Path

import numpy as np

from kubric.asset_tools.writer import clean_number, dumps, staging
from kubric.assets.archive import write_archive
from kubric.errors import InputError

CHARACTER_ARRAYS = {"vertices": np.float64, "faces": np.int32, "uv": np.float32,
                    "bone_parents": np.int32, "bone_rest": np.float64, "bone_tails": np.float64,
                    "skin_indices": np.int32, "skin_weights": np.float32,
                    "regressor_indices": np.int32, "regressor_weights": np.float64,
                    "regressor_offsets": np.int64}
MOTION_ARRAYS = {"rotations": np.float64, "root_offsets": np.float64}


def write_npz(path: Path, arrays: dict) -> None:
    """An uncompressed ``.npz`` (``np.load`` reads it) whose bytes depend only on the arrays."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.ascontiguousarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(name + ".npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


def _typed(arrays: dict, spec: dict, where: str) -> dict:
    out = {}
    for name, value in arrays.items():
        if value is None:
            continue
        if name not in spec:
            raise InputError(f"{where}: unknown array {name!r}; allowed: {sorted(spec)}")
        arr = np.asarray(value)
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise InputError(f"{where}: array {name!r} holds NaN or infinite values")
        out[name] = arr.astype(spec[name])
    return out


def _package(asset_id: str, asset_type: str, out_dir, stem: str, arrays: dict, info: dict,
             files: dict, license: str, metadata: dict) -> dict:
    out_dir = Path(out_dir)
    entry = clean_number({"id": asset_id, "asset_type": asset_type, "license": license,
                          "kwargs": {"arrays": "{asset_dir}/" + stem + ".npz",
                                     "info": "{asset_dir}/" + stem + ".json"},
                          "metadata": dict(metadata)})
    archive = out_dir / f"{asset_id}.tar.gz"
    archive.parent.mkdir(parents=True, exist_ok=True)
    with staging(archive.parent) as stage:
        write_npz(stage / f"{stem}.npz", arrays)
        (stage / f"{stem}.json").write_text(dumps(info))
        for name, data in sorted(files.items()):
            (stage / name).write_bytes(data if isinstance(data, bytes) else data.encode())
        (stage / "data.json").write_text(dumps(entry))
        write_archive(stage, archive)
    return entry


def package_character(asset_id: str, out_dir: str | os.PathLike, *, arrays: dict, info: dict,
                      files: dict, license: str, metadata: dict) -> dict:
    """Write ``<asset_id>.tar.gz`` (character.npz/json + ``files``); return the manifest entry."""
    typed = _typed(arrays, CHARACTER_ARRAYS, f"character {asset_id!r}")
    return _package(asset_id, "Character", out_dir, "character", typed, info, files, license,
                    metadata)


def package_motion(asset_id: str, out_dir: str | os.PathLike, *, rotations, root_offsets,
                   info: dict, files: dict, license: str, metadata: dict) -> dict:
    """Write ``<asset_id>.tar.gz`` (motion.npz/json + ``files``); return the manifest entry."""
    typed = _typed({"rotations": rotations, "root_offsets": root_offsets}, MOTION_ARRAYS,
                   f"motion {asset_id!r}")
    return _package(asset_id, "MotionClip", out_dir, "motion", typed, info, files, license,
                    metadata)
