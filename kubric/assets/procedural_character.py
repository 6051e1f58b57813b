"""A small procedural humanoid (:func:`tube_person`) and a walk cycle (:func:`walk_clip`).

Built in numpy in milliseconds, no files: a test fixture and a stand-in wherever a
:class:`kubric.Character` is needed without the MakeHuman source. The body is made of closed
tubes (torso, head, two three-bone arms, two three-bone legs) around a 15-bone rig whose bone
names follow MakeHuman's ``cmu_mb`` rig (Hips, Spine, Head, LeftArm, LeftForeArm, LeftHand,
LeftUpLeg, LeftLeg, LeftFoot, and Right*). Model frame as every character: metres, z up, facing
−y, feet at z = 0; the character's left is +x. Each tube ring is weighted to the bone it lies on,
blended smoothly over ±``blend`` metres around each joint (2 influences per vertex).

Its ``keypoint_regressor`` gives the 17 COCO keypoints: the joints are ring centroids of the tube
at the joint (shoulder = LeftArm head, elbow = LeftForeArm head, wrist = LeftHand head, hip =
LeftUpLeg head, knee = LeftLeg head, ankle = LeftFoot head); nose, eyes and ears are single
vertices of the head tube (front, front-left/right above, left/right sides).
"""

from __future__ import annotations

import numpy as np

from kubric.core.characters import COCO_KEYPOINTS, Character, MotionClip

#: (name, parent, head, tail), model frame, metres.
BONES = (
    ("Hips", None, (0.0, 0.0, 0.90), (0.0, 0.0, 1.05)),
    ("Spine", "Hips", (0.0, 0.0, 1.05), (0.0, 0.0, 1.42)),
    ("Head", "Spine", (0.0, 0.0, 1.46), (0.0, 0.0, 1.72)),
    ("LeftArm", "Spine", (0.19, 0.0, 1.38), (0.46, 0.0, 1.38)),
    ("LeftForeArm", "LeftArm", (0.46, 0.0, 1.38), (0.71, 0.0, 1.38)),
    ("LeftHand", "LeftForeArm", (0.71, 0.0, 1.38), (0.82, 0.0, 1.38)),
    ("RightArm", "Spine", (-0.19, 0.0, 1.38), (-0.46, 0.0, 1.38)),
    ("RightForeArm", "RightArm", (-0.46, 0.0, 1.38), (-0.71, 0.0, 1.38)),
    ("RightHand", "RightForeArm", (-0.71, 0.0, 1.38), (-0.82, 0.0, 1.38)),
    ("LeftUpLeg", "Hips", (0.10, 0.0, 0.92), (0.10, 0.0, 0.50)),
    ("LeftLeg", "LeftUpLeg", (0.10, 0.0, 0.50), (0.10, 0.0, 0.08)),
    ("LeftFoot", "LeftLeg", (0.10, 0.0, 0.08), (0.10, -0.16, 0.04)),
    ("RightUpLeg", "Hips", (-0.10, 0.0, 0.92), (-0.10, 0.0, 0.50)),
    ("RightLeg", "RightUpLeg", (-0.10, 0.0, 0.50), (-0.10, 0.0, 0.08)),
    ("RightFoot", "RightLeg", (-0.10, 0.0, 0.08), (-0.10, -0.16, 0.04)),
)
#: tube chains: (bones, radius at the chain's start, radius at its end)
CHAINS = ((("Hips", "Spine"), 0.14, 0.16), (("Head",), 0.10, 0.09),
          (("LeftArm", "LeftForeArm", "LeftHand"), 0.055, 0.035),
          (("RightArm", "RightForeArm", "RightHand"), 0.055, 0.035),
          (("LeftUpLeg", "LeftLeg", "LeftFoot"), 0.075, 0.045),
          (("RightUpLeg", "RightLeg", "RightFoot"), 0.075, 0.045))


def bone_frame(head, tail) -> np.ndarray:
    """(4, 4) a rest transform whose +Y runs head → tail (x chosen horizontal when possible)."""
    y = np.asarray(tail, float) - np.asarray(head, float)
    y /= np.linalg.norm(y)
    ref = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
    x = np.cross(y, ref)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, head
    return m


def _tube(points, radii, segments, first_vertex):
    """Rings around a polyline (closed with a centre vertex at each end) → (vertices, faces,
    ring starts). Ring k has ``segments`` vertices starting at index ``ring_starts[k]``."""
    pts = np.asarray(points, float)
    verts, faces, starts = [], [], []
    ang = 2 * np.pi * np.arange(segments) / segments
    for k, (p, r) in enumerate(zip(pts, radii, strict=True)):
        d = pts[min(k + 1, len(pts) - 1)] - pts[max(k - 1, 0)]
        d /= np.linalg.norm(d)
        ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
        u = np.cross(d, ref)
        u /= np.linalg.norm(u)
        w = np.cross(u, d)
        starts.append(first_vertex + len(verts))
        verts.extend(p + r * (np.cos(a) * u + np.sin(a) * w) for a in ang)
    for k in range(len(pts) - 1):
        a, b = starts[k], starts[k + 1]
        for s in range(segments):
            s1 = (s + 1) % segments
            faces += [(a + s, b + s, b + s1), (a + s, b + s1, a + s1)]
    cap0, cap1 = first_vertex + len(verts), first_vertex + len(verts) + 1
    verts += [pts[0], pts[-1]]
    for s in range(segments):
        s1 = (s + 1) % segments
        faces += [(cap0, starts[0] + s1, starts[0] + s), (cap1, starts[-1] + s, starts[-1] + s1)]
    return np.array(verts), faces, starts


def tube_person(name: str = "person", *, segments: int = 12, spacing: float = 0.04,
                blend: float = 0.05, **kwargs) -> Character:
    """The procedural humanoid (module doc) as a :class:`Character`; ``kwargs`` go to it."""
    names = [b[0] for b in BONES]
    parents = [-1 if b[1] is None else names.index(b[1]) for b in BONES]
    heads = {b[0]: np.array(b[2]) for b in BONES}
    tails = {b[0]: np.array(b[3]) for b in BONES}
    verts, faces, idx, wts, uv = [], [], [], [], []
    rings: dict[str, list[int]] = {}   # bone → first vertex of the ring at its head
    head_rings = []
    for chain, r0, r1 in CHAINS:
        joints = [heads[chain[0]]] + [tails[b] for b in chain]
        seg_len = [np.linalg.norm(joints[i + 1] - joints[i]) for i in range(len(chain))]
        total = sum(seg_len)
        cum = np.concatenate([[0.0], np.cumsum(seg_len)])
        pts, ring_bone, ring_s = [], [], []
        for i in range(len(chain)):
            n = max(2, int(np.ceil(seg_len[i] / spacing)))
            last = i == len(chain) - 1
            for t in np.linspace(0, 1, n + 1)[: None if last else -1]:
                pts.append(joints[i] + t * (joints[i + 1] - joints[i]))
                ring_s.append(cum[i] + t * seg_len[i])
                ring_bone.append(i)
        ring_s = np.array(ring_s)
        radii = r0 + (r1 - r0) * ring_s / total
        v, f, starts = _tube(pts, radii, segments, len(verts))
        for k, start in enumerate(starts):
            s, i = ring_s[k], ring_bone[k]
            # blend to the previous / next bone near the joints at cum[i] and cum[i+1]
            if i > 0 and s - cum[i] < blend:
                t = 0.5 + 0.5 * (s - cum[i]) / blend
                pair, w = (chain[i - 1], chain[i]), (1 - t, t)
            elif i < len(chain) - 1 and cum[i + 1] - s < blend:
                t = 0.5 + 0.5 * (cum[i + 1] - s) / blend
                pair, w = (chain[i], chain[i + 1]), (t, 1 - t)
            else:
                pair, w = (chain[i], chain[i]), (1.0, 0.0)
            for _ in range(segments):
                idx.append([names.index(pair[0]), names.index(pair[1])])
                wts.append(w)
            for b_i, b in enumerate(chain):
                if abs(s - cum[b_i]) < 1e-9:
                    rings.setdefault(b, []).append(start)
        for cap_bone in (chain[0], chain[-1]):
            idx.append([names.index(cap_bone)] * 2)
            wts.append((1.0, 0.0))
        if chain == ("Head",):
            head_rings = starts
        verts.extend(v)
        faces.extend(f)
    verts = np.array(verts)
    faces = np.array(faces, np.int32)
    # a cylindrical UV unwrap per vertex, stored per corner
    cyl = np.stack([np.arctan2(verts[:, 1], verts[:, 0]) / (2 * np.pi) + 0.5,
                    verts[:, 2] / 1.8], axis=1)
    uv = cyl[faces].astype(np.float32)
    reg = {}
    joint_bone = {"shoulder": "Arm", "elbow": "ForeArm", "wrist": "Hand", "hip": "UpLeg",
                  "knee": "Leg", "ankle": "Foot"}
    for side in ("left", "right"):
        for joint, bone in joint_bone.items():
            start = rings[side.capitalize() + bone][0]
            reg[f"{side}_{joint}"] = (np.arange(start, start + segments),
                                      np.full(segments, 1.0 / segments))
    mid = head_rings[len(head_rings) // 2]
    upper = head_rings[len(head_rings) // 2 + 1]
    # ring angle a: position r (cos a · u + sin a · w); for the vertical head u = +x, w = −y
    quarter = segments // 4
    eighth = max(1, segments // 8)
    reg["nose"] = (np.array([mid + quarter]), np.ones(1))                 # −y: the front
    reg["left_eye"] = (np.array([upper + quarter - eighth]), np.ones(1))  # front, towards +x
    reg["right_eye"] = (np.array([upper + quarter + eighth]), np.ones(1))
    reg["left_ear"] = (np.array([mid]), np.ones(1))                       # +x side
    reg["right_ear"] = (np.array([mid + 2 * quarter]), np.ones(1))        # −x side
    regressor = {k: reg[k] for k in COCO_KEYPOINTS}
    return Character(
        name=name, vertices=verts, faces=faces, uv=uv, bone_names=names, bone_parents=parents,
        bone_rest=np.stack([bone_frame(heads[n], tails[n]) for n in names]),
        bone_tails=np.stack([tails[n] for n in names]), skin_indices=np.array(idx, np.int32),
        skin_weights=np.array(wts, np.float32), keypoint_regressor=regressor, **kwargs)


def _about_x(angles) -> np.ndarray:
    """(…, 4) WXYZ rotations about the bone's local x axis."""
    a = np.asarray(angles, float) / 2
    return np.stack([np.cos(a), np.sin(a), np.zeros_like(a), np.zeros_like(a)], -1)


def walk_clip(seconds: float = 2.0, fps: float = 30.0, speed: float = 0.8,
              stride_hz: float = 1.0) -> MotionClip:
    """A procedural walk for :func:`tube_person`: legs and knees swing about their local x axis
    (the body's left-right axis), the arms hang lowered with the elbows bending in time, the
    root moves along −y at
    ``speed`` m/s with a small vertical bob."""
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    ph = 2 * np.pi * stride_hz * t
    names = ["LeftUpLeg", "LeftLeg", "RightUpLeg", "RightLeg", "LeftArm", "RightArm",
             "LeftForeArm", "RightForeArm", "Spine"]
    swing = 0.45 * np.sin(ph)
    knee_l = 0.6 * np.clip(np.sin(ph - 1.2), 0, None)
    knee_r = 0.6 * np.clip(np.sin(ph + np.pi - 1.2), 0, None)
    # arm bones point along ±x with local x horizontal: a rotation about local x by −1.1 rad
    # lowers either arm by 63° (towards −z)
    arm = _about_x(np.full_like(t, -1.1))
    rot = np.stack([_about_x(swing), _about_x(-knee_l), _about_x(-swing), _about_x(-knee_r),
                    arm, arm, _about_x(-0.3 - 0.3 * np.sin(ph)), _about_x(-0.3 + 0.3 * np.sin(ph)),
                    _about_x(0.05 * np.sin(2 * ph))], axis=1)
    offsets = np.stack([0 * t, -speed * t, 0.02 * np.sin(2 * ph)], -1)
    return MotionClip(names, fps, rot, offsets, name="procedural_walk",
                      metadata={"licence": "generated by kubric (no third-party data)"})
