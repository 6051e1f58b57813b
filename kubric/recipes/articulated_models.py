"""Articulated (multi-link URDF) models from ``pybullet_data`` for the recipes.

:data:`MODELS` names the multi-link URDFs that ship with PyBullet and work with
:func:`kubric.assets.articulated.add_articulated` (every link's visuals are meshes or primitives
it reads; tested by tests/test_vbr.py and tests/test_movi_articulated.py). :func:`add_model` adds
one, scaled so that its rest pose's largest extent is a given size, with one colour on every
part. Every part is an instance of its own (its own segmentation label): the base keeps the
URDF's root link and has ``articulated_links`` (the other links' names) and ``urdf`` (the model
name) in its metadata; every other link has ``articulated_link`` (its URDF link name) and
``articulated_base`` (the base object's name). Joints are passive (motors off): the links move
only as the body's motion and contacts drive them.
"""

from __future__ import annotations

import os

import numpy as np

from kubric.assets.articulated import add_articulated, link_visuals
from kubric.core.quaternion import Quaternion

#: model name → URDF path inside pybullet_data
MODELS = {
    "r2d2": "r2d2.urdf",
    "kuka_iiwa": "kuka_iiwa/model.urdf",
    "franka_panda": "franka_panda/panda.urdf",
    "laikago": "laikago/laikago.urdf",
    "a1": "a1/a1.urdf",
}


def model_path(name: str) -> str:
    """The URDF file of model ``name`` (one of :data:`MODELS`)."""
    import pybullet_data

    return os.path.join(pybullet_data.getDataPath(), MODELS[name])


def model_list(value) -> tuple[str, ...]:
    """Option converter: ``"r2d2,kuka_iiwa"`` or a sequence of names → a tuple of model names."""
    items = value.split(",") if isinstance(value, str) else list(value)
    names = tuple(str(v).strip() for v in items if str(v).strip())
    unknown = [n for n in names if n not in MODELS]
    if not names or unknown:
        raise ValueError(f"expected names of {', '.join(MODELS)} separated by commas")
    return names


model_list.allowed = f"model names separated by commas, from {', '.join(MODELS)}"


def rest_pose(urdf: str) -> tuple[np.ndarray, float]:
    """``(bounds, mass)``: the (2, 3) box of every link's visuals with all joints at 0, in the
    root link's frame (metres at scale 1), and the model's total mass (kg)."""
    import pybullet as pb

    meshes = link_visuals(urdf)
    client = pb.connect(pb.DIRECT)
    try:
        uid = pb.loadURDF(urdf, useFixedBase=True, physicsClientId=client)
        frames = {}
        for j in range(pb.getNumJoints(uid, physicsClientId=client)):
            name = pb.getJointInfo(uid, j, physicsClientId=client)[12].decode()
            state = pb.getLinkState(uid, j, computeForwardKinematics=1, physicsClientId=client)
            frames[name] = (np.asarray(state[4]), np.asarray(state[5]))
        mass = sum(pb.getDynamicsInfo(uid, k, physicsClientId=client)[0]
                   for k in range(-1, pb.getNumJoints(uid, physicsClientId=client)))
    finally:
        pb.disconnect(client)
    points = []
    for name, mesh in meshes.items():
        pos, xyzw = frames.get(name, (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])))
        rot = Quaternion((xyzw[3], xyzw[0], xyzw[1], xyzw[2])).rotation_matrix
        points.append(np.asarray(mesh.vertices) @ rot.T + pos)
    allp = np.concatenate(points)
    return np.stack([allp.min(axis=0), allp.max(axis=0)]), float(mass)


def add_model(scene, simulator, name: str, size: float, color, mesh_dir, object_name: str,
              urdf: str | None = None, **base_kwargs):
    """Add model ``name`` (or the URDF file ``urdf``) to ``scene``: scale so that its rest pose's
    largest extent is ``size`` m, mass = the URDF's total mass × scale³, every part with a
    random-hue-like ``color`` (a :class:`~kubric.Color`). ``base_kwargs`` (position, quaternion,
    ...) go to the base. Returns ``(base, {link name: link object}, rest bounds (2, 3) in metres
    in the base frame)``."""
    import kubric as kb

    urdf = urdf or model_path(name)
    bounds, mass = rest_pose(urdf)
    scale = size / max(float(np.max(bounds[1] - bounds[0])), 1e-9)
    base, links = add_articulated(scene, simulator, urdf, mesh_dir, name=object_name,
                                  scale=scale, mass=max(mass, 1e-3) * scale ** 3, **base_kwargs)
    material = kb.PrincipledBSDFMaterial(color=color, roughness=0.5)
    for part in (base, *links.values()):
        part.material = material
        part.metadata = {**part.metadata, "color": np.asarray(color.rgb, np.float32)}
    base.metadata = {**base.metadata, "urdf": name, "articulated_links": sorted(links)}
    return base, links, bounds * scale
