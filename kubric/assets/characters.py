"""Runtime loading of Character and MotionClip assets (numpy only).

An asset source entry with ``asset_type`` ``"Character"`` (or ``"MotionClip"``) points at
``character.npz`` + ``character.json`` (``motion.npz`` + ``motion.json``) inside its archive;
:func:`character_kwargs` / :func:`motion_kwargs` turn them into the keyword arguments of
``kb.Character`` / ``kb.MotionClip`` (docs/characters.md), which ``AssetSource.create`` passes on.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from kubric.core.characters import Character, MotionClip
from kubric.errors import InputError


class CharacterAssetError(InputError):
    """A character or motion archive whose files are missing or inconsistent."""


def _load(arrays_path, info_path, names: tuple, where: str):
    arrays_path, info_path = Path(arrays_path), Path(info_path)
    for p in (arrays_path, info_path):
        if not p.is_file():
            raise CharacterAssetError(f"{where}: {p.name} is missing from the asset archive")
    try:
        with np.load(arrays_path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise CharacterAssetError(f"{where}: {arrays_path} is not a readable .npz (truncated or "
                                  f"corrupt: {' '.join(str(err).split())[:120]})") from None
    missing = [n for n in names if n not in arrays]
    if missing:
        raise CharacterAssetError(f"{where}: {arrays_path.name} lacks arrays {missing}")
    try:
        info = json.loads(info_path.read_text())
    except (ValueError, UnicodeDecodeError) as err:
        raise CharacterAssetError(f"{where}: {info_path} is not valid JSON ({err})") from None
    if not isinstance(info, dict):
        raise CharacterAssetError(f"{where}: {info_path} is not a JSON object")
    return arrays, info


def skin_tone_color(info: dict, skin_tone: str | None, where: str):
    """The linear RGB of ``skin_tone`` (default: the asset's own) from the archive's palette."""
    if skin_tone is None:
        return tuple(info["skin_tone"]["linear_rgb"])
    tones = info.get("skin_tones", {})
    if skin_tone not in tones:
        raise KeyError(f"{where}: unknown skin_tone {skin_tone!r}; known: {sorted(tones)}")
    return tuple(tones[skin_tone])


def character_kwargs(arrays, info, where: str = "character", skin_tone: str | None = None) -> dict:
    """``kb.Character`` keyword arguments from a character archive's ``arrays``/``info`` files."""
    a, meta = _load(arrays, info, ("vertices", "faces", "bone_parents", "bone_rest",
                                   "bone_tails", "skin_indices", "skin_weights"), where)
    regressor = None
    if "regressor_offsets" in a:
        off = a["regressor_offsets"]
        names = meta["keypoint_names"]
        if len(off) != len(names) + 1:
            raise CharacterAssetError(f"{where}: {len(names)} keypoint names but "
                                      f"{len(off) - 1} regressor rows")
        regressor = {n: (a["regressor_indices"][off[i]:off[i + 1]].astype(np.int64),
                         a["regressor_weights"][off[i]:off[i + 1]].astype(np.float64))
                     for i, n in enumerate(names)}
    kwargs = {"vertices": a["vertices"].astype(np.float64), "faces": a["faces"].astype(np.int32),
              "uv": a["uv"].astype(np.float32) if "uv" in a else None,
              "bone_names": list(meta["bone_names"]),
              "bone_parents": a["bone_parents"].astype(np.int64),
              "bone_rest": a["bone_rest"].astype(np.float64),
              "bone_tails": a["bone_tails"].astype(np.float64),
              "skin_indices": a["skin_indices"].astype(np.int32),
              "skin_weights": a["skin_weights"].astype(np.float32),
              "keypoint_regressor": regressor}
    if "skin_tone" in meta:
        kwargs["skin_color"] = skin_tone_color(meta, skin_tone, where)
    elif skin_tone is not None:
        raise KeyError(f"{where}: this character has no skin tone palette; drop skin_tone=")
    return kwargs


def motion_kwargs(arrays, info, where: str = "motion") -> dict:
    """``kb.MotionClip`` keyword arguments from a motion archive's ``arrays``/``info`` files."""
    a, meta = _load(arrays, info, ("rotations", "root_offsets"), where)
    return {"bone_names": list(meta["bone_names"]), "fps": float(meta["fps"]),
            "rotations": a["rotations"].astype(np.float64),
            "root_offsets": a["root_offsets"].astype(np.float64),
            "name": meta.get("name", where)}


def create_character(entry: dict, kwargs: dict, metadata: dict, overrides: dict):
    """``kb.Character`` of a Character entry (``overrides``: constructor keywords, plus
    ``skin_tone=`` a palette name instead of ``material=``)."""
    import kubric.core as core

    where = f"character asset {entry['id']!r}"
    overrides = dict(overrides)
    skin_tone = overrides.pop("skin_tone", None)
    built = character_kwargs(kwargs["arrays"], kwargs["info"], where, skin_tone)
    color = built.pop("skin_color", None)
    if color is not None and "material" not in overrides:
        built["material"] = core.PrincipledBSDFMaterial(color=core.Color(*color),
                                                        roughness=0.6, specular=0.4)
    built.update(overrides)
    built["metadata"] = metadata
    built.setdefault("name", entry["id"])
    return Character(**built)


def create_motion(entry: dict, kwargs: dict, metadata: dict, overrides: dict):
    """``kb.MotionClip`` of a MotionClip entry."""
    built = motion_kwargs(kwargs["arrays"], kwargs["info"], f"motion asset {entry['id']!r}")
    built.update(overrides)
    built["metadata"] = metadata
    return MotionClip(**built)


def hip_height(bone_names, bone_rest) -> float:
    """Height of the ``Hips`` head above the mean of the ``LeftFoot``/``RightFoot`` heads (m)."""
    missing = [n for n in ("Hips", "LeftFoot", "RightFoot") if n not in bone_names]
    if missing:
        raise InputError(f"hip_height needs bones {missing} (a cmu_mb-like rig)")
    rest = np.asarray(bone_rest)
    i = list(bone_names).index
    return float(rest[i("Hips"), 2, 3] - 0.5 * (rest[i("LeftFoot"), 2, 3]
                                                 + rest[i("RightFoot"), 2, 3]))


def fit_clip(clip, character):
    """A copy of ``clip`` whose root offsets are scaled for ``character``'s legs: × (the
    character's hip height / the ``hip_height`` the clip was retargeted for, from its metadata).
    Rotations are unchanged. Use it when a clip made for one body drives another (a child)."""
    made_for = clip.metadata.get("hip_height")
    if not made_for:
        raise InputError(f"MotionClip {clip.name!r}: its metadata has no 'hip_height' "
                         f"(only clips of 'kubric assets humans' record it)")
    ratio = hip_height(character.bone_names, character.bone_rest) / float(made_for)
    return MotionClip(clip.bone_names, clip.fps, clip.rotations, clip.root_offsets * ratio,
                      name=clip.name, metadata={**clip.metadata, "root_scale": ratio})
