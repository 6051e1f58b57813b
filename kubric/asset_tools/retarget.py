"""Retarget a source skeleton's motion onto a target rig by world-rotation deltas.

Both skeletons are first put in the *same reference pose*: the source's zero pose (BVH: every
rotation channel 0, a T-pose for CMU files; DeepMimic: every joint at identity) and, on the target,
each aligned bone swung (minimal rotation, parents first) so that its head→tail direction equals
the direction of the source segment it follows in that pose. Then at every frame a target bone
mapped to a source joint takes that joint's world-rotation change from the reference,
``W_b(t) = W_s(t) · W_s,ref⁻¹ · W_b,ref``; an unmapped bone keeps its reference orientation
relative to its parent. Aligned bones therefore point exactly along their source segments at
every frame. Local pose rotations follow the character contract (docs/characters.md):
``q_b = Rl_b⁻¹ · W_parent⁻¹ · W_b`` with ``Rl_b`` the rest rotation relative to the parent.

All inputs are in the target's model frame (metres, Z up, facing −Y); convert the source first.
"""

from __future__ import annotations

import numpy as np

Y = np.array([0.0, 1.0, 0.0])


def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The minimal rotation (3×3) taking unit direction ``a`` to unit direction ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1 + 1e-12:  # opposite: half-turn about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0, 0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k / (1 + c)


def matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations → (..., 4) unit quaternions (w, x, y, z)."""
    m = np.asarray(m, dtype=np.float64)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = np.trace(m, axis1=1, axis2=2)
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = np.argmax(cand, axis=1)
    q = np.empty((len(m), 4))
    for i in range(4):
        sel = k == i
        if not sel.any():
            continue
        r = m[sel]
        if i == 0:
            s = np.sqrt(1.0 + tr[sel]) * 2
            q[sel] = np.stack([0.25 * s, (r[:, 2, 1] - r[:, 1, 2]) / s,
                               (r[:, 0, 2] - r[:, 2, 0]) / s, (r[:, 1, 0] - r[:, 0, 1]) / s], 1)
        else:
            a, b, c = [(0, 1, 2), (1, 2, 0), (2, 0, 1)][i - 1]
            s = np.sqrt(1.0 + r[:, a, a] - r[:, b, b] - r[:, c, c]) * 2
            out = np.empty((len(r), 4))
            out[:, 0] = (r[:, c, b] - r[:, b, c]) / s
            out[:, 1 + a] = 0.25 * s
            out[:, 1 + b] = (r[:, b, a] + r[:, a, b]) / s
            out[:, 1 + c] = (r[:, c, a] + r[:, a, c]) / s
            q[sel] = out
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(shape + (4,))


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z) → (..., 3, 3) rotations."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def continuous(q: np.ndarray) -> np.ndarray:
    """(T, J, 4): flip signs so each quaternion is on the same side as the previous frame's
    (frame 0: w ≥ 0), so that interpolating between frames takes the short way."""
    q = q.copy()
    q[0] *= np.where(q[0, :, :1] < 0, -1.0, 1.0)
    for t in range(1, len(q)):
        q[t] *= np.where(np.sum(q[t] * q[t - 1], axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return q


def reference_pose(parents, rest: np.ndarray, directions: dict[int, np.ndarray]) -> np.ndarray:
    """(J, 3, 3) world orientations of the target bones in the reference pose: each bone carried
    by its parent's change from rest, then swung onto ``directions[bone]`` when given."""
    rot = rest[:, :3, :3]
    ref = np.empty_like(rot)
    for b, p in enumerate(parents):
        ref[b] = rot[b] if p < 0 else ref[p] @ rot[p].T @ rot[b]
        if b in directions:
            ref[b] = swing(ref[b] @ Y, directions[b]) @ ref[b]
    return ref


def retarget_rotations(parents, rest: np.ndarray, source_world: np.ndarray,
                       mapping: dict[int, int], directions: dict[int, np.ndarray]) -> np.ndarray:
    """(T, J, 4) local pose quaternions of the target.

    Args:
      parents, rest: the target rig (parents before children; rest (J, 4, 4) model frame).
      source_world: (T, S, 3, 3) world rotations of the source joints, model frame, relative to
        the source's reference pose (identity there).
      mapping: target bone → source joint it follows (others keep their pose relative to the
        parent).
      directions: target bone → unit direction (model frame) of its source segment in the
        reference pose.
    """
    ref = reference_pose(parents, rest, directions)
    rot = rest[:, :3, :3]
    T = len(source_world)
    world = np.empty((T, len(parents), 3, 3))
    local = np.empty_like(world)
    for b, p in enumerate(parents):
        if b in mapping:
            world[:, b] = source_world[:, mapping[b]] @ ref[b]
        elif p < 0:
            world[:, b] = ref[b]
        else:
            world[:, b] = world[:, p] @ (ref[p].T @ ref[b])
        rest_local = rot[b] if p < 0 else rot[p].T @ rot[b]
        parent_world = np.eye(3) if p < 0 else world[:, p]
        local[:, b] = rest_local.T @ np.swapaxes(parent_world, -1, -2) @ world[:, b]
    return continuous(matrix_to_quaternion(local))


def forward_kinematics(parents, rest: np.ndarray, rotations: np.ndarray,
                       root_offsets: np.ndarray | None = None) -> np.ndarray:
    """(T, J, 4, 4) bone-to-model transforms by the contract's FK (docs/characters.md)."""
    T = len(rotations)
    R = quaternion_to_matrix(rotations)
    G = np.empty((T, len(parents), 4, 4))
    for b, p in enumerate(parents):
        L = np.tile(rest[b] if p < 0 else np.linalg.inv(rest[p]) @ rest[b], (T, 1, 1))
        if p < 0 and root_offsets is not None:
            L[:, :3, 3] += root_offsets
        L[:, :3, :3] = L[:, :3, :3] @ R[:, b]
        G[:, b] = L if p < 0 else G[:, p] @ L
    return G
