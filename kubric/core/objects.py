"""Objects with a pose (:class:`Object3D`) and with geometry and physics (:class:`PhysicalObject`).

Conventions: world is right-handed, z up, metres. ``position`` (3,) metres; ``quaternion`` (4,) WXYZ
rotating local into world coordinates; ``matrix_world`` (4, 4) maps local to world coordinates.
``bounds`` is the local axis-aligned box (before scale and rotation), shape (2, 3).
"""

from __future__ import annotations

import itertools

import numpy as np

from kubric.core import traits as kt
from kubric.core.assets import Asset
from kubric.core.materials import Material, UndefinedMaterial
from kubric.core.quaternion import Quaternion, look_at_quaternion

_AXIS_NAMES = ["X", "Y", "Z", "-X", "-Y", "-Z"]


def look_at_quat(position, target, up="Y", front="-Z") -> tuple[float, float, float, float]:
    """The WXYZ orientation that points the local ``front`` axis from ``position`` at ``target``,
    local ``up`` as close to world +Z as possible, as a plain tuple (upstream Kubric's function of
    this module). ``up`` / ``front`` are axis names ("X", "-Z", ...) or 3-vectors. See
    :func:`kubric.core.quaternion.look_at_quaternion`."""
    return tuple(float(c) for c in look_at_quaternion(position, target, up, front))


class Object3D(Asset):
    """Anything with a position and an orientation.

    Construct with at most one of ``quaternion=``, ``euler=`` (extrinsic XYZ radians) and
    ``look_at=`` (a point: turns ``front`` towards it, ``up`` as close to world +Z as possible).
    """

    position = kt.Vector3D((0.0, 0.0, 0.0), "(x, y, z) in metres, world frame")
    quaternion = kt.QuaternionProperty((1.0, 0.0, 0.0, 0.0), "WXYZ, local → world rotation")
    up = kt.Property("Y", kt.as_choice(_AXIS_NAMES), "local axis kept closest to world +Z by look_at")
    front = kt.Property("-Z", kt.as_choice(_AXIS_NAMES), "local axis pointed at the target by look_at")

    def __init__(self, *, look_at=None, euler=None, **kwargs):
        given = [k for k, v in (("look_at", look_at), ("euler", euler),
                                ("quaternion", kwargs.get("quaternion"))) if v is not None]
        if len(given) > 1:
            raise TypeError(f"{type(self).__name__}: give at most one of look_at, euler and "
                            f"quaternion, got {given}")
        super().__init__(**kwargs)
        if look_at is not None:
            self._set_property("quaternion", self._look_at_value(look_at), notify=False)
        elif euler is not None:
            self._set_property("quaternion", np.asarray(Quaternion.from_euler(euler)),
                               notify=False)

    def _look_at_value(self, target) -> np.ndarray:
        target = kt.as_vector(3)(target, self, "look_at")
        return np.asarray(look_at_quaternion(self.position, target, self.up, self.front))

    def look_at(self, target) -> None:
        """Turn the object so that its ``front`` axis points at ``target`` (notifies views)."""
        self.quaternion = self._look_at_value(target)

    @property
    def rotation_matrix(self) -> np.ndarray:
        """(3, 3) float64 rotation of ``quaternion`` (local → world)."""
        return Quaternion(self.quaternion).rotation_matrix

    @property
    def matrix_world(self) -> np.ndarray:
        """(4, 4) float64 transform local → world (rotation and translation; no scale)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation_matrix
        m[:3, 3] = self.position
        return m


class PhysicalObject(Object3D):
    """An object with geometry that takes part in simulation and rendering.

    Attributes:
      scale: (3,) per-axis scale; a scalar broadcasts.
      velocity: (3,) m/s; angular_velocity: (3,) rad/s, world frame.
      static: fixed in place during simulation.
      mass: kg, ≥ 0 (0 is treated as static by simulators). friction, restitution: in [0, 1].
      bounds: (2, 3) local axis-aligned box, lower ≤ upper.
      material: a :class:`~kubric.core.materials.Material`; assigning one adds it to the scenes.
      segmentation_id: label override for segmentation maps (None = by instance).
    """

    scale = kt.Scale((1.0, 1.0, 1.0), "per-axis scale (scalar broadcasts)")
    velocity = kt.Vector3D((0.0, 0.0, 0.0), "linear velocity (m/s), world frame")
    angular_velocity = kt.Vector3D((0.0, 0.0, 0.0), "angular velocity (rad/s), world frame")
    static = kt.Property(False, kt.as_bool(), "fixed during simulation")
    mass = kt.Float(1.0, low=0.0, doc="mass in kg")
    friction = kt.Float(0.5, 0.0, 1.0, "friction coefficient (default 0.5, as upstream)")
    restitution = kt.Float(0.5, 0.0, 1.0, "restitution (bounciness)")
    bounds = kt.Property(((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)), kt.as_bounds(),
                         "local axis-aligned bounds ((x0, y0, z0), (x1, y1, z1)), unscaled")
    material = kt.Property(lambda: _undefined_material(), kt.as_instance(lambda: _material_cls()),
                           "surface material")
    segmentation_id = kt.Property(None, kt.as_int(low=0, allow_none=True),
                                  "label override in segmentation maps")

    def _on_property_set(self, name, value):
        if name == "material":
            for scene in self.scenes:
                scene.add(value)
        super()._on_property_set(name, value)

    @property
    def bbox_3d(self) -> np.ndarray:
        """(8, 3) world-space corners of the scaled, rotated, translated local bounds.

        Corner order: itertools.product over x ∈ {min, max}, y ∈ {min, max}, z ∈ {min, max}.
        """
        b = np.asarray(self.bounds, dtype=np.float64) * np.asarray(self.scale, dtype=np.float64)
        corners = np.array(list(itertools.product(b[:, 0], b[:, 1], b[:, 2])))
        return corners @ self.rotation_matrix.T + np.asarray(self.position, dtype=np.float64)

    @property
    def aabbox(self) -> np.ndarray:
        """(2, 3) world-space axis-aligned box [[xmin, ymin, zmin], [xmax, ymax, zmax]]."""
        corners = self.bbox_3d
        return np.stack([corners.min(axis=0), corners.max(axis=0)])


def _material_cls():
    return Material


def _undefined_material():
    return UndefinedMaterial()


class Cube(PhysicalObject):
    """Axis-aligned cube with bounds ±1 (edge length 2 before scale)."""

    property_defaults = {"bounds": ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))}


class Sphere(PhysicalObject):
    """Sphere of radius 1 (bounds ±1 before scale)."""

    property_defaults = {"bounds": ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))}


class FileBasedObject(PhysicalObject):
    """An object whose geometry comes from files (usually created by an AssetSource).

    Attributes:
      asset_id: the id in its asset source.
      render_filename: mesh for rendering (OBJ, GLB/GLTF, PLY, STL, FBX or .blend).
      simulation_filename: URDF for simulation.
      render_import_kwargs: extra keyword arguments for the renderer's importer.
    """

    asset_id = kt.Property("", kt.as_str(), "id in the asset source")
    render_filename = kt.Property(None, kt.as_str(allow_none=True), "mesh file for rendering")
    simulation_filename = kt.Property(None, kt.as_str(allow_none=True), "URDF file for simulation")
    render_import_kwargs = kt.Property(dict, kt.as_dict(), "extra importer arguments")
