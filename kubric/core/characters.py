"""Rigged, skinned, animated characters (:class:`Character`) and motion clips (:class:`MotionClip`).

The model is the truth: it computes the deformed mesh at any frame by linear-blend skinning
(:mod:`kubric.core.skinning`), and the views follow it (the Blender view builds an armature with
the same bones and weights; the simulator makes per-bone kinematic colliders). Conventions, units
and the keypoint definitions: docs/characters.md.

Model frame: metres, z up, the character faces −y at rest, feet at z = 0. The object's own pose
(position, quaternion, scale: keyframable as for every object) maps the model frame to the world.
The pose is two keyframable properties: ``bone_rotations`` (J, 4) WXYZ per bone in its rest local
frame (identity = rest) and ``root_offset`` (3,) metres. Between keys ``bone_rotations`` are
interpolated per bone by normalised linear interpolation along the shorter arc (what Blender does
with pose-bone quaternion keys, so the two agree between frames as well as at them).
"""

from __future__ import annotations

import numpy as np

from kubric.core import skinning as sk
from kubric.core import traits as kt
from kubric.core.objects import PhysicalObject
from kubric.errors import InputError

#: The 17 COCO person keypoints, in COCO's order.
COCO_KEYPOINTS = ("nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder",
                  "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
                  "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")
#: COCO's skeleton (1-based keypoint index pairs, as in COCO's person category).
COCO_SKELETON = ((16, 14), (14, 12), (17, 15), (15, 13), (12, 13), (6, 12), (7, 13), (6, 7),
                 (6, 8), (7, 9), (8, 10), (9, 11), (2, 3), (1, 2), (1, 3), (2, 4), (3, 5), (4, 6),
                 (5, 7))
MAX_INFLUENCES = 8


def _array(where, name, value, dtype, shape) -> np.ndarray:
    """``value`` as an array of ``dtype`` whose shape matches ``shape`` (None = any size)."""
    try:
        arr = np.array(value, dtype=dtype)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {name} must be a numeric array of shape "
                         f"{_shape_text(shape)}, got {type(value).__name__}") from None
    if arr.ndim != len(shape) or any(s is not None and a != s
                                     for a, s in zip(arr.shape, shape, strict=True)):
        raise InputError(f"{where}: {name} must have shape {_shape_text(shape)}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0].tolist()
        raise InputError(f"{where}: {name} holds NaN or inf (first at index {bad})")
    return arr


def _shape_text(shape) -> str:
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"


def _integers(where, name, value, shape, low, high) -> np.ndarray:
    arr = np.asarray(value)
    if arr.size and arr.dtype.kind not in "iu":
        raise InputError(f"{where}: {name} must be integers, got dtype {arr.dtype}")
    arr = _array(where, name, arr, np.int64, shape)
    if arr.size and (arr.min() < low or arr.max() >= high):
        bad = arr[(arr < low) | (arr >= high)][0]
        raise InputError(f"{where}: {name} holds {int(bad)}; allowed: [{low}, {high - 1}]")
    return arr


class Character(PhysicalObject):
    """A skinned, animated mesh (module doc; contract in docs/characters.md).

    Rig and mesh (keyword arguments, fixed after construction): ``vertices`` (V, 3), ``faces``
    (F, 3), ``uv`` (F, 3, 2) or None, ``bone_names`` (J), ``bone_parents`` (J,), ``bone_rest``
    (J, 4, 4), ``bone_tails`` (J, 3), ``skin_indices`` / ``skin_weights`` (V, K ≤ 8),
    ``keypoint_regressor`` {name: (vertex indices, weights)} or None. Every other keyword is a
    property (position, quaternion, scale, material, bone_rotations, root_offset, ...).
    ``static`` defaults to True: a character moves by its keyframes only (a kinematic body).
    """

    bone_rotations = kt.Property(None, lambda v, o, n: o._convert_rotations(v),
                                 "(J, 4) WXYZ per bone, in its rest local frame; identity = rest",
                                 interpolation="linear")
    root_offset = kt.Vector3D((0.0, 0.0, 0.0), "root translation from its rest head (m, model)")
    property_defaults = {"static": True, "mass": 0.0}

    def __init__(self, *, vertices, faces, bone_names, bone_parents, bone_rest, bone_tails,
                 skin_indices, skin_weights, uv=None, keypoint_regressor=None, **kwargs):
        where = f"Character {kwargs.get('name') or 'Character'!r}"
        self._set_rig(where, vertices, faces, uv, bone_names, bone_parents, bone_rest,
                      bone_tails, skin_indices, skin_weights, keypoint_regressor)
        kwargs.setdefault("bounds", self.rest_bounds)
        super().__init__(**kwargs)

    # ------------------------------------------------------------------ construction
    def _set_rig(self, where, vertices, faces, uv, names, parents, rest, tails, idx, wts, reg):
        v = _array(where, "vertices", vertices, np.float64, (None, 3))
        if not len(v):
            raise InputError(f"{where}: vertices is empty")
        f = _integers(where, "faces", faces, (None, 3), 0, len(v))
        if not len(f):
            raise InputError(f"{where}: faces is empty (a character needs a triangulated mesh)")
        if uv is not None:
            uv = _array(where, "uv", uv, np.float32, (len(f), 3, 2))
        if isinstance(names, str) or not all(isinstance(n, str) and n for n in names):
            raise InputError(f"{where}: bone_names must be a list of non-empty strings")
        names = list(names)
        if not names:
            raise InputError(f"{where}: the rig has no bones")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise InputError(f"{where}: bone_names repeats {dup}")
        j = len(names)
        par = _integers(where, "bone_parents", parents, (j,), -1, j)
        if par[0] != -1 or np.any(par[1:] < 0) or np.any(par[1:] >= np.arange(1, j)):
            raise InputError(f"{where}: bone_parents must be -1 for bone 0 (the root) and a "
                             f"smaller index for every other bone, got {par.tolist()}")
        rst = _array(where, "bone_rest", rest, np.float64, (j, 4, 4))
        rot = rst[:, :3, :3]
        err = np.abs(rot @ rot.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero((err > 1e-5) | (np.linalg.det(rot) < 0)
                             | np.any(np.abs(rst[:, 3] - [0, 0, 0, 1]) > 1e-9, axis=1))
        if len(bad):
            raise InputError(f"{where}: bone_rest of bone {names[bad[0]]!r} is not a rigid "
                             "transform (orthonormal rotation, det +1, last row 0 0 0 1)")
        tl = _array(where, "bone_tails", tails, np.float64, (j, 3))
        axis = tl - rst[:, :3, 3]
        length = np.linalg.norm(axis, axis=1)
        cos = np.einsum("ji,ji->j", axis, rot[:, :, 1]) / np.maximum(length, 1e-12)
        bad = np.flatnonzero((length < 1e-6) | (cos < 1 - 1e-6))
        if len(bad):
            raise InputError(f"{where}: bone {names[bad[0]]!r}: its tail must lie on the bone's "
                             "local +Y axis at a positive distance from its head (bone_rest)")
        if np.ndim(idx) != 2 or np.shape(idx)[1] > MAX_INFLUENCES or np.shape(idx)[0] != len(v):
            raise InputError(f"{where}: skin_indices must have shape (V={len(v)}, K ≤ "
                             f"{MAX_INFLUENCES}), got {np.shape(idx)}")
        si = _integers(where, "skin_indices", idx, (len(v), None), 0, j)
        sw = _array(where, "skin_weights", wts, np.float64, si.shape)
        if np.any(sw < 0):
            raise InputError(f"{where}: skin_weights must be ≥ 0, got {sw.min():g}")
        total = sw.sum(axis=1)
        rendered = np.zeros(len(v), bool)
        rendered[f.ravel()] = True
        if np.any(rendered & (total <= 0)):
            n = int(np.sum(rendered & (total <= 0)))
            what = "has no skin weights" if not np.any(total > 0) else \
                f"leaves {n} rendered vertices without weight"
            raise InputError(f"{where}: the rig {what} (every vertex of a face needs weights)")
        sw = np.where(total[:, None] > 0, sw / np.where(total > 0, total, 1)[:, None], 0.0)
        self.vertices, self.faces, self.uv = v, f.astype(np.int32), uv
        self.bone_names, self.bone_parents, self.bone_rest, self.bone_tails = names, par, rst, tl
        self.skin_indices, self.skin_weights = si.astype(np.int32), sw
        self.rendered_vertices = np.flatnonzero(rendered)
        self.keypoint_regressor = self._check_regressor(where, reg, len(v))
        self._weights = sk.weight_matrix(self.skin_indices, sw, j)
        self._weights.setflags(write=False)
        self._rest_local = sk.rest_locals(rst, par)
        self._inv_rest = np.linalg.inv(rst)
        for arr in (v, self.faces, rst, tl, self.skin_indices, sw, par):
            arr.setflags(write=False)

    @staticmethod
    def _check_regressor(where, reg, num_vertices):
        if reg is None:
            return None
        if not isinstance(reg, dict) or not reg:
            raise InputError(f"{where}: keypoint_regressor must be a non-empty dict "
                             "{name: (vertex indices, weights)} or None")
        out = {}
        for name, pair in reg.items():
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise InputError(f"{where}: keypoint_regressor[{name!r}] must be "
                                 "(vertex indices, weights)")
            idx = _integers(where, f"keypoint_regressor[{name!r}] indices", pair[0], (None,), 0,
                            num_vertices)
            w = _array(where, f"keypoint_regressor[{name!r}] weights", pair[1], np.float64,
                       (len(idx),))
            if not len(idx):
                raise InputError(f"{where}: keypoint_regressor[{name!r}] names no vertex")
            out[str(name)] = (idx, w)
        return out

    def _convert_rotations(self, value):
        j = len(self.bone_names)
        if value is None:
            value = np.tile([1.0, 0.0, 0.0, 0.0], (j, 1))
        arr = _array(f"Character {self.name!r}", "bone_rotations", value, np.float64, (j, 4))
        norm = np.linalg.norm(arr, axis=1)
        if np.any(norm < 1e-8):
            bad = self.bone_names[int(np.flatnonzero(norm < 1e-8)[0])]
            raise InputError(f"Character {self.name!r}: bone_rotations of bone {bad!r} is the "
                             "zero quaternion (need a non-zero WXYZ quaternion per bone)")
        out = (arr / norm[:, None]).astype(np.float32)
        out.setflags(write=False)
        return out

    # ------------------------------------------------------------------ interpolation
    def get_value_at(self, name, frame, interpolation=None):
        """As :meth:`Asset.get_value_at`; ``bone_rotations`` between keys: per-bone nlerp along
        the shorter arc (module doc)."""
        keys = self.keyframes.get(name)
        if name != "bone_rotations" or not keys or frame in keys or interpolation is not None:
            return super().get_value_at(name, frame, interpolation)
        frames = sorted(keys)
        if frame <= frames[0] or frame >= frames[-1]:
            return keys[frames[0] if frame <= frames[0] else frames[-1]]
        right = int(np.searchsorted(frames, frame))
        f0, f1 = frames[right - 1], frames[right]
        q = sk.nlerp(keys[f0], keys[f1], (frame - f0) / (f1 - f0))
        return self._convert_rotations(q)

    # ------------------------------------------------------------------ geometry
    @property
    def num_bones(self) -> int:
        return len(self.bone_names)

    @property
    def keypoint_names(self) -> tuple[str, ...]:
        return tuple(self.keypoint_regressor or ())

    @property
    def rest_bounds(self) -> np.ndarray:
        """(2, 3) model-frame box of the rendered rest vertices."""
        v = self.vertices[self.rendered_vertices]
        return np.stack([v.min(axis=0), v.max(axis=0)])

    def triangle_bones(self) -> np.ndarray:
        """(F,) int: the body part of each face, the bone with the largest skin weight summed
        over its three vertices (ties: the lower bone index)."""
        return np.argmax(self._weights[self.faces].sum(axis=1), axis=1)

    def bone_index(self, name: str) -> int:
        try:
            return self.bone_names.index(name)
        except ValueError:
            raise KeyError(f"Character {self.name!r} has no bone {name!r}; bones: "
                           f"{self.bone_names}") from None

    def _pose(self):
        return (np.asarray(self.bone_rotations, np.float64),
                np.asarray(self.root_offset, np.float64))

    def posed_bones(self, frame=None) -> np.ndarray:
        """(J, 4, 4) posed bone → model transforms at ``frame`` (None: the current values)."""
        with self.at_frame(frame):
            rot, off = self._pose()
        return sk.posed_bones(self._rest_local, self.bone_parents, rot, off)

    def skinning_matrices(self, frame=None) -> np.ndarray:
        """(J, 4, 4) model-frame skinning matrices ``S_j`` at ``frame``."""
        return sk.skinning_matrices(self.posed_bones(frame), self._inv_rest)

    def model_to_world(self, frame=None) -> np.ndarray:
        """(4, 4) model → world (the object's position, quaternion and scale) at ``frame``."""
        with self.at_frame(frame):
            return sk.object_matrix(self.position, self.quaternion, self.scale)

    def bone_transforms(self, frame=None) -> np.ndarray:
        """(J, 4, 4) posed bone → world transforms at ``frame`` (heads at ``[:, :3, 3]``)."""
        return self.model_to_world(frame) @ self.posed_bones(frame)

    def bone_transforms_at(self, frames) -> np.ndarray:
        """(N, J, 4, 4) posed bone → world transforms at N (fractional) ``frames``, computed in
        one batch (what :meth:`bone_transforms` gives frame by frame)."""
        frames = list(frames)
        rot = np.stack([self.get_value_at("bone_rotations", f) for f in frames]).astype(float)
        off = np.stack([self.get_value_at("root_offset", f) for f in frames]).astype(float)
        posed = sk.posed_bones(self._rest_local, self.bone_parents, rot, off)
        worlds = np.stack([sk.object_matrix(self.get_value_at("position", f),
                                            self.get_value_at("quaternion", f),
                                            self.get_value_at("scale", f)) for f in frames])
        return worlds[:, None] @ posed

    def _world(self, model_points, frame):
        m = self.model_to_world(frame)
        return model_points @ m[:3, :3].T + m[:3, 3]

    def deformed_vertices(self, frame=None, indices=None, space: str = "world") -> np.ndarray:
        """(V, 3) skinned vertices at ``frame`` (or only ``indices``), ``space`` "world" or
        "model"."""
        if space not in ("world", "model"):
            raise InputError(f"space must be 'world' or 'model', got {space!r}")
        sel = slice(None) if indices is None else np.asarray(indices)
        pts = sk.skin(self.vertices[sel], self._weights[sel], self.skinning_matrices(frame))
        return pts if space == "model" else self._world(pts, frame)

    def surface_points(self, triangles, barycentrics, frame=None, space: str = "world"):
        """(N, 3) points ``Σ bary_i · deformed(faces[tri, i])`` at ``frame``: the rendered
        surface point with these (triangle, barycentric) coordinates on the deformed mesh.
        ``frame=None`` and ``space="rest"`` give the rest-pose point (model frame)."""
        tri = np.asarray(triangles, np.int64)
        bary = np.asarray(barycentrics, np.float64)
        if bary.shape != tri.shape + (3,):
            raise InputError(f"barycentrics must have shape {tri.shape + (3,)}, got {bary.shape}")
        if tri.size and (tri.min() < 0 or tri.max() >= len(self.faces)):
            raise InputError(f"triangles must be in [0, {len(self.faces) - 1}]")
        corners = self.faces[tri]                                      # (N, 3)
        if space == "rest":
            pts = self.vertices[corners]
        else:
            used, inverse = np.unique(corners, return_inverse=True)
            pts = self.deformed_vertices(frame, used, space)[inverse.reshape(corners.shape)]
        return np.einsum("ni,nij->nj", bary, pts)

    def keypoints(self, frame=None, space: str = "world") -> np.ndarray:
        """(K, 3) keypoints (``keypoint_names`` order) from the regressor on the deformed mesh."""
        if self.keypoint_regressor is None:
            raise InputError(f"Character {self.name!r} has no keypoint_regressor")
        idx = np.concatenate([i for i, _ in self.keypoint_regressor.values()])
        used, inverse = np.unique(idx, return_inverse=True)
        pts = self.deformed_vertices(frame, used, space)[inverse]
        out, start = [], 0
        for i, w in self.keypoint_regressor.values():
            out.append(w @ pts[start:start + len(i)])
            start += len(i)
        return np.stack(out)

    def model_box(self, frame=None) -> np.ndarray:
        """(2, 3) model-frame box of the rendered deformed vertices at ``frame``."""
        pts = self.deformed_vertices(frame, self.rendered_vertices, "model")
        return np.stack([pts.min(axis=0), pts.max(axis=0)])

    def aabb(self, frame=None) -> np.ndarray:
        """(2, 3) world-space box of the rendered deformed vertices at ``frame``."""
        pts = self.deformed_vertices(frame, self.rendered_vertices)
        return np.stack([pts.min(axis=0), pts.max(axis=0)])

    @property
    def aabbox(self) -> np.ndarray:
        return self.aabb()

    @property
    def bbox_3d(self) -> np.ndarray:
        """(8, 3) world corners of the model-frame box of the current deformed mesh (corner
        order as :attr:`PhysicalObject.bbox_3d`)."""
        import itertools
        b = self.model_box()
        corners = np.array(list(itertools.product(b[:, 0], b[:, 1], b[:, 2])))
        return self._world(corners, None)

    # ------------------------------------------------------------------ animation
    def play(self, clip, start_frame: int | None = None, frame_rate: float | None = None, *,
             end_frame: int | None = None, clip_start: float = 0.0, loop: bool = False) -> None:
        """Key ``bone_rotations`` and ``root_offset`` at every frame from ``start_frame`` to
        ``end_frame`` (default: the scene's range) from ``clip`` resampled to ``frame_rate``
        (default: the scene's): frame f shows clip time ``clip_start + (f − start_frame) /
        frame_rate`` seconds, interpolated between clip samples (nlerp / linear); past the end the
        clip holds its last sample, or wraps with ``loop``. Bones the clip does not name keep
        their current rotation."""
        if not isinstance(clip, MotionClip):
            raise TypeError(f"Character.play needs a MotionClip, got {type(clip).__name__}")
        unknown = [n for n in clip.bone_names if n not in self.bone_names]
        if unknown:
            raise InputError(f"MotionClip {clip.name!r}: joints {unknown} match no bone of "
                             f"character {self.name!r} (bones: {self.bone_names})")
        scene = self.active_scene
        if start_frame is None or end_frame is None or frame_rate is None:
            if scene is None:
                raise InputError("Character.play: the character is in no scene; pass "
                                 "start_frame, end_frame and frame_rate")
            start_frame = scene.frame_start if start_frame is None else start_frame
            end_frame = scene.frame_end if end_frame is None else end_frame
            frame_rate = scene.frame_rate if frame_rate is None else frame_rate
        if frame_rate <= 0 or end_frame < start_frame:
            raise InputError(f"Character.play: need frame_rate > 0 and end_frame ≥ start_frame, "
                             f"got {frame_rate}, {start_frame}..{end_frame}")
        cols = [self.bone_names.index(n) for n in clip.bone_names]
        frames = np.arange(start_frame, end_frame + 1)
        rot, off = clip.sample(clip_start + (frames - start_frame) / float(frame_rate), loop)
        base = np.asarray(self.bone_rotations, np.float64)
        prev = None
        for i, f in enumerate(frames):
            pose = base.copy()
            pose[cols] = rot[i]
            if prev is not None:
                pose = sk.align_signs(prev, pose)
            prev = pose
            self.bone_rotations = pose
            self.root_offset = off[i]
            self.keyframe_insert("bone_rotations", int(f))
            self.keyframe_insert("root_offset", int(f))


class MotionClip:
    """A skeletal animation: per-sample bone rotations and root offsets for a named rig.

    Args:
      bone_names: the J joints the clip drives (matched by name to a character's bones).
      fps: samples per second (> 0).
      rotations: (T, J, 4) WXYZ, same convention as :attr:`Character.bone_rotations`.
      root_offsets: (T, 3) metres, as :attr:`Character.root_offset`.
      name: for messages; metadata: free-form (source file, licence, acknowledgement).
    """

    def __init__(self, bone_names, fps, rotations, root_offsets, name: str = "clip",
                 metadata: dict | None = None):
        where = f"MotionClip {name!r}"
        if isinstance(bone_names, str) or not bone_names or not all(
                isinstance(n, str) and n for n in bone_names):
            raise InputError(f"{where}: bone_names must be a non-empty list of strings")
        if isinstance(fps, bool) or not isinstance(fps, (int, float, np.number)) or \
                not np.isfinite(fps) or fps <= 0:
            raise InputError(f"{where}: fps must be a positive number, got {fps!r}")
        j = len(bone_names)
        rot = np.asarray(rotations, dtype=np.float64)
        if rot.ndim != 3 or rot.shape[1:] != (j, 4) or not len(rot):
            raise InputError(f"{where}: rotations must have shape (T ≥ 1, {j}, 4), got "
                             f"{rot.shape}")
        bad = ~np.isfinite(rot).all(axis=2)
        if bad.any():
            t, b = np.argwhere(bad)[0]
            raise InputError(f"{where}: rotations hold NaN or inf at sample {t}, joint "
                             f"{bone_names[b]!r}")
        norm = np.linalg.norm(rot, axis=2)
        if np.any(norm < 1e-8):
            t, b = np.argwhere(norm < 1e-8)[0]
            raise InputError(f"{where}: zero quaternion at sample {t}, joint {bone_names[b]!r}")
        off = _array(where, "root_offsets", root_offsets, np.float64, (len(rot), 3))
        self.bone_names = list(bone_names)
        self.fps = float(fps)
        self.rotations = rot / norm[..., None]
        self.root_offsets = off
        self.name = str(name)
        self.metadata = dict(metadata or {})

    @property
    def num_samples(self) -> int:
        return len(self.rotations)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last sample."""
        return (self.num_samples - 1) / self.fps

    def sample(self, times, loop: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(rotations (N, J, 4), root_offsets (N, 3)) at ``times`` (seconds; see Character.play)."""
        s = np.asarray(times, np.float64) * self.fps
        n = self.num_samples
        if loop and n > 1:
            s = np.mod(s, n - 1)
        s = np.clip(s, 0, n - 1)
        i0 = np.floor(s).astype(np.int64)
        i1 = np.minimum(i0 + 1, n - 1)
        t = s - i0
        rot = sk.nlerp(self.rotations[i0], self.rotations[i1], t[:, None])
        off = (1 - t[:, None]) * self.root_offsets[i0] + t[:, None] * self.root_offsets[i1]
        return rot, off
