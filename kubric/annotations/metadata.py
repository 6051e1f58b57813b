"""Scene, camera and instance metadata and collision events for ``metadata.json`` /
``events.json`` (fields in ``docs/scene-format.md``). Pure numpy over the scene model; every projection
goes through :mod:`kubric.core.camera_geometry`.

Frames: functions take ``frames`` (scene frame numbers, default ``scene.frame_start ..
scene.frame_end``); per-frame arrays have one row per entry of ``frames``, in that order.
"""

from __future__ import annotations

import importlib.metadata
from collections.abc import Sequence

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core.color import Color
from kubric.core.deformables import Deformable
from kubric.core.materials import Texture
from kubric.core.objects import PhysicalObject

CAMERA_CONVENTIONS = (
    "world: right-handed, z up, metres; quaternions WXYZ. matrices_world (T,4,4) and R map camera "
    "-> world with Blender camera axes (x right, y up, looking down -z). K is upstream Kubric's "
    "normalised form: (u, v, 1) ~ K @ p_cam with u, v in [0, 1], origin at the top-left image "
    "corner, v down. intrinsics_pixels is OpenCV's (x right, y down, looking down +z, pixel "
    "(row r, col c) centred at (c+0.5, r+0.5)). depth = Euclidean distance to the camera centre. "
    "distortion_model / distortion_coefficients: OpenCV's lens model (none, opencv = "
    "cv2.projectPoints' k1,k2,p1,p2,k3,k4,k5,k6; fisheye = cv2.fisheye's k1..k4, zero-padded to 8) "
    "with intrinsics_pixels as its cameraMatrix; extrinsics_opencv (T,4,4) maps world -> OpenCV "
    "camera axes.")


def _frames(scene, frames) -> list[int]:
    if frames is None:
        return list(scene.frames)
    return [int(f) if float(f).is_integer() else float(f) for f in frames]


def library_versions() -> dict[str, str]:
    """Installed versions of kubric, numpy, bpy (Blender) and pybullet (read from package
    metadata: nothing is imported)."""
    versions = {}
    for dist in ("kubric", "numpy", "bpy", "pybullet"):
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[dist] = "not installed"
    return versions


def describe_background(value) -> str:
    """A JSON-friendly description of ``scene.background``: a colour's hex string or a texture's
    file name / asset id."""
    if isinstance(value, Color):
        return value.hexstr
    if isinstance(value, Texture):
        return str(value.metadata.get("asset_id") or value.filename or value.uid)
    return str(value)


def get_scene_metadata(scene, frames: Sequence[float] | None = None, **kwargs) -> dict:
    """Scene-level metadata: ``resolution`` [W, H], ``frame_rate``, ``step_rate``, ``gravity``
    (3,), ``num_frames``, ``frame_start``, ``frame_end``, ``background``,
    ``background_depth`` (depth written where no surface is hit) and library
    ``versions``, updated with ``scene.metadata`` and then ``kwargs`` (e.g. ``seed``,
    ``num_instances``, renderer settings)."""
    frames = _frames(scene, frames)
    meta = {
        "resolution": [int(v) for v in scene.resolution],
        "frame_rate": int(scene.frame_rate),
        "step_rate": int(scene.step_rate),
        "gravity": np.asarray(scene.gravity, dtype=np.float32),
        "num_frames": len(frames),
        "frame_start": int(frames[0]) if frames else int(scene.frame_start),
        "frame_end": int(frames[-1]) if frames else int(scene.frame_end),
        "background": describe_background(scene.background),
        "background_depth": geo.BACKGROUND_DEPTH,
        "versions": library_versions(),
    }
    meta.update(scene.metadata)
    meta.update(kwargs)
    return meta


def get_camera_info(camera, frames: Sequence[float] | None = None, resolution=None,
                    **extra) -> dict:
    """Camera metadata over ``frames`` (default: the camera's scene's frame range); ``extra``
    keyword arguments are added to the result as they are (as upstream did).

    Returns: ``focal_length`` and ``sensor_width`` (mm), ``field_of_view`` (horizontal, rad)
    (perspective) or ``orthographic_scale`` (m); ``positions`` (T,3) and ``quaternions`` (T,4
    WXYZ); ``K`` (3,3 normalised), ``R`` (4,4 camera→world at the first frame),
    ``matrices_world`` (T,4,4), ``extrinsics_opencv`` (T,4,4 world → OpenCV camera axes),
    ``intrinsics_pixels`` (3,3, perspective only: OpenCV's cameraMatrix), ``distortion_model``
    and ``distortion_coefficients`` (perspective only: the lens, OpenCV's order, zero-padded to
    8; :mod:`kubric.core.lenses`), ``resolution`` and a ``conventions`` note (see
    :mod:`kubric.core.camera_geometry`).
    """
    scene = camera.active_scene
    if frames is None and scene is None:
        raise ValueError(f"{camera.uid} is in no scene: pass frames explicitly")
    frames = _frames(scene, frames)
    if resolution is None:
        if scene is None:
            raise ValueError(f"{camera.uid} is in no scene: pass resolution=(width, height)")
        resolution = scene.resolution
    matrices = geo.camera_to_world_matrices(camera, frames)
    info = {
        "K": geo.normalised_intrinsics(camera, resolution),
        "R": matrices[0],
        "matrices_world": matrices,
        "extrinsics_opencv": np.stack([_to_opencv(camera, f) for f in frames]),
        "positions": camera.get_values_over_time("position", frames),
        "quaternions": camera.get_values_over_time("quaternion", frames),
        "resolution": [int(v) for v in resolution],
        "conventions": CAMERA_CONVENTIONS,
    }
    if geo.is_orthographic(camera):
        info["orthographic_scale"] = float(camera.orthographic_scale)
    else:
        info["focal_length"] = float(camera.focal_length)
        info["sensor_width"] = float(camera.sensor_width)
        info["field_of_view"] = float(camera.field_of_view)
        info["intrinsics_pixels"] = geo.pixel_intrinsics(camera, resolution)
        lens = geo.lens_of(camera)
        info["distortion_model"] = lens.name
        info["distortion_coefficients"] = np.pad(np.asarray(lens.coefficients, np.float64),
                                                 (0, 8 - len(lens.coefficients)))
    info.update(extra)
    return info


def _to_opencv(camera, frame) -> np.ndarray:
    """(4, 4) world → OpenCV camera (x right, y down, looking down +z) at ``frame``."""
    out = geo.world_to_camera(camera, frame)
    out[:3] = geo.CAMERA_TO_OPENCV @ out[:3]
    return out


def bboxes_3d_over_time(asset, frames: Sequence[float]) -> np.ndarray:
    """(T, 8, 3) world corners of the asset's scaled local bounds at each frame (corner order of
    :attr:`PhysicalObject.bbox_3d`)."""
    corners = []
    for frame in frames:
        with asset.at_frame(frame):
            corners.append(asset.bbox_3d)
    return np.asarray(corners, dtype=np.float32).reshape(len(frames), 8, 3)


def get_instance_info(scene, assets_subset: Sequence | None = None,
                      frames: Sequence[float] | None = None) -> list[dict]:
    """Per-instance metadata, one dict per asset of ``assets_subset`` (default: the scene's
    foreground objects with geometry — lights and cameras are not instances), in that order.
    An explicit subset may only hold :class:`~kubric.core.objects.PhysicalObject` s.

    Each dict starts from a copy of ``asset.metadata`` (recipe extras such as ``shape``,
    ``color_label`` and the ``visibility`` / ``bboxes`` / ``bbox_frames`` set by the
    segmentation annotations) and adds ``asset_id`` (or the uid when the asset has none),
    ``mass``, ``friction``, ``restitution``, ``positions`` (T,3), ``quaternions`` (T,4 WXYZ),
    ``velocities`` (T,3) (a deformable's: those of its simulated nodes' centroid,
    :meth:`~kubric.core.deformables.Deformable.centroid_motion`; its quaternions and angular
    velocities stay its rest pose's), ``angular_velocities`` (T,3), ``image_positions`` (T,2 normalised
    (x, y), y down, projected at each frame's camera pose) and ``bboxes_3d`` (T,8,3).
    """
    if assets_subset is None:
        assets = [a for a in scene.foreground_assets if isinstance(a, PhysicalObject)]
    else:
        assets = list(assets_subset)
        wrong = [a.uid for a in assets if not isinstance(a, PhysicalObject)]
        if wrong:
            raise TypeError(f"get_instance_info: {wrong} are not PhysicalObjects (instances have "
                            "mass, bounds and a trajectory)")
    frames = _frames(scene, frames)
    camera = scene.camera
    infos = []
    for asset in assets:
        info = dict(asset.metadata)
        info["asset_id"] = getattr(asset, "asset_id", "") or asset.uid
        for name in ("mass", "friction", "restitution"):
            info[name] = float(getattr(asset, name))
        positions = asset.get_values_over_time("position", frames)
        info["positions"] = positions
        info["quaternions"] = asset.get_values_over_time("quaternion", frames)
        info["velocities"] = asset.get_values_over_time("velocity", frames)
        if isinstance(asset, Deformable):  # its simulated mesh's centroid, not its rest pose
            centroids, velocities = asset.centroid_motion(frames, scene.frame_rate)
            positions = centroids.astype(positions.dtype)
            info["positions"] = positions
            info["velocities"] = velocities.astype(info["velocities"].dtype)
        info["angular_velocities"] = asset.get_values_over_time("angular_velocity", frames)
        info["image_positions"] = np.array(
            [geo.project_points(camera, p, f, scene.resolution)[:2]
             for f, p in zip(frames, positions, strict=True)], dtype=np.float32).reshape(-1, 2)
        info["bboxes_3d"] = bboxes_3d_over_time(asset, frames)
        infos.append(info)
    return infos


def process_collisions(collisions: Sequence[dict], scene,
                       assets_subset: Sequence | None = None) -> list[dict]:
    """Collision events for ``events.json``.

    Args:
      collisions: simulator events ``{"instances": (asset_a, asset_b), "frame": float, "force":
        float, "position": (3,), "contact_normal": (3,)}``; ``frame`` is a scene frame number
        (fractional for sub-steps).
      assets_subset: the instance list (default: the scene's foreground assets).

    Returns:
      one dict per event: ``instances`` [i, j] (index into the instance list, −1 for anything
      else, e.g. the floor), ``frame``, ``force``, ``position``, ``contact_normal`` and
      ``image_position`` (normalised (x, y), projected with the camera pose *at the event's
      frame*).
    """
    assets = list(scene.foreground_assets if assets_subset is None else assets_subset)
    index = {id(a): i for i, a in enumerate(assets)}
    events = []
    for c in collisions:
        missing = {"instances", "frame", "force", "position", "contact_normal"} - set(c)
        if missing:
            raise KeyError(f"collision event {c!r} lacks {sorted(missing)}")
        a, b = c["instances"]
        frame = float(c["frame"])
        position = np.asarray(c["position"], dtype=np.float64).reshape(3)
        uv = geo.project_points(scene.camera, position, frame, scene.resolution)
        events.append({
            "instances": [index.get(id(a), -1), index.get(id(b), -1)],
            "frame": frame,
            "force": float(c["force"]),
            "position": position.astype(np.float32),
            "contact_normal": np.asarray(c["contact_normal"], dtype=np.float32).reshape(3),
            "image_position": uv[:2].astype(np.float32),
        })
    return events
