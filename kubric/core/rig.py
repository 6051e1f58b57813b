"""Camera rigs: N cameras mounted at fixed poses on a rig that moves. Pure numpy.

A :class:`CameraRig` is a **reference camera** (any keyframed or static
:class:`~kubric.core.cameras.PerspectiveCamera`; its frame is the rig's frame) plus named
**mounts**: the (4, 4) camera → rig transform of each camera, fixed for the whole scene. The
first mount is the reference camera itself (the identity); :meth:`CameraRig.build` adds one
more camera to the scene per further mount, each keyed at every frame the scene renders or its
flow reads (``frame_start − 1 … frame_end + 1``) and at every key of the reference camera, with

    matrix_world(camera k, frame t) = matrix_world(reference, t) @ mount_k.

Frames and units: the rig frame is the reference camera's frame, Blender's camera axes (x right,
y up, looking down −z; ``docs/conventions.md``), metres. In OpenCV's camera axes (x right, y down,
looking down +z) a mount is ``CAMERA_TO_OPENCV @ mount @ CAMERA_TO_OPENCV``; the per-frame
world → OpenCV-camera extrinsics of every camera are in its metadata
(:func:`kubric.annotations.metadata.get_camera_info`). The cameras share the reference's
intrinsics and lens (focal length, sensor width, shift, lens model, and the thin lens of depth
of field: ``use_dof``, f-number, focus distance along each camera's own axis), so they differ
only by pose;
one simulation serves all of them (the cameras are background assets, never simulated).

Presets:

* :func:`stereo`: ``left`` (the reference) and ``right``, ``baseline`` metres along the camera's
  +x: a **rectified pair** (same orientation and intrinsics, horizontal baseline). A surface
  point at z-depth Z (metres along the view axis) seen at column x_left in the left image is at
  x_right = x_left − d in the right one, with the **disparity** d = fx · B / Z pixels (fx the
  pixel focal length, :attr:`~kubric.core.cameras.Camera.intrinsics_pixels`).
* :func:`ring`: ``num`` cameras on a horizontal circle around the point the reference camera
  looks at (``distance`` metres in front of it), each turned to keep looking at it: camera k is
  the reference rotated by 2πk/num about the world-vertical axis through that point (the
  vertical of the rig's pose at the first frame, held fixed in the rig frame).

* :func:`random_rig`: ``num`` cameras ``cam0`` (the reference) … drawn at random around the same
  point as the ring's (the reference's pose at the first frame): camera k at distance
  ``distance · U[RANDOM_DISTANCE]`` from it, in a direction uniform on the band of the upper
  hemisphere between the elevations :data:`RANDOM_ELEVATION` (z uniform: the sphere's own
  uniform measure), looking at it with its vertical as close to the world's as possible; its
  mount, fixed from then on, is its pose in the rig frame at that first frame.

Camera names: lower-case letters and digits, starting with a letter (``left``, ``right``,
``cam1``...); they prefix the per-camera layer and file names of a scene directory.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

import numpy as np

from kubric.core.cameras import PerspectiveCamera
from kubric.core.quaternion import Quaternion, look_at_quaternion

#: random_rig: a camera's distance to the pivot, as factors of the reference camera's
RANDOM_DISTANCE = (0.8, 1.2)
#: random_rig: a camera's elevation above the pivot's horizontal plane, degrees
RANDOM_ELEVATION = (10.0, 70.0)
#: the intrinsics every camera of a rig copies from the reference camera
SHARED_INTRINSICS = ("focal_length", "sensor_width", "shift_x", "shift_y", "lens",
                     "use_dof", "aperture_fstop", "focus_distance")
_NAME = re.compile(r"[a-z][a-z0-9]*\Z")


class CameraRig:
    """Cameras with fixed mounts on a moving rig (module doc).

    Args:
      reference: the rig's camera (mount 0, the identity): its pose over time is the rig's.
      mounts: ``{name: (4, 4) camera → rig transform}`` of the other cameras, in order (rotation
        orthonormal with determinant +1, metres).
      reference_name: the reference camera's name in the rig (``left`` for stereo).
      kind: the preset's name, recorded in the metadata (``stereo``, ``ring``, ``custom``).
      baseline: metres between the two cameras of a stereo rig (None for other rigs).
    """

    def __init__(self, reference: PerspectiveCamera, mounts: Mapping[str, np.ndarray],
                 reference_name: str = "cam0", kind: str = "custom",
                 baseline: float | None = None):
        if not isinstance(reference, PerspectiveCamera):
            raise TypeError(f"CameraRig: the reference camera must be a PerspectiveCamera, got "
                            f"{type(reference).__name__}")
        names = [reference_name, *mounts]
        bad = [n for n in names if not isinstance(n, str) or not _NAME.match(n)]
        if bad or len(set(names)) != len(names):
            raise ValueError(f"CameraRig: camera names {names} must be distinct lower-case "
                             "letters and digits starting with a letter")
        self.reference = reference
        self.reference_name = reference_name
        self.kind = kind
        self.baseline = baseline
        self.mounts = {reference_name: np.eye(4)}
        for name, m in mounts.items():
            self.mounts[name] = _check_mount(name, m)
        self.cameras: dict[str, PerspectiveCamera] = {reference_name: reference}

    @property
    def names(self) -> list[str]:
        """Camera names, the reference first."""
        return list(self.mounts)

    def build(self, scene) -> dict[str, PerspectiveCamera]:
        """Add the mounted cameras to ``scene`` (the reference stays the active camera) and
        return ``{name: camera}``, the reference first. Call it once the reference camera's
        motion is final (after the simulation is fine: cameras are never simulated)."""
        ref = self.reference
        frames = set(range(scene.frame_start - 1, scene.frame_end + 2))
        for prop in ("position", "quaternion"):
            frames |= set(ref.keyframes.get(prop, {}))
        keyed = any(ref.keyframes.get(p) for p in ("position", "quaternion"))
        active = scene.camera
        for name, mount in list(self.mounts.items())[1:]:
            cam = PerspectiveCamera(name=name, **{k: getattr(ref, k) for k in SHARED_INTRINSICS})
            for frame in sorted(frames) if keyed else [None]:
                self._place(cam, self.pose(ref, mount, frame))
                if frame is not None:
                    cam.keyframe_insert("position", frame)
                    cam.keyframe_insert("quaternion", frame)
            scene.add(cam)
            self.cameras[name] = cam
        scene.camera = active
        return dict(self.cameras)

    @staticmethod
    def pose(reference, mount: np.ndarray, frame: float | None) -> np.ndarray:
        """(4, 4) camera → world of the camera on ``mount`` at ``frame``."""
        with reference.at_frame(frame):
            return reference.matrix_world @ mount

    @staticmethod
    def _place(cam, matrix: np.ndarray) -> None:
        cam.position = matrix[:3, 3]
        cam.quaternion = np.asarray(Quaternion(matrix=matrix[:3, :3]).normalised)

    def metadata(self) -> dict:
        """The rig's description for ``metadata.json``: kind, camera names, baseline (m) and each
        mount (camera → rig, Blender camera axes, metres)."""
        return {"kind": self.kind, "cameras": self.names,
                "baseline": None if self.baseline is None else float(self.baseline),
                "mounts": {k: v for k, v in self.mounts.items()},
                "conventions": "mounts: camera -> rig (the reference camera's frame), Blender "
                               "camera axes (x right, y up, looking down -z), metres; "
                               "matrix_world(camera) = matrix_world(reference) @ mount"}


def _check_mount(name: str, m) -> np.ndarray:
    m = np.asarray(m, np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"CameraRig: mount {name!r} must be a finite (4, 4) matrix, got shape "
                         f"{m.shape}")
    r = m[:3, :3]
    if not (np.allclose(r @ r.T, np.eye(3), atol=1e-9) and np.linalg.det(r) > 0
            and np.allclose(m[3], (0, 0, 0, 1))):
        raise ValueError(f"CameraRig: mount {name!r} must be a rigid transform (rotation with "
                         "determinant +1, last row 0 0 0 1)")
    return m


def translation(x: float, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """(4, 4) mount translated by (x, y, z) metres in the rig frame."""
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def stereo(reference: PerspectiveCamera, baseline: float) -> CameraRig:
    """A rectified stereo pair: ``left`` = ``reference``, ``right`` ``baseline`` metres along
    its +x (module doc)."""
    if not np.isfinite(baseline) or baseline <= 0:
        raise ValueError(f"stereo: baseline must be a positive number of metres, got {baseline!r}")
    return CameraRig(reference, {"right": translation(float(baseline))}, "left", "stereo",
                     float(baseline))


def ring(reference: PerspectiveCamera, num: int, distance: float, frame: float | None = None
         ) -> CameraRig:
    """``num`` cameras ``cam0`` (the reference) … on a circle about the vertical through the
    point ``distance`` metres in front of the reference (its pose at ``frame``; module doc)."""
    if int(num) != num or num < 2:
        raise ValueError(f"ring: num must be an integer ≥ 2, got {num!r}")
    if not np.isfinite(distance) or distance <= 0:
        raise ValueError(f"ring: distance must be a positive number of metres, got {distance!r}")
    with reference.at_frame(frame):
        world_up = reference.matrix_world[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    pivot = np.array([0.0, 0.0, -float(distance)])
    mounts = {}
    for k in range(1, int(num)):
        rot = Quaternion(axis=world_up, angle=2 * np.pi * k / num).rotation_matrix
        m = np.eye(4)
        m[:3, :3] = rot
        m[:3, 3] = pivot - rot @ pivot
        mounts[f"cam{k}"] = m
    return CameraRig(reference, mounts, "cam0", "ring")


def random_rig(reference: PerspectiveCamera, num: int, distance: float, rng,
               frame: float | None = None) -> CameraRig:
    """``num`` cameras ``cam0`` (the reference) … drawn with ``rng`` (a
    ``numpy.random.RandomState``) around the point ``distance`` metres in front of the
    reference (its pose at ``frame``; module doc)."""
    if int(num) != num or num < 2:
        raise ValueError(f"random_rig: num must be an integer ≥ 2, got {num!r}")
    if not np.isfinite(distance) or distance <= 0:
        raise ValueError(f"random_rig: distance must be a positive number of metres, got "
                         f"{distance!r}")
    with reference.at_frame(frame):
        to_world = reference.matrix_world
    pivot = to_world[:3, :3] @ np.array([0.0, 0.0, -float(distance)]) + to_world[:3, 3]
    low, high = np.sin(np.radians(RANDOM_ELEVATION))
    mounts = {}
    for k in range(1, int(num)):
        radius = float(distance) * rng.uniform(*RANDOM_DISTANCE)
        z, azimuth = rng.uniform(low, high), rng.uniform(0.0, 2 * np.pi)
        across = np.sqrt(1.0 - z * z)
        position = pivot + radius * np.array([across * np.cos(azimuth),
                                              across * np.sin(azimuth), z])
        pose = np.eye(4)
        pose[:3, :3] = look_at_quaternion(position, pivot).rotation_matrix
        pose[:3, 3] = position
        mounts[f"cam{k}"] = np.linalg.inv(to_world) @ pose
    return CameraRig(reference, mounts, "cam0", "random")


__all__ = ["CameraRig", "RANDOM_DISTANCE", "RANDOM_ELEVATION", "SHARED_INTRINSICS",
           "random_rig", "ring", "stereo", "translation"]
