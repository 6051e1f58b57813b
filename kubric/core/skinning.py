"""Forward kinematics and linear-blend skinning for :class:`kubric.core.characters.Character`.

Pure numpy, float64. Conventions (docs/characters.md):

* ``bone_rest[j]`` (4, 4) maps bone j's rest local frame to the character's model frame (the
  translation is the bone head, local +Y points from head to tail, as Blender's bones).
* A pose is ``rotations`` (J, 4) WXYZ, each bone's rotation in its own rest local frame (Blender's
  pose-bone ``rotation_quaternion``), plus ``root_offset`` (3,): the root's translation in model
  space relative to its rest head.
* ``L_j = rest_local_j @ R(q_j)`` with ``rest_local_j = inv(bone_rest[parent]) @ bone_rest[j]``;
  the root's ``rest_local`` is ``bone_rest[root]`` translated by ``root_offset``.
  ``G_j = G_parent @ L_j`` (bone → model, posed); ``S_j = G_j @ inv(bone_rest[j])`` (skinning).
* Linear-blend skinning: ``v' = Σ_k w_k S_{idx_k} v`` (as a dense (V, J) weight matrix);
  vertices with zero total weight keep their rest position (Blender's armature modifier leaves
  unweighted vertices in place).
"""

from __future__ import annotations

import numpy as np


def quaternions_to_matrices(q: np.ndarray) -> np.ndarray:
    """(..., 4) WXYZ quaternions (normalised here) → (..., 3, 3) rotation matrices."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rest_locals(bone_rest: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """(J, 4, 4) each bone's rest transform relative to its parent (the root's: to the model)."""
    out = np.array(bone_rest, dtype=np.float64)
    inv = np.linalg.inv(out)
    for j, p in enumerate(parents):
        if p >= 0:
            out[j] = inv[p] @ bone_rest[j]
    return out


def posed_bones(rest_local: np.ndarray, parents: np.ndarray, rotations: np.ndarray,
                root_offset: np.ndarray) -> np.ndarray:
    """(..., J, 4, 4) posed bone → model transforms ``G`` (module doc) for rotations
    (..., J, 4) and root offsets (..., 3): any leading batch shape (e.g. several frames)."""
    rotations = np.asarray(rotations, np.float64)
    batch = rotations.shape[:-2]
    local = np.broadcast_to(rest_local, batch + rest_local.shape).copy()
    local[..., :3, :3] = local[..., :3, :3] @ quaternions_to_matrices(rotations)
    out = np.empty_like(local)
    for j, p in enumerate(parents):
        if p < 0:
            m = local[..., j, :, :].copy()
            m[..., :3, 3] += root_offset
            out[..., j, :, :] = m
        else:
            out[..., j, :, :] = out[..., p, :, :] @ local[..., j, :, :]
    return out


def skinning_matrices(posed: np.ndarray, inv_rest: np.ndarray) -> np.ndarray:
    """(J, 4, 4) ``S_j = G_j @ inv(bone_rest_j)``."""
    return posed @ inv_rest


def weight_matrix(indices: np.ndarray, weights: np.ndarray, num_bones: int) -> np.ndarray:
    """(V, J) dense skin weights from (V, K) indices / weights (repeated indices add up)."""
    out = np.zeros((len(indices), num_bones))
    np.add.at(out, (np.repeat(np.arange(len(indices)), indices.shape[1]), indices.ravel()),
              weights.ravel().astype(np.float64))
    return out


def skin(vertices: np.ndarray, weights: np.ndarray, skinning: np.ndarray) -> np.ndarray:
    """Linear-blend skinning of (V, 3) rest vertices in the model frame → (V, 3).

    ``weights`` (V, J) dense per-bone weights (rows normalised, or all zero = unweighted: the
    vertex keeps its rest position); one (V, J) × (J, 12) product blends the matrices.
    """
    j = len(skinning)
    blend = (weights @ skinning[:, :3, :].reshape(j, 12)).reshape(-1, 3, 4)
    out = np.einsum("vij,vj->vi", blend[:, :, :3], vertices) + blend[:, :, 3]
    unweighted = weights.sum(axis=1) == 0
    if unweighted.any():
        out[unweighted] = vertices[unweighted]
    return out


def to_world(points: np.ndarray, position, quaternion, scale) -> np.ndarray:
    """Model-frame (…, 3) points → world: scale, then rotate, then translate (Object3D)."""
    rot = quaternions_to_matrices(np.asarray(quaternion, dtype=np.float64))
    return (np.asarray(points) * np.asarray(scale, np.float64)) @ rot.T + np.asarray(
        position, np.float64)


def object_matrix(position, quaternion, scale) -> np.ndarray:
    """(4, 4) model → world including scale."""
    m = np.eye(4)
    m[:3, :3] = quaternions_to_matrices(np.asarray(quaternion, np.float64)) * np.asarray(
        scale, np.float64)
    m[:3, 3] = position
    return m


def align_signs(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``q1`` (…, 4) with rows flipped where their dot product with ``q0`` is negative."""
    dot = np.sum(np.asarray(q0) * np.asarray(q1), axis=-1, keepdims=True)
    return np.where(dot < 0, -np.asarray(q1), np.asarray(q1))


def nlerp(q0: np.ndarray, q1: np.ndarray, t) -> np.ndarray:
    """Per-row normalised linear interpolation along the shorter arc (what Blender does between
    quaternion keys: component-wise linear, normalised when the matrix is built)."""
    q0 = np.asarray(q0, np.float64)
    q1 = align_signs(q0, np.asarray(q1, np.float64))
    t = np.asarray(t, np.float64)[..., None] if np.ndim(t) else t
    q = (1.0 - t) * q0 + t * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def matrices_to_quaternions(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices → (..., 4) WXYZ unit quaternions (w ≥ 0), vectorised
    (Shepperd's method: the largest of w, x, y, z is found first for numerical stability)."""
    m = np.asarray(m, np.float64)
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cand = np.stack([tr, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], -1)
    k = np.argmax(cand, axis=-1)
    q = np.empty(m.shape[:-2] + (4,))
    s = np.sqrt(np.maximum(1.0 + 2.0 * cand.max(-1) - tr, 1e-300))  # 2·|largest component|·2
    w = (m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1])
    xy, xz, yz = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    rows = {0: (s / 2, w[0] / (2 * s), w[1] / (2 * s), w[2] / (2 * s)),
            1: (w[0] / (2 * s), s / 2, xy / (2 * s), xz / (2 * s)),
            2: (w[1] / (2 * s), xy / (2 * s), s / 2, yz / (2 * s)),
            3: (w[2] / (2 * s), xz / (2 * s), yz / (2 * s), s / 2)}
    for i, row in rows.items():
        sel = k == i
        q[sel] = np.stack([c[sel] for c in row], -1)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)
