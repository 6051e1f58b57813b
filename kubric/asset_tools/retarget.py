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

from kubric.core.skinning import matrices_to_quaternions, quaternions_to_matrices

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
    return continuous(matrices_to_quaternions(local))


def forward_kinematics(parents, rest: np.ndarray, rotations: np.ndarray,
                       root_offsets: np.ndarray | None = None) -> np.ndarray:
    """(T, J, 4, 4) bone-to-model transforms by the contract's FK (docs/characters.md)."""
    T = len(rotations)
    R = quaternions_to_matrices(rotations)
    G = np.empty((T, len(parents), 4, 4))
    for b, p in enumerate(parents):
        L = np.tile(rest[b] if p < 0 else np.linalg.inv(rest[p]) @ rest[b], (T, 1, 1))
        if p < 0 and root_offsets is not None:
            L[:, :3, 3] += root_offsets
        L[:, :3, :3] = L[:, :3, :3] @ R[:, b]
        G[:, b] = L if p < 0 else G[:, p] @ L
    return G
