"""The one place that defines Kubric's camera conventions. Pure numpy.

Frames
  * **Camera frame** (Blender's): x right, y up, the camera looks down **−z**. ``matrix_world``
    (4×4) maps camera → world.
  * **OpenCV frame**: x right, y down, looking down **+z** = camera frame with y and z negated.

Image coordinates
  * **Normalised** (upstream Kubric): ``(u, v)`` in [0, 1]², origin at the *top-left corner* of
    the image, u to the right, v **down**.
  * **Pixels**: ``(x, y) = (u·W, v·H)``: origin at the top-left corner, the centre of pixel
    (row r, column c) is at ``(c + 0.5, r + 0.5)``.

Perspective camera (focal length f and sensor width sw in mm, resolution W×H, square pixels, so the
sensor height is sh = sw·H/W; ``shift_x``, ``shift_y`` in units of the sensor width, as Blender with
horizontal sensor fit):
  * normalised intrinsics (upstream's form, for a point in the camera frame):
    ``K = [[f/sw, 0, -cx], [0, -f/sh, -cy], [0, 0, -1]]`` with ``cx = 0.5 - shift_x`` and
    ``cy = 0.5 + shift_y·W/H``; ``(u, v, 1) ∝ K @ p_cam``.
  * pixel intrinsics (OpenCV): ``[[fx, 0, cx·W], [0, fy, cy·H], [0, 0, 1]]``, ``fx = fy = f/sw·W``.
  * **depth** = Euclidean distance from the camera centre; **z** = distance along the view axis.
Lens (``PerspectiveCamera.lens``, :mod:`kubric.core.lenses`; default none = the pinhole above):
OpenCV's models with OpenCV's conventions. A camera-frame point ``p`` is turned into the OpenCV
frame (``CAMERA_TO_OPENCV @ p``), the lens maps it to distorted normalised coordinates
``(xd, yd)``, and the pixel intrinsics above (they are OpenCV's ``cameraMatrix``) give the pixel
``(fx·xd + cx·W, fy·yd + cy·H)``, exactly what ``cv2.projectPoints`` (Brown–Conrady) or
``cv2.fisheye.projectPoints`` (fisheye) return for the same K and coefficients. Each pixel means
the ray the lens gives it (:func:`pixel_rays`): every exact layer, track and keypoint describes the
distorted image. Points outside the lens's domain (behind the camera, or past the radius where
the model folds back) have no image position: NaN pixels, sign −1 in :func:`project_points`;
pixels outside the lens's image have no ray: NaN directions.

Orthographic camera (``orthographic_scale`` = visible width in metres): ``u = x_cam / scale + cx``,
``v = -y_cam / (scale·H/W) + cy``; depth and z are both the distance from the image plane.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from kubric.core.lenses import PINHOLE

#: Depth / z written where a pixel-centre ray hits nothing (metres).
BACKGROUND_DEPTH = 10000.0

# Blender camera frame → OpenCV camera frame (read-only: a shared constant, not state).
CAMERA_TO_OPENCV = np.diag([1.0, -1.0, -1.0])
CAMERA_TO_OPENCV.setflags(write=False)


def image_size(camera, resolution=None) -> tuple[int, int]:
    if resolution is not None:
        w, h = (int(v) for v in resolution)
    else:
        scene = camera.active_scene
        if scene is None:
            raise ValueError(f"{camera.uid} is in no scene: pass resolution=(width, height)")
        w, h = scene.resolution
    return w, h


def principal_point(camera, resolution=None) -> tuple[float, float]:
    """Normalised principal point (cx, cy) in [0, 1] image coordinates (y down)."""
    w, h = image_size(camera, resolution)
    return 0.5 - float(camera.shift_x), 0.5 + float(camera.shift_y) * w / h


def normalised_intrinsics(camera, resolution=None) -> np.ndarray:
    """Upstream Kubric's 3×3 ``K`` (see module doc); for orthographic cameras the affine map
    ``(u, v, 1) = K @ (x_cam, y_cam, 1)``."""
    w, h = image_size(camera, resolution)
    cx, cy = principal_point(camera, (w, h))
    if is_orthographic(camera):
        s = float(camera.orthographic_scale)
        return np.array([[1.0 / s, 0.0, cx], [0.0, -w / (s * h), cy], [0.0, 0.0, 1.0]])
    fx = camera.focal_length / camera.sensor_width
    fy = fx * w / h
    return np.array([[fx, 0.0, -cx], [0.0, -fy, -cy], [0.0, 0.0, -1.0]])


def pixel_intrinsics(camera, resolution=None) -> np.ndarray:
    """OpenCV 3×3 pixel intrinsics (perspective cameras only)."""
    if is_orthographic(camera):
        raise ValueError(f"{camera.uid} is orthographic: it has no pinhole pixel intrinsics")
    w, h = image_size(camera, resolution)
    cx, cy = principal_point(camera, (w, h))
    f = camera.focal_length / camera.sensor_width * w
    return np.array([[f, 0.0, cx * w], [0.0, f, cy * h], [0.0, 0.0, 1.0]])


def is_orthographic(camera) -> bool:
    return hasattr(camera, "orthographic_scale")


def lens_of(camera):
    """The camera's lens model (:mod:`kubric.core.lenses`); orthographic cameras: the pinhole
    identity."""
    return getattr(camera, "lens", PINHOLE)


def has_distortion(camera) -> bool:
    """Whether the camera's lens is not the pinhole identity."""
    return not lens_of(camera).is_pinhole


def camera_to_world(camera, frame: float | None = None) -> np.ndarray:
    """(4, 4) camera → world matrix at ``frame`` (interpolated from keyframes; None = now)."""
    with camera.at_frame(frame):
        return camera.matrix_world


def camera_to_world_matrices(camera, frames: Sequence[float]) -> np.ndarray:
    """(T, 4, 4) camera → world matrices for each frame."""
    return np.stack([camera_to_world(camera, f) for f in frames])


def world_to_camera(camera, frame: float | None = None) -> np.ndarray:
    """(4, 4) world → camera (Blender camera frame) matrix at ``frame``."""
    m = camera_to_world(camera, frame)
    inv = np.eye(4)
    inv[:3, :3] = m[:3, :3].T
    inv[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return inv


def project_points(camera, points, frame: float | None = None, resolution=None) -> np.ndarray:
    """Project world points (..., 3) to normalised image coordinates.

    Returns (..., 3): ``u``, ``v`` (origin top-left, v down) and ``+1`` for points in front of the
    camera, ``-1`` behind it (upstream's ``project_point`` format).
    """
    m = world_to_camera(camera, frame)
    cam = np.asarray(points, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
    return _project_camera_points(camera, cam, resolution)


def _project_camera_points(camera, cam: np.ndarray, resolution) -> np.ndarray:
    """(u, v, ±1) of points (..., 3) already in the camera frame."""
    w, h = image_size(camera, resolution)
    cx, cy = principal_point(camera, (w, h))
    if has_distortion(camera):
        xy = _lens_pixels(camera, cam, (w, h))
        inside = np.isfinite(xy).all(axis=-1)
        return np.stack([xy[..., 0] / w, xy[..., 1] / h, np.where(inside, 1.0, -1.0)], axis=-1)
    if is_orthographic(camera):
        s = float(camera.orthographic_scale)
        u = cam[..., 0] / s + cx
        v = -cam[..., 1] / (s * h / w) + cy
        sign = np.where(cam[..., 2] < 0, 1.0, -1.0)
    else:
        fx = camera.focal_length / camera.sensor_width
        fy = fx * w / h
        d = -cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = fx * cam[..., 0] / d + cx
            v = -fy * cam[..., 1] / d + cy
        sign = np.sign(d)
    return np.stack([u, v, sign], axis=-1)


def _lens_pixels(camera, cam: np.ndarray, resolution) -> np.ndarray:
    """Pixel positions (..., 2) of camera-frame points (..., 3) through the camera's lens (NaN
    outside its domain)."""
    k = pixel_intrinsics(camera, resolution)
    xy_d = lens_of(camera).project(cam @ CAMERA_TO_OPENCV.T)
    return np.stack([k[0, 0] * xy_d[..., 0] + k[0, 2], k[1, 1] * xy_d[..., 1] + k[1, 2]], -1)


def project_to_pixels(camera, points, frame: float | None = None, resolution=None):
    """World points (..., 3) → (pixel xy (..., 2), depth (...)): depth is the distance to the camera
    centre (perspective) or to the image plane (orthographic)."""
    w, h = image_size(camera, resolution)
    m = world_to_camera(camera, frame)
    cam = np.asarray(points, dtype=np.float64) @ m[:3, :3].T + m[:3, 3]
    xy = _project_camera_points(camera, cam, (w, h))[..., :2] * np.array([w, h], dtype=np.float64)
    depth = -cam[..., 2] if is_orthographic(camera) else np.linalg.norm(cam, axis=-1)
    return xy, depth


def pinhole_rays(intrinsics_pixels, camera_to_world, pixels_xy, lens=None):
    """The one pixel-ray function of a camera given by numbers: rays through pixel positions
    (..., 2) (x right, y down; the centre of pixel (row r, column c) is (c + 0.5, r + 0.5)) of a
    camera with OpenCV intrinsics ``intrinsics_pixels`` (3, 3: fx, fy, cx, cy in pixels, no skew),
    ``camera_to_world`` (4, 4) in Blender camera axes (x right, y up, −z forward) and an
    optional ``lens`` (:mod:`kubric.core.lenses`; None = pinhole; NaN directions where the lens's
    image has no ray). Returns world (origins (..., 3), unit directions (..., 3)), float64."""
    k = np.asarray(intrinsics_pixels, dtype=np.float64)
    if k.shape != (3, 3) or k[0, 1] != 0:
        raise ValueError(f"pinhole_rays: intrinsics must be a 3×3 matrix without skew, got "
                         f"{k.tolist()}")
    xy = np.asarray(pixels_xy, dtype=np.float64)
    if lens is not None and not lens.is_pinhole:
        xy_d = np.stack([(xy[..., 0] - k[0, 2]) / k[0, 0], (xy[..., 1] - k[1, 2]) / k[1, 1]], -1)
        local = _directions_of(lens.undistort(xy_d))
    else:
        local = np.stack([(xy[..., 0] - k[0, 2]) / k[0, 0], -(xy[..., 1] - k[1, 2]) / k[1, 1],
                          -np.ones(xy.shape[:-1])], axis=-1)
        local /= np.linalg.norm(local, axis=-1, keepdims=True)
    m = np.asarray(camera_to_world, dtype=np.float64)
    dirs = local @ m[:3, :3].T
    return np.broadcast_to(m[:3, 3], dirs.shape).copy(), dirs


def pixel_centres(height: int, width: int) -> np.ndarray:
    """(H, W, 2) pixel-centre positions (x, y) = (c + 0.5, r + 0.5) of every pixel (r, c)."""
    rows, cols = np.meshgrid(np.arange(height) + 0.5, np.arange(width) + 0.5, indexing="ij")
    return np.stack([cols, rows], axis=-1)


def pixel_rays(camera, pixels_xy, frame: float | None = None, resolution=None):
    """Rays through pixel positions (..., 2): returns (origins (..., 3), unit directions (..., 3))
    in world coordinates (perspective cameras: :func:`pinhole_rays`, through the camera's lens:
    NaN directions where the lens's image has no ray)."""
    w, h = image_size(camera, resolution)
    m = camera_to_world(camera, frame)
    if not is_orthographic(camera):
        return pinhole_rays(pixel_intrinsics(camera, (w, h)), m, pixels_xy, lens_of(camera))
    xy = np.asarray(pixels_xy, dtype=np.float64)
    u, v = xy[..., 0] / w, xy[..., 1] / h
    cx, cy = principal_point(camera, (w, h))
    rot, centre = m[:3, :3], m[:3, 3]
    s = float(camera.orthographic_scale)
    local = np.stack([(u - cx) * s, -(v - cy) * s * h / w, np.zeros_like(u)], axis=-1)
    origins = local @ rot.T + centre
    dirs = np.broadcast_to(-rot[:, 2], origins.shape).copy()
    return origins, dirs


def pixel_centre_rays(camera, frame: float | None = None, resolution=None):
    """:func:`pixel_rays` through every pixel centre, (H·W, 3) each, row-major (pixel (r, c) at
    index r·W + c); a lens's camera-frame directions are computed once per (lens, intrinsics,
    size) and reused for every frame."""
    w, h = image_size(camera, resolution)
    if not has_distortion(camera):
        return pixel_rays(camera, pixel_centres(h, w).reshape(-1, 2), frame, (w, h))
    m = camera_to_world(camera, frame)
    dirs = _centre_directions(camera, w, h).reshape(-1, 3) @ m[:3, :3].T
    return np.broadcast_to(m[:3, 3], dirs.shape).copy(), dirs


def _centre_directions(camera, w: int, h: int) -> np.ndarray:
    """(H, W, 3) camera-frame lens directions of the pixel centres (cached, read-only)."""
    k = pixel_intrinsics(camera, (w, h))
    return _cached_directions(lens_of(camera), tuple(k.ravel().tolist()), w, h)


@functools.lru_cache(maxsize=8)
def _cached_directions(lens, k: tuple, w: int, h: int) -> np.ndarray:
    dirs = pinhole_rays(np.asarray(k).reshape(3, 3), np.eye(4), pixel_centres(h, w), lens)[1]
    dirs.setflags(write=False)
    return dirs


def _directions_of(ab: np.ndarray) -> np.ndarray:
    """Unit Blender-camera-frame directions (..., 3) of pinhole positions (..., 2) (OpenCV)."""
    opencv = np.concatenate([ab, np.ones(ab.shape[:-1] + (1,))], axis=-1)
    opencv /= np.linalg.norm(opencv, axis=-1, keepdims=True)
    return opencv @ CAMERA_TO_OPENCV.T  # the matrix is its own inverse


def unproject_pixels(camera, pixels_xy, depth, frame: float | None = None, resolution=None):
    """Inverse of :func:`project_to_pixels`: pixel positions (..., 2) and depth (...) → world
    points (..., 3)."""
    origins, dirs = pixel_rays(camera, pixels_xy, frame, resolution)
    return origins + dirs * np.asarray(depth, dtype=np.float64)[..., None]


def _depth_per_z(camera, w: int, h: int) -> np.ndarray:
    """(H, W) factor depth / z at every pixel centre (1 at pixels with no ray through a lens)."""
    if is_orthographic(camera):
        return np.ones((h, w))
    if has_distortion(camera):
        return np.nan_to_num(-1.0 / _centre_directions(camera, w, h)[..., 2], nan=1.0)
    cx, cy = principal_point(camera, (w, h))
    fx = camera.focal_length / camera.sensor_width
    fy = fx * w / h
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    dx = (u[None, :] - cx) / fx
    dy = (v[:, None] - cy) / fy
    return np.sqrt(1.0 + dx**2 + dy**2)


def _per_pixel(camera, image, factor_fn):
    arr = np.asarray(image)
    squeeze = arr.ndim >= 3 and arr.shape[-1] == 1
    hw = arr.shape[-3:-1] if squeeze else arr.shape[-2:]
    if len(hw) != 2:
        raise ValueError(f"expected an image (..., H, W) or (..., H, W, 1), got shape {arr.shape}")
    h, w = hw
    factor = factor_fn(_depth_per_z(camera, w, h))
    if squeeze:
        factor = factor[..., None]
    return (arr * factor).astype(np.result_type(arr.dtype, np.float32))


def z_to_depth(camera, z) -> np.ndarray:
    """z (distance along the view axis) → depth (distance to the camera centre), per pixel.
    ``z`` has shape (..., H, W) or (..., H, W, 1)."""
    return _per_pixel(camera, z, lambda f: f)


def depth_to_z(camera, depth) -> np.ndarray:
    """Inverse of :func:`z_to_depth`."""
    return _per_pixel(camera, depth, lambda f: 1.0 / f)
