"""PyBullet bodies for model objects: creation, and pose/velocity conversion model ↔ engine.

Conventions:
  * The model's ``position`` / ``quaternion`` (WXYZ) describe the object's own frame (the mesh /
    URDF link origin). PyBullet's base pose and velocity describe the base's *inertial* frame
    (centre of mass, XYZW quaternion). :class:`Body` stores the inertial frame relative to the link
    frame and converts both ways; for Cube and Sphere the two frames coincide and values pass
    through unchanged (bit-exact).
  * Velocities are world-frame m/s and rad/s. The model's ``velocity`` is the velocity of the
    object's origin; the engine's is that of the centre of mass (they differ only for URDF objects
    whose centre of mass is offset from their origin).
  * Cube: box with half extents ``scale`` (model bounds ±1). Sphere: radius ``scale`` (uniform
    scale only). FileBasedObject: a ``.urdf`` loaded with ``globalScaling = scale`` (uniform only).
  * An object is *fixed* (PyBullet mass 0) when ``static`` is True or ``mass`` is 0.
"""

from __future__ import annotations

import pathlib
from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from kubric.core.objects import Cube, FileBasedObject, Sphere
from kubric.core.quaternion import Quaternion

_IDENTITY_POS = (0.0, 0.0, 0.0)
_IDENTITY_ORN = (0.0, 0.0, 0.0, 1.0)  # XYZW


def wxyz_to_xyzw(q) -> tuple[float, float, float, float]:
    w, x, y, z = (float(v) for v in q)
    return x, y, z, w


def xyzw_to_wxyz(q) -> tuple[float, float, float, float]:
    x, y, z, w = (float(v) for v in q)
    return w, x, y, z


@dataclass
class Body:
    """The engine side of one model object (``uid`` is None when the object is not simulated).

    Attributes:
      uid: PyBullet body unique id, or None.
      key: what the body was built from (shape, scale, file, fixed); a change means rebuild.
      links: link indices to configure (-1 = base, then every joint's child link).
      inertial_pos, inertial_orn: the base inertial frame in the object's frame (XYZW).
    """

    uid: int | None = None
    key: tuple | None = None
    links: tuple[int, ...] = (-1,)
    inertial_pos: tuple[float, float, float] = _IDENTITY_POS
    inertial_orn: tuple[float, float, float, float] = _IDENTITY_ORN
    _offset: bool = field(default=False, repr=False)

    def set_inertial(self, pos, orn) -> None:
        """Store the base inertial frame: position (3,) and XYZW orientation in the object's
        frame."""
        self.inertial_pos = tuple(float(v) for v in pos)
        self.inertial_orn = tuple(float(v) for v in orn)
        self._offset = (self.inertial_pos != _IDENTITY_POS
                        or self.inertial_orn != _IDENTITY_ORN)

    # -------------------------------------------------------------- model → engine
    def engine_pose(self, position, quaternion_wxyz):
        """(com position, com orientation XYZW) for a model pose."""
        pos = tuple(float(v) for v in position)
        if not self._offset:
            return pos, wxyz_to_xyzw(quaternion_wxyz)
        rot = Quaternion(quaternion_wxyz).normalised
        com = np.asarray(pos) + rot.rotate(self.inertial_pos)
        orn = rot * Quaternion(xyzw_to_wxyz(self.inertial_orn))
        return tuple(float(v) for v in com), wxyz_to_xyzw(orn)

    def engine_velocity(self, position, quaternion_wxyz, velocity, angular_velocity):
        """(com linear velocity, angular velocity) for the model's origin velocity."""
        lin = tuple(float(v) for v in velocity)
        ang = tuple(float(v) for v in angular_velocity)
        if not self._offset:
            return lin, ang
        r = Quaternion(quaternion_wxyz).normalised.rotate(self.inertial_pos)
        return tuple(float(v) for v in np.asarray(lin) + np.cross(ang, r)), ang

    # -------------------------------------------------------------- engine → model
    def model_state(self, com_pos, com_orn_xyzw, com_vel, ang_vel):
        """(position, quaternion WXYZ, velocity, angular_velocity) of the object's origin."""
        if not self._offset:
            return (tuple(com_pos), xyzw_to_wxyz(com_orn_xyzw), tuple(com_vel), tuple(ang_vel))
        com_rot = Quaternion(xyzw_to_wxyz(com_orn_xyzw))
        rot = com_rot * Quaternion(xyzw_to_wxyz(self.inertial_orn)).inverse
        r = rot.rotate(self.inertial_pos)
        pos = np.asarray(com_pos) - r
        vel = np.asarray(com_vel) - np.cross(ang_vel, r)
        return (tuple(float(v) for v in pos), tuple(float(v) for v in rot.normalised),
                tuple(float(v) for v in vel), tuple(ang_vel))


def is_fixed(obj) -> bool:
    """Whether the engine treats ``obj`` as immovable (static, or mass 0)."""
    return bool(obj.static) or float(obj.mass) == 0.0


def _positive_scale(obj) -> tuple[float, float, float]:
    scale = tuple(float(v) for v in obj.scale)
    if min(scale) <= 0:
        raise ValueError(f"{obj.uid}: scale must be positive on every axis for simulation, "
                         f"got {list(scale)}")
    return scale


def _uniform_scale(obj, what: str) -> float:
    scale = _positive_scale(obj)
    if not (scale[0] == scale[1] == scale[2]):
        raise ValueError(f"{obj.uid}: PyBullet supports only uniform scale for {what}, got "
                         f"scale={list(scale)} (use equal values on all three axes)")
    return scale[0]


def shape_key(obj) -> tuple | None:
    """What the engine body of ``obj`` is built from; None when it has no engine body.

    Raises ValueError naming the object for scales or files the engine cannot represent.
    """
    fixed = is_fixed(obj)
    if isinstance(obj, Cube):
        return ("box", _positive_scale(obj), fixed)
    if isinstance(obj, Sphere):
        return ("sphere", _uniform_scale(obj, "a Sphere"), fixed)
    if isinstance(obj, FileBasedObject):
        if obj.simulation_filename is None:
            return None
        scale = _uniform_scale(obj, "a URDF FileBasedObject")
        return ("urdf", _urdf_path(obj), scale, fixed)
    raise TypeError(f"{obj.uid}: the PyBullet view cannot simulate a {type(obj).__name__}; "
                    "supported: Cube, Sphere, FileBasedObject")


def has_joints(urdf_path: str) -> bool:
    """Whether a URDF file declares any ``<joint>`` (a multi-link, articulated model)."""
    with open(urdf_path, errors="replace") as fh:
        return "<joint" in fh.read()


def _urdf_path(obj) -> str:
    path = pathlib.Path(obj.simulation_filename).expanduser()
    if path.suffix.lower() != ".urdf":
        raise ValueError(f"{obj.uid}: simulation_filename {str(path)!r} has format "
                         f"{path.suffix!r}; the PyBullet view loads only '.urdf' files")
    if not path.is_file():
        raise FileNotFoundError(f"{obj.uid}: simulation_filename {str(path)!r} does not exist")
    return str(path.resolve())


class ShapeCache:
    """Collision shapes of one PyBullet client, shared by all bodies of the same geometry."""

    def __init__(self, client: int):
        self.client = client
        self._shapes: dict[tuple, int] = {}

    def get(self, kind: str, size) -> int:
        key = (kind, size)
        if key not in self._shapes:
            if kind == "box":
                idx = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(size),
                                              physicsClientId=self.client)
            else:
                idx = pb.createCollisionShape(pb.GEOM_SPHERE, radius=size,
                                              physicsClientId=self.client)
            self._shapes[key] = idx
        return self._shapes[key]


def create_body(obj, key: tuple, shapes: ShapeCache) -> Body:
    """Create the engine body of ``obj`` from its ``shape_key`` (pose and dynamics set later)."""
    client = shapes.client
    body = Body(key=key)
    if key[0] in ("box", "sphere"):
        mass = 0.0 if key[-1] else float(obj.mass)
        # Maximal coordinates (a plain rigid body) plus contactProcessingThreshold=0 (set by the
        # view) avoid PyBullet's "sticky walls" (bullet3 issue 3094), as upstream Kubric does.
        body.uid = pb.createMultiBody(baseMass=mass,
                                      baseCollisionShapeIndex=shapes.get(key[0], key[1]),
                                      baseVisualShapeIndex=-1, useMaximalCoordinates=True,
                                      physicsClientId=client)
    else:
        _, path, scale, fixed = key
        articulated = has_joints(path)
        try:
            # a multi-link URDF keeps its joints only in reduced coordinates (PyBullet merges
            # the links of a maximal-coordinate body into its base)
            body.uid = pb.loadURDF(path, useFixedBase=fixed, globalScaling=scale,
                                   useMaximalCoordinates=not articulated,
                                   physicsClientId=client)
        except pb.error as err:
            raise ValueError(f"{obj.uid}: PyBullet could not load simulation_filename "
                             f"{path!r} ({err})") from None
        joints = pb.getNumJoints(body.uid, physicsClientId=client)
        body.links = (-1, *range(joints))
        for joint in range(joints):  # passive joints: PyBullet's default motors hold them
            pb.setJointMotorControl2(body.uid, joint, pb.VELOCITY_CONTROL, force=0.0,
                                     physicsClientId=client)
        if not fixed:
            _set_total_mass(body, float(obj.mass), client)
    # The body was created at the origin without rotation, so its base (= inertial) pose now is
    # the inertial frame in the object's frame. (getDynamicsInfo does not report it for
    # maximal-coordinate bodies.)
    pos, orn = pb.getBasePositionAndOrientation(body.uid, physicsClientId=client)
    body.set_inertial(pos, orn)
    return body


def _set_total_mass(body: Body, mass: float, client: int) -> None:
    """Scale the link masses so they sum to ``mass`` (kg); all on the base if they sum to 0."""
    masses = [pb.getDynamicsInfo(body.uid, link, physicsClientId=client)[0]
              for link in body.links]
    total = float(sum(masses))
    if total <= 0:
        pb.changeDynamics(body.uid, -1, mass=mass, physicsClientId=client)
        return
    for link, m in zip(body.links, masses, strict=True):
        if m > 0:
            pb.changeDynamics(body.uid, link, mass=m * mass / total, physicsClientId=client)


def set_mass(body: Body, obj, client: int) -> None:
    """Apply a changed (non-zero, non-static) model mass to an existing dynamic body."""
    if body.key[0] == "urdf":
        _set_total_mass(body, float(obj.mass), client)
    else:
        pb.changeDynamics(body.uid, -1, mass=float(obj.mass), physicsClientId=client)
