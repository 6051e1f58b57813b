"""Lens models: how a ray in the camera frame becomes a position on the image. Pure numpy.

Every model here is OpenCV's, with OpenCV's conventions, and works in the **OpenCV camera frame**
(x right, y down, looking down +z; :data:`kubric.core.camera_geometry.CAMERA_TO_OPENCV`). A point
``P = (X, Y, Z)`` has the *pinhole* normalised position ``(a, b) = (X / Z, Y / Z)``; the lens maps
it to the *distorted* normalised position ``(xd, yd)``, and the camera's pixel intrinsics (OpenCV's
``K``: fx, fy, cx, cy) put it on the image: ``(x, y) = (fx·xd + cx, fy·yd + cy)``.

* :class:`BrownConrady` (OpenCV's default model, ``cv2.projectPoints``): coefficients in OpenCV's
  order ``(k1, k2, p1, p2, k3, k4, k5, k6)``; with ``r² = a² + b²`` and
  ``R = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)``::

      xd = a·R + 2·p1·a·b + p2·(r² + 2a²)
      yd = b·R + p1·(r² + 2b²) + 2·p2·a·b

* :class:`Fisheye` (OpenCV's ``cv2.fisheye``, Kannala–Brandt): coefficients ``(k1, k2, k3, k4)``;
  ``θ = atan(r)`` (the angle from the optical axis), ``θd = θ·(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)``
  and ``(xd, yd) = (θd / r)·(a, b)`` (no skew).

Domain (where a model is one-to-one, so every image position means one ray and back):
points in front of the camera only (``Z > 0``), and

* Brown–Conrady: ``r < r_max``, where ``r_max`` is the first radius at which the radial map
  ``ρ(r) = r·R(r²)`` stops increasing or R's denominator reaches 0 (found on a grid of 20000
  view angles up to 90°, refined by bisection; tan(90° − 0.0045°) ≈ 12732 when it never does).
  Tangential terms do not enter r_max; :meth:`Lens.undistort` additionally checks that its
  solution maps back (|error| < 1e-12) with a positive Jacobian determinant.
* Fisheye: ``θ < θ_max = min(π/2, the first angle at which θd(θ) stops increasing)``.

Outside the domain :meth:`Lens.distort` returns NaN (the point has no image position), and
:meth:`Lens.undistort` returns NaN for image positions outside the lens's image (no ray).

:data:`PINHOLE` (``Pinhole()``) is the identity: a camera without distortion.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass

import numpy as np

#: undistort's convergence: |distort(solution) − target| below this (normalised units)
TOLERANCE = 1e-12
_NEWTON_STEPS = 30
_BISECTIONS = 80
_GRID = 20001  # samples of the view angle in [0, π/2) when looking for the domain's edge


def _coefficients(cls_name: str, values, count: int) -> tuple[float, ...]:
    vals = tuple(float(v) for v in np.asarray(values, dtype=np.float64).reshape(-1))
    if len(vals) != count or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{cls_name}: expected {count} finite coefficients, got "
                         f"{list(np.asarray(values).reshape(-1))}")
    return vals


def _first_drop(slope: np.ndarray, grid: np.ndarray, slope_fn) -> float:
    """The first position where ``slope`` (of ``slope_fn`` on ``grid``) is no longer positive,
    refined by bisection on slope_fn; the grid's end when it never is."""
    bad = np.flatnonzero(~(slope > 0))
    if len(bad) == 0:
        return float(grid[-1])
    if bad[0] == 0:
        return 0.0
    lo, hi = float(grid[bad[0] - 1]), float(grid[bad[0]])
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if slope_fn(mid) > 0:
            lo = mid
        else:
            hi = mid
    return lo


def _solve(jac: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solutions x of jac (N, 2, 2) · x = rhs (N, 2)."""
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    return np.stack([jac[:, 1, 1] * rhs[:, 0] - jac[:, 0, 1] * rhs[:, 1],
                     jac[:, 0, 0] * rhs[:, 1] - jac[:, 1, 0] * rhs[:, 0]], -1) / det[:, None]


class Lens(abc.ABC):
    """A lens model (see module doc). ``name`` is the metadata's model name, ``coefficients`` the
    values in OpenCV's order."""

    name = "none"
    _names: tuple[str, ...] = ()  # the coefficients' attribute names, in OpenCV's order

    @property
    def coefficients(self) -> tuple[float, ...]:
        return tuple(getattr(self, n) for n in self._names)

    def _check_coefficients(self) -> None:
        vals = _coefficients(type(self).__name__, [getattr(self, n) for n in self._names],
                             len(self._names))
        for n, v in zip(self._names, vals, strict=True):
            object.__setattr__(self, n, v)

    @property
    def is_pinhole(self) -> bool:
        return False

    @abc.abstractmethod
    def domain_radius(self) -> float:
        """The largest pinhole radius r = |(a, b)| inside the domain (exclusive; may be ∞)."""

    @abc.abstractmethod
    def radial(self, r: np.ndarray) -> np.ndarray:
        """The distorted radius of pinhole radius ``r`` (radial part only), increasing on the
        domain."""

    @abc.abstractmethod
    def _map(self, ab: np.ndarray) -> np.ndarray:
        """The model on (..., 2) pinhole positions (no domain check)."""

    def distort(self, ab) -> np.ndarray:
        """Pinhole normalised positions (..., 2) → distorted ones (..., 2); NaN outside the
        domain."""
        ab = np.asarray(ab, dtype=np.float64)
        r = np.hypot(ab[..., 0], ab[..., 1])
        with np.errstate(invalid="ignore", over="ignore"):
            out = self._map(ab)
        out[~(r < self.domain_radius())] = np.nan
        return out

    def project(self, points_opencv) -> np.ndarray:
        """Points (..., 3) in the OpenCV camera frame → distorted normalised positions (..., 2);
        NaN for points not in front of the camera (Z ≤ 0) or outside the domain."""
        p = np.asarray(points_opencv, dtype=np.float64)
        z = p[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ab = p[..., :2] / np.where(z > 0, z, np.nan)[..., None]
        return self.distort(ab)

    def undistort(self, xy_d) -> np.ndarray:
        """Distorted normalised positions (..., 2) → pinhole ones (..., 2), the inverse of
        :meth:`distort` on its domain: the radius by bisection on the (increasing) radial map,
        then Newton's method on the full model; NaN where no point of the domain maps there
        within :data:`TOLERANCE`."""
        xy_d = np.asarray(xy_d, dtype=np.float64)
        flat = xy_d.reshape(-1, 2)
        rd = np.hypot(flat[:, 0], flat[:, 1])
        r = self._invert_radial(rd)
        edge = min(self.domain_radius(), 1e8)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ab = flat * np.where(rd > 0, r / rd, 1.0)[:, None]
            active = np.flatnonzero(np.isfinite(ab).all(axis=1))
            for _ in range(_NEWTON_STEPS):
                err = self._map(ab[active]) - flat[active]
                busy = np.abs(err).max(axis=1) > TOLERANCE * 1e-3
                active, err = active[busy], err[busy]
                if not len(active):
                    break
                ab[active] -= _solve(self._jacobian(ab[active]), err)
                # Newton thrown far off the domain (an image position with no ray): give up there
                lost = ~(np.hypot(ab[active, 0], ab[active, 1]) < 4 * edge)
                ab[active[lost]] = np.nan
                active = active[~lost]
            err = np.abs(self._map(ab) - flat).max(axis=1)
            jac = self._jacobian(ab)
            det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        ok = (err < TOLERANCE * np.maximum(1.0, rd)) & (det > 0) & (
            np.hypot(ab[:, 0], ab[:, 1]) < self.domain_radius())
        ab[~ok] = np.nan
        return ab.reshape(xy_d.shape)

    def _invert_radial(self, rd: np.ndarray) -> np.ndarray:
        """Pinhole radii with ``radial(r) = rd`` by bisection on [0, domain edge) (Newton's
        start; at the edge for rd beyond the edge's image, which tangential terms can reach)."""
        hi_r = min(self.domain_radius(), 1e8)
        top = float(self.radial(np.array([hi_r]))[0])
        lo, hi = np.zeros_like(rd), np.full_like(rd, hi_r)
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            below = self.radial(mid) < rd
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
        r = 0.5 * (lo + hi)
        r[~(rd < top)] = hi_r * (1 - 1e-6)
        r[~np.isfinite(rd)] = np.nan
        return r

    @abc.abstractmethod
    def _jacobian(self, ab: np.ndarray) -> np.ndarray:
        """(N, 2, 2) d distort / d (a, b), analytic."""

    def record(self) -> dict:
        """The metadata's description: ``{"model": name, "coefficients": [...]}`` (OpenCV's
        order)."""
        return {"model": self.name, "coefficients": list(self.coefficients)}


@dataclass(frozen=True, eq=True)
class Pinhole(Lens):
    """No distortion (the identity)."""

    name = "none"

    @property
    def is_pinhole(self) -> bool:
        return True

    def domain_radius(self) -> float:
        return math.inf

    def radial(self, r):
        return np.asarray(r, dtype=np.float64)

    def _map(self, ab):
        return np.array(ab, dtype=np.float64)

    def _jacobian(self, ab):
        return np.broadcast_to(np.eye(2), ab.shape[:-1] + (2, 2)).copy()


@dataclass(frozen=True, eq=True)
class BrownConrady(Lens):
    """OpenCV's distortion model (``cv2.projectPoints``); coefficients in OpenCV's order
    ``(k1, k2, p1, p2, k3, k4, k5, k6)`` (dimensionless, on normalised positions)."""

    k1: float = 0.0
    k2: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    k5: float = 0.0
    k6: float = 0.0
    name = "opencv"
    _names = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")

    def __post_init__(self):
        self._check_coefficients()
        object.__setattr__(self, "_edge", self._find_edge())

    @classmethod
    def from_opencv(cls, coefficients) -> BrownConrady:
        """From OpenCV's ``distCoeffs`` (4, 5 or 8 values: k1, k2, p1, p2[, k3[, k4, k5, k6]])."""
        vals = np.asarray(coefficients, dtype=np.float64).reshape(-1)
        if len(vals) not in (4, 5, 8):
            raise ValueError(f"BrownConrady: OpenCV distCoeffs have 4, 5 or 8 values "
                             f"(k1, k2, p1, p2[, k3[, k4, k5, k6]]), got {vals.tolist()}")
        return cls(*np.concatenate([vals, np.zeros(8 - len(vals))]))

    def _ratio(self, r2):
        num = 1 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        den = 1 + r2 * (self.k4 + r2 * (self.k5 + r2 * self.k6))
        return num, den

    def radial(self, r):
        r = np.asarray(r, dtype=np.float64)
        num, den = self._ratio(r * r)
        return r * num / den

    def _slope(self, r):
        """d radial / d r (−1 where R's denominator is not positive)."""
        r2 = np.asarray(r, dtype=np.float64) ** 2
        num, den = self._ratio(r2)
        dnum = self.k1 + r2 * (2 * self.k2 + 3 * r2 * self.k3)
        dden = self.k4 + r2 * (2 * self.k5 + 3 * r2 * self.k6)
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = num / den + 2 * r2 * (dnum * den - num * dden) / (den * den)
        return np.where(den > 0, slope, -1.0)

    def _find_edge(self) -> float:
        r = np.tan(np.linspace(0.0, np.pi / 2, _GRID)[:-1])
        with np.errstate(over="ignore", invalid="ignore"):
            return _first_drop(self._slope(r), r, lambda x: float(self._slope(x)))

    def domain_radius(self) -> float:
        return self._edge

    def _map(self, ab):
        a, b = ab[..., 0], ab[..., 1]
        r2 = a * a + b * b
        num, den = self._ratio(r2)
        ratio = num / den
        return np.stack([a * ratio + 2 * self.p1 * a * b + self.p2 * (r2 + 2 * a * a),
                         b * ratio + self.p1 * (r2 + 2 * b * b) + 2 * self.p2 * a * b], -1)

    def _jacobian(self, ab):
        a, b = ab[..., 0], ab[..., 1]
        r2 = a * a + b * b
        num, den = self._ratio(r2)
        dnum = self.k1 + r2 * (2 * self.k2 + 3 * r2 * self.k3)
        dden = self.k4 + r2 * (2 * self.k5 + 3 * r2 * self.k6)
        ratio, dratio = num / den, (dnum * den - num * dden) / (den * den)  # d ratio / d r²
        p1, p2 = self.p1, self.p2
        return np.stack([
            np.stack([ratio + 2 * a * a * dratio + 2 * p1 * b + 6 * p2 * a,
                      2 * a * b * dratio + 2 * p1 * a + 2 * p2 * b], -1),
            np.stack([2 * a * b * dratio + 2 * p1 * a + 2 * p2 * b,
                      ratio + 2 * b * b * dratio + 6 * p1 * b + 2 * p2 * a], -1)], -2)


@dataclass(frozen=True, eq=True)
class Fisheye(Lens):
    """OpenCV's fisheye model (``cv2.fisheye``, Kannala–Brandt); coefficients ``(k1, k2, k3,
    k4)`` of the angle polynomial (radians)."""

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0
    name = "fisheye"
    _names = ("k1", "k2", "k3", "k4")

    def __post_init__(self):
        self._check_coefficients()
        theta = np.linspace(0.0, np.pi / 2, _GRID)
        edge = _first_drop(self._slope(theta), theta, lambda t: float(self._slope(t)))
        object.__setattr__(self, "_edge", math.tan(min(edge, np.pi / 2)))
        object.__setattr__(self, "max_angle", min(edge, np.pi / 2))

    def _theta_d(self, theta):
        t2 = theta * theta
        return theta * (1 + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4))))

    def _slope(self, theta):
        """d θd / d θ."""
        t2 = np.asarray(theta, dtype=np.float64) ** 2
        return 1 + t2 * (3 * self.k1 + t2 * (5 * self.k2 + t2 * (7 * self.k3 + t2 * 9 * self.k4)))

    def radial(self, r):
        return self._theta_d(np.arctan(np.asarray(r, dtype=np.float64)))

    def domain_radius(self) -> float:
        return self._edge

    def _map(self, ab):
        r = np.hypot(ab[..., 0], ab[..., 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(r > 1e-12, self._theta_d(np.arctan(r)) / r, 1.0)
        return ab * scale[..., None]

    def _jacobian(self, ab):
        # (θd / r)·(a, b): J = s·I + (ds/dr / r)·(a, b)ᵀ(a, b), s = θd / r
        r = np.hypot(ab[..., 0], ab[..., 1])
        theta = np.arctan(r)
        dtheta_d = self._slope(theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(r > 1e-12, self._theta_d(theta) / r, 1.0)
            ds_r = np.where(r > 1e-6, (dtheta_d / (1 + r * r) - s) / (r * r), 0.0)
        outer = ab[..., :, None] * ab[..., None, :]
        return s[..., None, None] * np.eye(2) + ds_r[..., None, None] * outer


#: the identity lens (a camera without distortion)
PINHOLE = Pinhole()

#: metadata model name → class (``lens=`` option values of the recipes)
MODELS = {"none": Pinhole, "opencv": BrownConrady, "fisheye": Fisheye}


def from_record(model: str, coefficients=()) -> Lens:
    """The lens of a metadata record / recipe option: ``model`` one of :data:`MODELS`,
    ``coefficients`` in OpenCV's order (opencv: 4, 5 or 8 values; fisheye: 4; none: none)."""
    if model not in MODELS:
        raise ValueError(f"unknown lens model {model!r}; allowed: {sorted(MODELS)}")
    coefficients = list(np.asarray(coefficients, dtype=np.float64).reshape(-1))
    if model == "none":
        if coefficients:
            raise ValueError(f"lens model 'none' takes no coefficients, got {coefficients}")
        return PINHOLE
    if model == "opencv":
        return BrownConrady.from_opencv(coefficients)
    return Fisheye(*_coefficients("Fisheye", coefficients, 4))


def from_camera_record(camera) -> Lens:
    """The lens of a camera record (metadata.json's ``camera`` or a packed example's camera
    features: ``distortion_model`` (str or bytes) and ``distortion_coefficients``, zero-padded to
    8); the pinhole when the record has none (scenes written before lenses)."""
    model = camera.get("distortion_model", "none")
    model = model.decode() if isinstance(model, bytes) else str(model)
    if model == "none":
        return PINHOLE
    coefficients = np.asarray(camera["distortion_coefficients"], np.float64).reshape(-1)
    return from_record(model, coefficients if model == "opencv" else coefficients[:4])


def pinhole_refusal(camera, what: str) -> str | None:
    """One line when the camera record has a lens that ``what`` (a pinhole-only format) cannot
    describe; None for a pinhole camera."""
    lens = from_camera_record(camera)
    if lens.is_pinhole:
        return None
    return (f"{what} describes pinhole cameras only; this scene's camera has the lens "
            f"{lens.name} {list(lens.coefficients)} (metadata camera.distortion_model)")
