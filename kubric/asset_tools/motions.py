"""The motion source of ``kubric assets humans``: CMU BVH and DeepMimic clips on ``cmu_mb``.

- **CMU** (Debian ``assimp-testmodels``: ``/usr/share/assimp/models/BVH/01_01.bvh``, ``01_03.bvh``;
  cgspeed's conversion of the CMU Graphics Lab database, 120 fps): the joint names are cmu_mb's
  (``LFingers``/``RFingers`` are cmu_mb's ``LeftHandFinger1``/``RightHandFinger1``); every bone
  follows its joint, aligned to its segment in the BVH zero pose (a T-pose).
- **DeepMimic** (``pybullet_data/data/motions/humanoid3d_*.txt`` for ``humanoid/humanoid.urdf``,
  Y up, facing +X, left = −Z; offsets ×0.25 = the clips' metres): see :data:`DEEPMIMIC_MAP`.

Retargeting: :mod:`kubric.asset_tools.retarget`, onto the ``average`` character's rest pose.
Root offsets: the source root trajectory, relative to its first frame horizontally, scaled by
the ratio of hip-above-ankle heights (target / source); ``motion.json`` records the target's
``hip_height`` so a player may rescale for other bodies.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from kubric.asset_tools import retarget
from kubric.asset_tools.bvh import BVHError, read_bvh
from kubric.asset_tools.character_writer import package_motion
from kubric.asset_tools.writer import write_manifest
from kubric.assets.characters import hip_height
from kubric.core import skinning
from kubric.errors import InputError

CMU_DIR = Path("/usr/share/assimp/models/BVH")
CMU_CLIPS = ("01_01", "01_03")
CMU_ALIASES = {"LFingers": "LeftHandFinger1", "RFingers": "RightHandFinger1"}
CMU_ACK = ("The data used in this project was obtained from mocap.cs.cmu.edu. The database was "
           "created with funding from NSF EIA-0196217.")
CMU_LICENSE = ("CMU Graphics Lab Motion Capture Database (BVH conversion by B. Hahne, cgspeed): "
               "free for research and commercial use; acknowledgement requested: " + CMU_ACK)
DEEPMIMIC_LICENSE = ("DeepMimic motion clips as shipped in pybullet_data (bullet3, zlib licence; "
                     "motions from DeepMimic, Peng et al. 2018)")

#: axes of the sources → model frame (metres, Z up, facing −Y, left = +X)
BVH_TO_MODEL = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y up, facing +Z, left +X
DEEPMIMIC_TO_MODEL = np.array([[0.0, 0, -1], [-1, 0, 0], [0, 1, 0]])  # Y up, facing +X, left −Z
DEEPMIMIC_SCALE = 0.25

#: DeepMimic frame layout after the duration: root position (3), root quaternion (4), then these
#: joints: quaternion (w, x, y, z) for spherical joints, one angle about z for knees/elbows
DEEPMIMIC_JOINTS = (("chest", 4), ("neck", 4), ("right_hip", 4), ("right_knee", 1),
                    ("right_ankle", 4), ("right_shoulder", 4), ("right_elbow", 1),
                    ("left_hip", 4), ("left_knee", 1), ("left_ankle", 4), ("left_shoulder", 4),
                    ("left_elbow", 1))
#: cmu_mb bone ← DeepMimic joint (aligned to the segment to ``child`` when given). Every other
#: bone (Spine, Spine1, Neck1, Head, L/RHipJoint, L/RShoulder, hands, fingers, thumbs, toes)
#: keeps its reference pose relative to its parent; the DeepMimic wrists are fixed joints.
DEEPMIMIC_MAP = {
    "Hips": ("root", "chest"), "LowerBack": ("chest", "neck"), "Neck": ("neck", None),
    "LeftUpLeg": ("left_hip", "left_knee"), "LeftLeg": ("left_knee", "left_ankle"),
    "LeftFoot": ("left_ankle", None), "RightUpLeg": ("right_hip", "right_knee"),
    "RightLeg": ("right_knee", "right_ankle"), "RightFoot": ("right_ankle", None),
    "LeftArm": ("left_shoulder", "left_elbow"), "LeftForeArm": ("left_elbow", "left_wrist"),
    "RightArm": ("right_shoulder", "right_elbow"), "RightForeArm": ("right_elbow", "right_wrist"),
}


class MotionError(InputError):
    """A motion file that cannot be retargeted (one line naming the file and the problem)."""


def _rig(character: dict):
    a = character["arrays"]
    return (character["facts"]["bone_names"], a["bone_parents"], a["bone_rest"],
            a["bone_tails"])


def _hip_height(names, rest) -> float:
    return hip_height(names, rest)


def retarget_bvh(path: str | Path, names, parents, rest, tails, aliases=None) -> dict:
    """A BVH clip retargeted onto the rig (bone names matched to joint names, ``aliases``
    renaming joints); returns rotations (T, J, 4), root_offsets (T, 3), fps and the bones used."""
    motion = read_bvh(path)
    aliases = dict(CMU_ALIASES if aliases is None else aliases)
    jnames = [aliases.get(n, n) for n in motion.names]
    index = {b: i for i, b in enumerate(names)}
    matched = {index[n]: j for j, n in enumerate(jnames) if n in index}
    if not matched:
        raise MotionError(f"{path}: none of its joints {motion.names[:8]}... matches a bone of "
                          f"the rig ({names[:8]}...)")
    if jnames[0] not in index:
        raise MotionError(f"{path}: its root joint {motion.names[0]!r} is not a rig bone")
    C = BVH_TO_MODEL
    zero = motion.rest_positions() @ C.T
    directions = {}
    for b, j in matched.items():
        kids = [c for c in motion.joints[j].children if jnames[c] in index
                and parents[index[jnames[c]]] == b]
        if kids:  # the child whose bone starts nearest this bone's tail
            c = min(kids, key=lambda k: np.linalg.norm(rest[index[jnames[k]], :3, 3] - tails[b]))
            d = zero[c] - zero[j]
        elif motion.joints[j].end_site is not None:
            d = C @ motion.joints[j].end_site
        else:
            continue
        if np.linalg.norm(d) > 1e-6:
            directions[b] = d / np.linalg.norm(d)
    world = motion.world_transforms()
    src_rot = C @ world[:, :, :3, :3] @ C.T
    rotations = retarget.retarget_rotations(parents, rest, src_rot, matched, directions)
    root = [j for j, joint in enumerate(motion.joints) if joint.parent < 0][0]
    pos = world[:, root, :3, 3] @ C.T
    feet = [jnames.index(n) for n in ("LeftFoot", "RightFoot") if n in jnames]
    if len(feet) != 2:
        raise MotionError(f"{path}: no LeftFoot/RightFoot joints to measure the leg length")
    src_hip = float(zero[root, 2] - zero[feet, 2].mean())
    scale = _hip_height(names, rest) / src_hip
    offsets = pos * scale
    offsets[:, :2] -= offsets[0, :2]
    offsets[:, 2] -= rest[index[jnames[root]], 2, 3]
    return {"rotations": rotations, "root_offsets": offsets, "fps": motion.fps,
            "mapped": sorted(names[b] for b in matched), "directions": directions, "loop": False,
            "source_world": src_rot, "mapping": matched, "scale": scale}


def read_humanoid_urdf(path: str | Path) -> dict:
    """``{joint: (parent link, origin xyz (3,))}`` of DeepMimic's humanoid.urdf (regex: the file
    ends with a NUL byte that XML parsers reject)."""
    text = Path(path).read_bytes().decode("latin-1")
    out = {}
    for m in re.finditer(r'<joint name="([^"]+)"[^>]*>(.*?)</joint>', text, re.S):
        parent = re.search(r'<parent link\s*=\s*"([^"]+)"', m.group(2)).group(1)
        xyz = re.search(r'xyz\s*=\s*"([^"]+)"', m.group(2)).group(1)
        out[m.group(1)] = (parent, np.array([float(v) for v in xyz.split()]))
    return out


def read_deepmimic(path: str | Path) -> dict:
    """(durations (T,), root position (T, 3), {joint: (T, 4) quaternion or (T,) angle})."""
    path = Path(path)
    try:
        frames = np.asarray(json.loads(path.read_text())["Frames"], dtype=np.float64)
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise MotionError(f"{path}: not a DeepMimic motion file ({err})") from None
    width = 8 + sum(n for _, n in DEEPMIMIC_JOINTS)
    if frames.ndim != 2 or frames.shape[1] != width:
        raise MotionError(f"{path}: frames must have {width} values, got shape {frames.shape}")
    if not np.isfinite(frames).all():
        raise MotionError(f"{path}: a frame holds NaN/inf "
                          f"(first frame {int(np.nonzero(~np.isfinite(frames).all(1))[0][0])})")
    joints, col = {"root": frames[:, 4:8]}, 8
    for name, n in DEEPMIMIC_JOINTS:
        joints[name] = frames[:, col] if n == 1 else frames[:, col:col + 4]
        col += n
    loop = json.loads(path.read_text()).get("Loop", "none") == "wrap"
    return {"durations": frames[:, 0], "root": frames[:, 1:4], "joints": joints, "loop": loop}


def resample_uniform(durations, rotations, offsets, where):
    """Frames with per-frame ``durations`` (the last may be 0) → uniform frames at the median
    frame rate: kept as they are when every duration is within 1 % of the median, else resampled
    (quaternions by normalised linear interpolation between the neighbouring frames, after the
    sign continuity of :func:`retarget.continuous`; root offsets linearly)."""
    dt = np.asarray(durations[:-1], dtype=np.float64)
    if len(dt) == 0 or (dt <= 0).any():
        raise MotionError(f"{where}: frame durations must be > 0 (except the last), got "
                          f"{sorted(set(np.round(dt, 6).tolist()))[:5]}")
    step = float(np.median(dt))
    if np.all(np.abs(dt - step) <= 0.01 * step):
        return rotations, offsets, 1.0 / step
    times = np.concatenate([[0.0], np.cumsum(dt)])
    new = np.arange(0.0, times[-1] + 1e-9, step)
    i = np.clip(np.searchsorted(times, new, side="right") - 1, 0, len(times) - 2)
    f = ((new - times[i]) / (times[i + 1] - times[i]))[:, None]
    q = (1 - f[..., None]) * rotations[i] + f[..., None] * rotations[i + 1]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q, (1 - f) * offsets[i] + f * offsets[i + 1], 1.0 / step


def deepmimic_kinematics(clip: dict, urdf) -> dict:
    """Forward kinematics of a DeepMimic clip on humanoid.urdf, in the file's frame (Y up; the
    URDF's offsets × :data:`DEEPMIMIC_SCALE`): ``{"order": joint names (root, the
    :data:`DEEPMIMIC_JOINTS`, the two wrists), "zero": {joint: (3,) position at the zero pose,
    root at 0}, "world": {joint: (T, 3, 3)}, "positions": {joint: (T, 3)}}``."""
    joints = read_humanoid_urdf(urdf)
    order = ["root"] + [n for n, _ in DEEPMIMIC_JOINTS] + ["left_wrist", "right_wrist"]
    parent_of = {n: joints[n][0] for n in order if n != "root"}
    zero = {"root": np.zeros(3)}
    for n in order[1:]:
        zero[n] = zero[parent_of[n]] + DEEPMIMIC_SCALE * joints[n][1]
    T = len(clip["root"])
    world = {"root": skinning.quaternions_to_matrices(clip["joints"]["root"])}
    positions = {"root": clip["root"]}
    for n in order[1:]:
        parent = parent_of[n]
        positions[n] = positions[parent] + world[parent] @ (DEEPMIMIC_SCALE * joints[n][1])
        q = clip["joints"].get(n)
        if q is None:  # the fixed wrists
            world[n] = world[parent]
            continue
        if q.ndim == 1:  # revolute about z
            c, s = np.cos(q), np.sin(q)
            local = np.zeros((T, 3, 3))
            local[:, 0, 0], local[:, 0, 1], local[:, 1, 0], local[:, 1, 1] = c, -s, s, c
            local[:, 2, 2] = 1
        else:
            local = skinning.quaternions_to_matrices(q)
        world[n] = world[parent] @ local
    return {"order": order, "zero": zero, "world": world, "positions": positions}


def retarget_deepmimic(path, urdf, names, parents, rest) -> dict:
    """A DeepMimic clip retargeted onto the rig through :data:`DEEPMIMIC_MAP`."""
    clip = read_deepmimic(path)
    kin = deepmimic_kinematics(clip, urdf)
    order, zero, world = kin["order"], kin["zero"], kin["world"]
    C = DEEPMIMIC_TO_MODEL
    index = {b: i for i, b in enumerate(names)}
    src_names = order[:-2]
    src_rot = np.stack([C @ world[n] @ C.T for n in src_names], axis=1)
    mapping, directions = {}, {}
    for bone, (joint, child) in DEEPMIMIC_MAP.items():
        b = index[bone]
        mapping[b] = src_names.index(joint)
        if child is not None:
            d = C @ (zero[child] - zero[joint])
            directions[b] = d / np.linalg.norm(d)
    rotations = retarget.retarget_rotations(parents, rest, src_rot, mapping, directions)
    src_hip = float(zero["root"][1] - 0.5 * (zero["left_ankle"][1] + zero["right_ankle"][1]))
    scale = _hip_height(names, rest) / src_hip
    offsets = (clip["root"] @ C.T) * scale
    offsets[:, :2] -= offsets[0, :2]
    offsets[:, 2] -= rest[index["Hips"], 2, 3]
    rotations, offsets, fps = resample_uniform(clip["durations"], rotations, offsets, path)
    return {"rotations": rotations, "root_offsets": offsets, "fps": fps, "loop": clip["loop"],
            "mapped": sorted(DEEPMIMIC_MAP), "directions": directions, "source_world": src_rot,
            "mapping": mapping, "scale": scale}


def deepmimic_files() -> tuple[Path, list[Path]]:
    import pybullet_data
    root = Path(pybullet_data.getDataPath())
    return root / "humanoid" / "humanoid.urdf", sorted((root / "data" / "motions").glob(
        "humanoid3d_*.txt"))


def build_motion_source(out: str | Path, character: dict, progress: bool = True,
                        cmu_dir: str | Path = CMU_DIR, deepmimic: bool = True) -> Path:
    """Write the motion source (CMU + DeepMimic clips on cmu_mb) into ``out``."""
    out = Path(out)
    names, parents, rest, tails = _rig(character)
    hip = _hip_height(names, rest)
    cmu_dir = Path(cmu_dir)
    missing = [c for c in CMU_CLIPS if not (cmu_dir / f"{c}.bvh").is_file()]
    if missing:
        raise FileNotFoundError(f"CMU clips {missing} not found in {cmu_dir}: install Debian's "
                                f"assimp-testmodels (apt-get install -y assimp-testmodels)")
    terms = (cmu_dir / "01_nn.bvh.source.txt")
    cmu_files = {"ACKNOWLEDGEMENT": CMU_ACK + "\n"}
    if terms.is_file():
        cmu_files["SOURCE.txt"] = terms.read_bytes()
    jobs = [(f"cmu_{c}", "cmu", cmu_dir / f"{c}.bvh") for c in CMU_CLIPS]
    if deepmimic:
        urdf, clips = deepmimic_files()
        jobs += [(p.stem.replace("humanoid3d_", "deepmimic_"), "deepmimic", p) for p in clips]
    entries = {}
    for i, (clip_id, kind, path) in enumerate(jobs):
        if kind == "cmu":
            r = retarget_bvh(path, names, parents, rest, tails)
            license_, files = CMU_LICENSE, cmu_files
        else:
            r = retarget_deepmimic(path, urdf, names, parents, rest)
            license_, files = DEEPMIMIC_LICENSE, {}
        T = len(r["rotations"])
        info = {"name": clip_id, "bone_names": names, "fps": r["fps"], "rig": "cmu_mb",
                "original_file": path.name, "license": license_, "hip_height": hip,
                "driven_bones": r["mapped"], "frames": T,
                "loop": r["loop"]}
        meta = {"category": "motion", "source": kind, "frames": T, "fps": r["fps"],
                "duration": T / r["fps"], "rig": "cmu_mb", "original_file": path.name,
                "hip_height": hip}
        entries[clip_id] = package_motion(clip_id, out, rotations=r["rotations"],
                                          root_offsets=r["root_offsets"], info=info, files=files,
                                          license=license_, metadata=meta)
        if progress:
            print(f"  [{i + 1}/{len(jobs)}] {clip_id}: {T} frames at {r['fps']:.4g} fps",
                  flush=True)
    for fname, data in sorted(cmu_files.items()):  # the acknowledgement also sits at the top
        (out / fname).write_bytes(data if isinstance(data, bytes) else data.encode())
    (out / "LICENSES.txt").write_text("cmu_*: " + CMU_LICENSE + "\n\ndeepmimic_*: "
                                      + DEEPMIMIC_LICENSE + "\n")
    return write_manifest(out / "manifest.json", "MotionClips", "1", entries,
                          description="motion clips retargeted onto MakeHuman's cmu_mb rig "
                                      "(docs/characters.md)")


__all__ = ["BVHError", "MotionError", "build_motion_source", "retarget_bvh",
           "retarget_deepmimic"]
