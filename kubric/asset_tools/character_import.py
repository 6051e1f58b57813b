"""``kubric assets characters SRC --out DIR``: your rigged characters and animations → sources.

Each ``.gltf``/``.glb``/``.fbx``/``.bvh`` file under SRC is read by bpy's importer in a fresh
process (:mod:`kubric.asset_tools.character_bpy`). A file with a mesh skinned to an armature
becomes a **character** (``OUT/characters``): Blender's frame after import (Z up; glTF and
Mixamo-style FBX characters face −Y), ``--scale`` applied, shifted so that the mesh stands on
z = 0 centred on its bounding box in x and y. A file whose armature has an action becomes one
**motion clip** per character it fits (``OUT/motions``, id ``<file stem>@<character id>``): the
character of the same file, and every character whose bone names include all of the clip's
driven bones (BVH or animation-only FBX for that rig), retargeted by world-rotation deltas
(:mod:`kubric.asset_tools.retarget`); a clip that fits no character is kept on its own skeleton
(id ``<file stem>``, rig = its own bone names). Root offsets are the root bone's displacement
from its rest position, scaled by the ratio of root heights (target / source; 1 for the
character of the same file) and ``--scale``.

Animations are retargeted in Blender's world frame, so a separate animation file must use the
same axes as the character: BVH files are read as Y up facing +Z (``--bvh-up y``, the usual
convention, e.g. CMU) or as Z up unchanged (``--bvh-up z``, as Blender's BVH exporter writes).

Files that cannot be used (no armature, a mesh not skinned to it, unweighted vertices, NaN in a
clip, an importer failure, a FIFO or other non-regular file) are skipped with one line naming
the file and the problem; so is a glTF file whose buffer or image URIs leave SRC or name
anything but a bounded regular file (:mod:`kubric.assets.gltf_refs`). Two files with one stem
(``a/dup.gltf`` and ``b/dup.glb``) are refused before anything is read: ids are stems.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from kubric.asset_tools import retarget
from kubric.asset_tools.bvh import BVHError, read_bvh
from kubric.asset_tools.character_writer import package_character, package_motion
from kubric.asset_tools.writer import write_manifest
from kubric.assets.gltf_refs import GltfReferenceError, check_gltf
from kubric.errors import InputError

EXTENSIONS = (".gltf", ".glb", ".fbx", ".bvh")
#: the largest ``--scale`` (file units → metres; 1000 turns kilometres into metres)
MAX_SCALE = 1000.0


class CharacterImportError(InputError):
    """A file that cannot become a character or clip (one line naming it)."""


def extract(path: Path, timeout: float = 600, bvh_up: str = "y") -> tuple[dict, dict]:
    """Run the bpy extraction of ``path`` in a fresh process; (arrays, info)."""
    with tempfile.TemporaryDirectory(prefix="kubric-char-") as tmp:
        out = Path(tmp) / "extract.npz"
        proc = subprocess.run([sys.executable, "-P", "-m", "kubric.asset_tools.character_bpy",
                               str(path), str(out), bvh_up], capture_output=True, text=True,
                              timeout=timeout)
        errors = [ln[len("ERROR: "):] for ln in proc.stdout.splitlines() if ln.startswith("ERROR: ")]
        if errors:
            raise CharacterImportError(errors[-1])
        if proc.returncode != 0 or not out.is_file():
            tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
            raise CharacterImportError(f"{path}: bpy extraction failed (exit {proc.returncode}): "
                                       f"{tail}")
        with np.load(out) as z:
            arrays = {k: z[k] for k in z.files}
        return arrays, json.loads(out.with_suffix(".json").read_text())


def character_from_extract(arrays: dict, info: dict, where: str, scale: float = 1.0) -> dict:
    """Character arrays (model frame, standing on z = 0) from an extraction; raises
    :class:`CharacterImportError` for a non-skinned file or unweighted vertices."""
    if "vertices" not in arrays:
        raise CharacterImportError(f"{where}: no mesh is skinned to armature {info['armature']!r} "
                                   f"(meshes without an armature modifier: "
                                   f"{info.get('unskinned_meshes', [])}); not a character")
    rendered = np.zeros(len(arrays["vertices"]), bool)
    rendered[arrays["faces"].ravel()] = True
    bad = int(np.sum(rendered & ~arrays["weighted"]))
    if bad:
        raise CharacterImportError(f"{where}: {bad} of {int(rendered.sum())} rendered vertices "
                                   f"have no weight on any bone (a rig without weights?)")
    v = arrays["vertices"] * scale
    shift = np.array([-(v[:, 0].min() + v[:, 0].max()) / 2, -(v[:, 1].min() + v[:, 1].max()) / 2,
                      -v[:, 2].min()])
    rest = arrays["bone_rest"].copy()
    rest[:, :3, 3] = rest[:, :3, 3] * scale + shift
    out = {"vertices": v + shift, "faces": arrays["faces"], "uv": arrays.get("uv"),
           "bone_parents": arrays["bone_parents"], "bone_rest": rest,
           "bone_tails": arrays["bone_tails"] * scale + shift,
           "skin_indices": arrays["skin_indices"], "skin_weights": arrays["skin_weights"]}
    return out


def clip_onto(src_arrays: dict, src_info: dict, target: dict, target_names: list[str],
              same_file: bool, scale: float, where: str) -> dict:
    """The action of an extraction retargeted onto ``target`` (arrays with bone_parents/rest)."""
    pose = src_arrays["pose_world"]
    if not np.isfinite(pose).all():
        raise CharacterImportError(f"{where}: the animation holds NaN/inf")
    src_names = src_info["bone_names"]
    src_rest = src_arrays["bone_rest"]
    index = {n: i for i, n in enumerate(target_names)}
    mapping = {index[n]: j for j, n in enumerate(src_names) if n in index}
    if not mapping:
        raise CharacterImportError(f"{where}: none of the clip's bones {src_names[:6]}... "
                                   f"matches a bone of the character")
    rel = pose[:, :, :3, :3] @ np.swapaxes(src_rest[:, :3, :3], -1, -2)[None]
    directions = {}
    if not same_file:
        for b, j in mapping.items():
            d = src_arrays["bone_tails"][j] - src_rest[j, :3, 3]
            if np.linalg.norm(d) > 1e-9:
                directions[b] = d / np.linalg.norm(d)
    rotations = retarget.retarget_rotations(target["bone_parents"], target["bone_rest"], rel,
                                            mapping, directions)
    root_t = int(np.nonzero(np.asarray(target["bone_parents"]) < 0)[0][0])
    if root_t not in mapping:
        raise CharacterImportError(f"{where}: the character's root bone "
                                   f"{target_names[root_t]!r} is not in the clip")
    root_s = mapping[root_t]
    if same_file:
        ratio = scale
    else:
        src_floor = min(src_rest[:, 2, 3].min(), src_arrays["bone_tails"][:, 2].min())
        src_h = src_rest[root_s, 2, 3] - src_floor
        tgt_h = target["bone_rest"][root_t, 2, 3]
        ratio = tgt_h / src_h if src_h > 1e-9 else scale
    offsets = (pose[:, root_s, :3, 3] - src_rest[root_s, :3, 3]) * ratio
    return {"rotations": rotations, "root_offsets": offsets}


def check_unique_stems(files) -> None:
    """One-line :class:`InputError` when two files share a stem: a character's and a clip's ids
    are file stems, so one would silently replace the other."""
    seen: dict[str, Path] = {}
    for path in files:
        if path.stem in seen:
            raise InputError(f"{seen[path.stem]} and {path} have the same name {path.stem!r} "
                             "(character and clip ids are file names without extension); "
                             "rename one")
        seen[path.stem] = path


def import_characters(src: str | Path, out: str | Path, name: str = "UserCharacters",
                      license: str = "unknown (user-provided files)", scale: float = 1.0,
                      progress: bool = True, bvh_up: str = "y") -> dict:
    """Import every supported file under ``src`` (a file or folder); returns a report
    ``{name, converted, reused, skipped: [{id, source, reason}], total}``."""
    src, out = Path(src), Path(out)
    if not src.exists():
        raise FileNotFoundError(f"{src}: no such file or folder")
    if not 0 < scale <= MAX_SCALE:
        raise InputError(f"--scale must be in (0, {MAX_SCALE:g}] (file units → metres), got "
                         f"{scale!r}")
    if bvh_up not in ("y", "z"):
        raise InputError(f"--bvh-up must be 'y' or 'z', got {bvh_up!r}")
    files = [src] if not src.is_dir() else sorted(p for p in src.rglob("*")
                                                   if p.suffix.lower() in EXTENSIONS)
    bad = [p for p in files if p.suffix.lower() not in EXTENSIONS]
    if bad:
        raise InputError(f"{bad[0]}: unsupported file type; allowed: {list(EXTENSIONS)}")
    skipped = [{"id": p.stem, "source": str(p), "reason": f"{p}: not a regular file (a FIFO, "
                "device or folder is never read)"} for p in files if not p.is_file()]
    files = [p for p in files if p.is_file()]
    check_unique_stems(files)
    extracted = []
    root = src if src.is_dir() else src.parent
    for i, path in enumerate(files):
        try:
            if path.suffix.lower() in (".gltf", ".glb"):
                check_gltf(path, root)  # before bpy follows a URI out of SRC or into a device
            elif path.suffix.lower() == ".bvh":
                read_bvh(path)  # NaN, impossible frame counts and times, absurd lengths
            extracted.append((path, *extract(path, bvh_up=bvh_up)))
            if progress:
                print(f"  [{i + 1}/{len(files)}] read {path.name}", flush=True)
        except (CharacterImportError, GltfReferenceError, BVHError) as err:
            skipped.append({"id": path.stem, "source": str(path), "reason": str(err)})
    characters, char_entries = {}, {}
    for path, arrays, info in extracted:
        if "vertices" not in arrays and "pose_world" in arrays:
            continue  # an animation-only file
        try:
            built = character_from_extract(arrays, info, str(path), scale)
        except CharacterImportError as err:
            skipped.append({"id": path.stem, "source": str(path), "reason": str(err)})
            continue
        cid = path.stem
        characters[cid] = (built, info["bone_names"], path)
        body = built["vertices"]
        meta = {"category": "character", "height": float(np.ptp(body[:, 2])),
                "nr_vertices": len(body), "nr_faces": len(built["faces"]),
                "nr_bones": len(info["bone_names"]), "original_file": path.name, "rig": cid}
        char_info = {"rig": cid, "bone_names": info["bone_names"], "keypoint_names": [],
                     "license": license, "original_file": path.name, "armature": info["armature"]}
        char_entries[cid] = package_character(cid, out / "characters", arrays=built,
                                              info=char_info, files={}, license=license,
                                              metadata=meta)
    motion_entries = {}
    for path, arrays, info in extracted:
        if "pose_world" not in arrays:
            continue
        targets = [(cid, c) for cid, c in characters.items() if c[2] == path or
                   set(info["bone_names"]) <= set(c[1])]
        if not targets:
            own = {"bone_parents": arrays["bone_parents"], "bone_rest": arrays["bone_rest"]}
            targets = [(None, (own, info["bone_names"], path))]
        for cid, (target, names, tpath) in targets:
            mid = path.stem if cid is None else f"{path.stem}@{cid}"
            try:
                clip = clip_onto(arrays, info, target, names, tpath == path, scale, str(path))
            except CharacterImportError as err:
                skipped.append({"id": mid, "source": str(path), "reason": str(err)})
                continue
            T = len(clip["rotations"])
            minfo = {"name": mid, "bone_names": names, "fps": info["fps"],
                     "rig": cid or path.stem, "original_file": path.name, "license": license,
                     "action": info["action"], "frames": T}
            meta = {"category": "motion", "frames": T, "fps": info["fps"],
                    "duration": T / info["fps"], "rig": cid or path.stem,
                    "original_file": path.name}
            motion_entries[mid] = package_motion(mid, out / "motions", info=minfo, files={},
                                                 license=license, metadata=meta, **clip)
    if char_entries:
        write_manifest(out / "characters" / "manifest.json", f"{name}Characters", "1",
                       char_entries, description="rigged characters imported with bpy; metres, "
                                                 "Z up (docs/characters.md)")
    if motion_entries:
        write_manifest(out / "motions" / "manifest.json", f"{name}Motions", "1", motion_entries,
                       description="animations imported with bpy (docs/characters.md)")
    return {"name": name, "converted": len(char_entries) + len(motion_entries), "reused": 0,
            "skipped": skipped, "total": len(char_entries) + len(motion_entries) + len(skipped)}
