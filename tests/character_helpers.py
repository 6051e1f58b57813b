"""Shared by the character tests: the contract's FK + linear-blend skinning, written out
independently of kubric's own implementations."""

from __future__ import annotations

import numpy as np


def lbs(a, rotations=None, root_offset=None):
    """The contract's forward kinematics + linear-blend skinning, written out here."""
    rest, parents = a["bone_rest"], a["bone_parents"]
    J = len(parents)
    G = np.empty((J, 4, 4))
    for j in range(J):
        L = rest[j].copy() if parents[j] < 0 else np.linalg.inv(rest[parents[j]]) @ rest[j]
        if parents[j] < 0 and root_offset is not None:
            L[:3, 3] += root_offset
        if rotations is not None:
            w, x, y, z = rotations[j] / np.linalg.norm(rotations[j])
            R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                          [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                          [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
            L[:3, :3] = L[:3, :3] @ R
        G[j] = L if parents[j] < 0 else G[parents[j]] @ L
    S = G @ np.linalg.inv(rest)
    vh = np.c_[a["vertices"], np.ones(len(a["vertices"]))]
    per = np.einsum("vkab,vb->vka", S[a["skin_indices"]], vh)[..., :3]
    return np.einsum("vk,vka->va", a["skin_weights"].astype(np.float64), per), G
