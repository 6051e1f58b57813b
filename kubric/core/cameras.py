"""Cameras. A camera looks down its local −Z axis with +Y up (Blender's convention); conventions
for intrinsics, projection and depth live in :mod:`kubric.core.camera_geometry`."""

from __future__ import annotations

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import traits as kt
from kubric.core.assets import UndefinedAsset
from kubric.core.lenses import PINHOLE, Lens
from kubric.core.objects import Object3D


class Camera(Object3D):
    """Base class of cameras (part of the background; never simulated)."""

    property_defaults = {"background": True}
    shift_x = kt.Float(0.0, -10.0, 10.0, "horizontal lens shift, in units of the sensor width")
    shift_y = kt.Float(0.0, -10.0, 10.0, "vertical lens shift, in units of the sensor width")
    rolling_shutter_duration = kt.Float(
        0.0, 0.0, 10.0, "rolling shutter: readout time from the image's top edge to its bottom "
        "edge, in frames (0 = global shutter; row times: kubric.core.rolling_shutter)")

    @property
    def intrinsics(self) -> np.ndarray:
        """Upstream Kubric's normalised 3×3 ``K`` (see camera_geometry)."""
        return geo.normalised_intrinsics(self)

    @property
    def intrinsics_pixels(self) -> np.ndarray:
        """OpenCV 3×3 pixel intrinsics for the scene's resolution."""
        return geo.pixel_intrinsics(self)

    def project_point(self, point3d, frame: float | None = None) -> np.ndarray:
        """World point(s) (..., 3) → (u, v, ±1): normalised, origin top-left, v down; +1 in front."""
        return geo.project_points(self, point3d, frame)

    def unproject_pixel(self, pixel_xy, depth, frame: float | None = None) -> np.ndarray:
        """Pixel position(s) (..., 2) (centres at +0.5) and depth (...) → world point(s) (..., 3)."""
        return geo.unproject_pixels(self, pixel_xy, depth, frame)

    def z_to_depth(self, z) -> np.ndarray:
        """Per-pixel z (..., H, W[, 1]) → depth (distance to the camera centre)."""
        return geo.z_to_depth(self, z)

    def depth_to_z(self, depth) -> np.ndarray:
        return geo.depth_to_z(self, depth)


class UndefinedCamera(Camera, UndefinedAsset):
    """Marker: the scene has no camera yet."""


class PerspectiveCamera(Camera):
    """Pinhole camera (optionally with thin-lens depth of field).

    Attributes:
      focal_length: mm (default 50). sensor_width: mm (default 36), horizontal.
      field_of_view: horizontal, radians (setting it changes focal_length).
      use_dof, focus_distance (m), aperture_fstop: thin-lens depth of field (renderer only).
      lens: the lens model (:mod:`kubric.core.lenses`: ``BrownConrady``, ``Fisheye``; default
        the pinhole identity); projections, pixel rays and every exact layer go through it
        (:mod:`kubric.core.camera_geometry`). Not keyframed.
    """

    focal_length = kt.Float(50.0, 1e-3, 1e5, "focal length (mm)")
    sensor_width = kt.Float(36.0, 1e-3, 1e4, "horizontal sensor size (mm)")
    use_dof = kt.Property(False, kt.as_bool(), "render with depth of field")
    focus_distance = kt.Float(10.0, 0.0, doc="distance to the plane in focus (m)")
    aperture_fstop = kt.Float(2.8, 1e-3, doc="f-number of the aperture")
    lens = kt.Property(PINHOLE, lambda v, o, n: _as_lens(v, o, n),
                       "lens model (kubric.core.lenses; OpenCV's conventions)")

    @property
    def field_of_view(self) -> float:
        """Horizontal field of view in radians: 2·atan(sensor_width / (2·focal_length))."""
        return float(2.0 * np.arctan2(self.sensor_width / 2.0, self.focal_length))

    @field_of_view.setter
    def field_of_view(self, fov: float) -> None:
        fov = kt.as_float(1e-6, np.pi - 1e-6)(fov, self, "field_of_view")
        self.focal_length = self.sensor_width / (2.0 * np.tan(fov / 2.0))

    @property
    def sensor_height(self) -> float:
        """mm, from the scene's aspect ratio (square pixels)."""
        w, h = geo.image_size(self)
        return self.sensor_width * h / w


def _as_lens(value, owner, name):
    if value is None:
        return PINHOLE
    if not isinstance(value, Lens):
        raise TypeError(f"{type(owner).__name__}.{name} must be a kubric.core.lenses lens "
                        f"(Pinhole, BrownConrady, Fisheye) or None, got {value!r}")
    return value


class OrthographicCamera(Camera):
    """Parallel projection; ``orthographic_scale`` is the visible width in metres (default 6)."""

    orthographic_scale = kt.Float(6.0, 1e-6, doc="visible width (m)")
