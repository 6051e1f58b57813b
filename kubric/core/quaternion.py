"""Unit quaternions in **WXYZ** order (scalar first), the convention used everywhere in Kubric.

A rotation quaternion ``q = (w, x, y, z)`` rotates a vector ``v`` as ``q * (0, v) * q⁻¹``; composing
``q1 * q2`` applies ``q2`` first. Euler angles are *extrinsic* XYZ (rotate about world X, then world
Y, then world Z), i.e. ``q = qz * qy * qx``. Pure numpy, float64 internally.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

_AXES = {
    "X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0),
    "-X": (-1.0, 0.0, 0.0), "-Y": (0.0, -1.0, 0.0), "-Z": (0.0, 0.0, -1.0),
}


def axis_vector(direction: str | Iterable[float]) -> np.ndarray:
    """A unit 3-vector from an axis name ("X", "-Z", ...) or any non-zero 3-vector."""
    if isinstance(direction, str):
        key = direction.upper()
        if key not in _AXES:
            raise ValueError(f"unknown axis {direction!r}; allowed: {sorted(_AXES)}")
        return np.array(_AXES[key])
    v = np.asarray(direction, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise ValueError(f"expected a finite non-zero 3-vector, got {direction!r}")
    return v / np.linalg.norm(v)


class Quaternion:
    """An immutable WXYZ quaternion.

    Construct from four numbers ``Quaternion(w, x, y, z)``, a sequence ``Quaternion((w, x, y, z))``,
    ``Quaternion(axis=(x, y, z), angle=radians)`` (``radians=`` / ``degrees=`` also accepted, as in
    pyquaternion) or ``Quaternion(matrix=R)`` (3×3 or 4×4 rotation).
    Iterating yields ``w, x, y, z``; ``np.asarray(q)`` gives the float64 array of the four elements.
    """

    __slots__ = ("_q",)

    def __init__(self, *args, axis=None, angle=None, matrix=None, radians=None, degrees=None):
        given = [v for v in (angle, radians, degrees) if v is not None]
        if len(given) > 1:
            raise TypeError("give the rotation angle once: angle=, radians= or degrees=")
        if degrees is not None:
            angle = np.deg2rad(float(degrees))
        elif radians is not None:
            angle = radians
        if axis is not None or angle is not None:
            if args or matrix is not None or axis is None or angle is None:
                raise TypeError("Quaternion(axis=..., angle=...) takes both and nothing else")
            a = axis_vector(axis)
            half = 0.5 * float(angle)
            q = np.concatenate([[np.cos(half)], np.sin(half) * a])
        elif matrix is not None:
            if args:
                raise TypeError("Quaternion(matrix=...) takes no positional arguments")
            q = _matrix_to_quaternion(np.asarray(matrix, dtype=np.float64))
        elif len(args) == 4:
            q = np.array(args, dtype=np.float64)
        elif len(args) == 1:
            q = np.array(args[0], dtype=np.float64).reshape(-1)
        elif not args:
            q = np.array([1.0, 0.0, 0.0, 0.0])
        else:
            raise TypeError(f"Quaternion takes 0, 1 or 4 positional arguments, got {len(args)}")
        if q.shape != (4,) or not np.all(np.isfinite(q)):
            raise ValueError(f"a quaternion needs 4 finite numbers (w, x, y, z), got {args!r}")
        self._q = q
        self._q.setflags(write=False)

    # --- basic protocol
    @property
    def elements(self) -> np.ndarray:
        """The (4,) float64 array (w, x, y, z), read-only."""
        return self._q

    w = property(lambda self: float(self._q[0]))
    x = property(lambda self: float(self._q[1]))
    y = property(lambda self: float(self._q[2]))
    z = property(lambda self: float(self._q[3]))

    def __iter__(self) -> Iterator[float]:
        return iter(float(v) for v in self._q)

    def __len__(self) -> int:
        return 4

    def __getitem__(self, i):
        return self._q[i]

    def __array__(self, dtype=None, copy=None):
        return np.array(self._q, dtype=dtype)

    def __repr__(self) -> str:
        return "Quaternion(w={:.6g}, x={:.6g}, y={:.6g}, z={:.6g})".format(*self._q)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Quaternion):
            return NotImplemented
        return bool(np.array_equal(self._q, other._q))

    def __hash__(self) -> int:
        return hash(tuple(self._q))

    # --- algebra
    def __mul__(self, other: Quaternion) -> Quaternion:
        if not isinstance(other, Quaternion):
            return NotImplemented
        w1, x1, y1, z1 = self._q
        w2, x2, y2, z2 = other._q
        return Quaternion(
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        )

    @property
    def norm(self) -> float:
        return float(np.linalg.norm(self._q))

    @property
    def conjugate(self) -> Quaternion:
        return Quaternion(self._q * np.array([1.0, -1.0, -1.0, -1.0]))

    @property
    def inverse(self) -> Quaternion:
        return Quaternion(self.conjugate._q / self.norm**2)

    @property
    def normalised(self) -> Quaternion:
        n = self.norm
        if n == 0:
            raise ValueError("cannot normalise the zero quaternion")
        return Quaternion(self._q / n)

    normalized = normalised

    @property
    def rotation_matrix(self) -> np.ndarray:
        """The 3×3 rotation matrix (float64) of the normalised quaternion."""
        w, x, y, z = self.normalised._q
        return np.array([
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ])

    def rotate(self, vector) -> np.ndarray:
        """Rotate a (3,) vector or an (N, 3) array of vectors."""
        v = np.asarray(vector, dtype=np.float64)
        return v @ self.rotation_matrix.T

    @property
    def axis_angle(self) -> tuple[np.ndarray, float]:
        q = self.normalised._q
        if q[0] < 0:
            q = -q
        s = np.linalg.norm(q[1:])
        angle = 2.0 * np.arctan2(s, q[0])
        axis = q[1:] / s if s > 1e-12 else np.array([1.0, 0.0, 0.0])
        return axis, float(angle)

    @property
    def axis(self) -> np.ndarray:
        """Unit rotation axis (x axis for the identity)."""
        return self.axis_angle[0]

    @property
    def angle(self) -> float:
        """Rotation angle in radians, in [0, π]."""
        return self.axis_angle[1]

    radians = angle

    @property
    def degrees(self) -> float:
        return float(np.rad2deg(self.angle))

    @classmethod
    def from_euler(cls, euler_xyz) -> Quaternion:
        """Extrinsic XYZ Euler angles (radians): rotate about world X, then Y, then Z."""
        ex, ey, ez = np.asarray(euler_xyz, dtype=np.float64).reshape(3)
        qx = cls(axis="X", angle=ex)
        qy = cls(axis="Y", angle=ey)
        qz = cls(axis="Z", angle=ez)
        return qz * qy * qx

    @classmethod
    def slerp(cls, q0, q1, t: float) -> Quaternion:
        """Spherical linear interpolation along the shorter arc, t ∈ [0, 1]."""
        a = cls(q0).normalised._q if not isinstance(q0, Quaternion) else q0.normalised._q
        b = cls(q1).normalised._q if not isinstance(q1, Quaternion) else q1.normalised._q
        dot = float(np.dot(a, b))
        if dot < 0.0:
            b, dot = -b, -dot
        if dot > 0.9995:  # nearly parallel: normalised lerp is exact to float precision
            return cls((1 - t) * a + t * b).normalised
        theta = np.arccos(np.clip(dot, -1.0, 1.0))
        s = np.sin(theta)
        return cls((np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / s)


def _matrix_to_quaternion(m: np.ndarray) -> np.ndarray:
    if m.shape == (4, 4):
        m = m[:3, :3]
    if m.shape != (3, 3):
        raise ValueError(f"rotation matrix must be 3×3 or 4×4, got shape {m.shape}")
    if not np.allclose(m @ m.T, np.eye(3), atol=1e-5) or np.linalg.det(m) < 0:
        raise ValueError("matrix is not a proper rotation (orthonormal with determinant +1)")
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def look_at_quaternion(position, target, up="Y", front="-Z") -> Quaternion:
    """Orientation that points the local ``front`` axis from ``position`` at ``target``.

    The local ``up`` axis is turned as close to world +Z as possible. With the defaults (cameras and
    lights: front = −Z, up = +Y), looking from the origin at (0, 0, 1) gives (0, 0, 1, 0). When the view
    direction is parallel to world Z, the frame falls back as upstream Kubric does: looking straight
    down, the camera's x axis is world −X and its y axis world −Y.
    """
    position = np.asarray(position, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    direction = target - position
    if np.linalg.norm(direction) < 1e-12:
        raise ValueError(f"look_at target {target.tolist()} coincides with position {position.tolist()}")
    f = direction / np.linalg.norm(direction)
    r = np.cross(np.array([0.0, 0.0, 1.0]), f)
    r = r / np.linalg.norm(r) if np.linalg.norm(r) > 1e-9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(f, r)
    u /= np.linalg.norm(u)
    local_up, local_front = axis_vector(up), axis_vector(front)
    if abs(float(np.dot(local_up, local_front))) > 1e-6:
        raise ValueError(f"up {up!r} and front {front!r} must be orthogonal")
    local_right = np.cross(local_up, local_front)
    world_frame = np.stack([r, u, f], axis=1)
    local_frame = np.stack([local_right, local_up, local_front], axis=1)
    return Quaternion(matrix=world_frame @ local_frame.T)
