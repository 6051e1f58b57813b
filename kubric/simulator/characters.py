"""Characters in PyBullet: kinematic per-bone convex colliders that follow the animation.

A :class:`~kubric.core.characters.Character` becomes one fixed (mass 0) PyBullet body per bone:
the convex hull of the rest vertices whose largest skin weight is on that bone, expressed in the
bone's rest frame (bones that dominate fewer than 4 vertices get no collider). Before every physics
step, each collider is moved to its bone's pose at that step's time (the model's keyframes at the
fractional frame: :meth:`Character.bone_transforms_at`, every step of a run in one batch), so
thrown objects are pushed away by the moving limbs and bounce off them; contacts with any
collider are reported as contacts with the character (``events.json``). The colliders never
receive forces and the simulator never writes keyframes of a character: its motion comes from its
own keys only.

Limits: a convex hull per bone over-covers concave parts (the hull of a hand is a box-like blob);
the skin between two bones is covered by both hulls at rest and stretches between them when a
joint bends; the scale must be uniform.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from kubric.core.skinning import matrices_to_quaternions
from kubric.errors import InputError

MIN_HULL_VERTICES = 4


@dataclass
class CharacterBodies:
    """The engine side of one character: ``bones[i]`` is driven by ``uids[i]``."""

    bones: list[int] = field(default_factory=list)
    uids: list[int] = field(default_factory=list)
    scale: float = 1.0


def uniform_scale(character) -> float:
    s = np.asarray(character.scale, np.float64)
    if np.ptp(s) > 1e-6 * np.abs(s).max():
        raise InputError(f"{character.uid}: PyBullet simulates characters with a uniform scale "
                         f"only, got scale {s.tolist()}")
    return float(s[0])


def _hull_vertices(points: np.ndarray) -> np.ndarray:
    """Indices of the points on the convex hull (all of them when they span no volume)."""
    from scipy.spatial import ConvexHull, QhullError
    try:
        return ConvexHull(points).vertices
    except (QhullError, ValueError):
        return np.arange(len(points))


def build_character_bodies(character, client: int) -> CharacterBodies:
    """One fixed convex-hull body per bone (module doc), posed at the current model pose."""
    scale = uniform_scale(character)
    main = np.argmax(character.skin_weights, axis=1)
    owner = character.skin_indices[np.arange(len(main)), main]
    used = np.zeros(len(character.vertices), bool)
    used[character.rendered_vertices] = True
    out = CharacterBodies(scale=scale)
    inv_rest = np.linalg.inv(character.bone_rest)
    for j in range(character.num_bones):
        pts = character.vertices[used & (owner == j)]
        if len(pts) < MIN_HULL_VERTICES:
            continue
        local = (pts @ inv_rest[j, :3, :3].T + inv_rest[j, :3, 3]) * scale
        local = local[_hull_vertices(local)]  # Bullet's hull tests every point it is given
        shape = pb.createCollisionShape(pb.GEOM_MESH, vertices=local.tolist(),
                                        physicsClientId=client)
        uid = pb.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape,
                                 physicsClientId=client)
        out.bones.append(j)
        out.uids.append(uid)
    set_dynamics(character, out, client)
    pose_character(character, out, client, None)
    return out


def set_dynamics(character, bodies: CharacterBodies, client: int) -> None:
    """The character's friction and restitution on every collider."""
    for uid in bodies.uids:
        pb.changeDynamics(uid, -1, lateralFriction=float(character.friction),
                          restitution=float(character.restitution),
                          contactProcessingThreshold=0.0, physicsClientId=client)


def pose_character(character, bodies: CharacterBodies, client: int, frame) -> None:
    """Move every collider to its bone's world pose at ``frame`` (None: the current values)."""
    if bodies.uids:
        place(bodies, client, character.bone_transforms(frame)[bodies.bones])


def schedule(character, bodies: CharacterBodies, frames) -> np.ndarray:
    """(N, B, 4, 4) the colliders' poses at N (fractional) ``frames``, computed in one batch;
    :func:`place` applies one of them."""
    if not bodies.uids:
        return np.zeros((len(frames), 0, 4, 4))
    return character.bone_transforms_at(frames)[:, bodies.bones]


def place(bodies: CharacterBodies, client: int, transforms: np.ndarray) -> None:
    """Move the colliders to ``transforms`` (B, 4, 4) (bone → world, scale included)."""
    quats = matrices_to_quaternions(transforms[:, :3, :3] / bodies.scale)[:, [1, 2, 3, 0]]
    for uid, m, q in zip(bodies.uids, transforms, quats, strict=True):
        pb.resetBasePositionAndOrientation(uid, m[:3, 3].tolist(), q.tolist(),
                                           physicsClientId=client)


def remove_character_bodies(bodies: CharacterBodies, client: int) -> None:
    for uid in bodies.uids:
        pb.removeBody(uid, physicsClientId=client)
    bodies.bones, bodies.uids = [], []
