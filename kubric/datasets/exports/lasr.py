"""Export a scene directory as a LASR / ViSER video sequence (the ``DAVIS`` folder layout):
``kubric export lasr SCENE --out DIR``; the ``vbr`` recipe writes one into every scene's ``lasr/``.

LASR (Yang et al., CVPR 2021, "Learning Articulated Shape Reconstruction from a Monocular Video")
and its successor ViSER read one video as ``database/DAVIS/<Kind>/Full-Resolution/<seq>/`` plus a
config file ``configs/<seq>.config``. :func:`export_lasr` writes that tree from a scene's layers
and ``metadata.json``::

    OUT/DAVIS/JPEGImages/Full-Resolution/SEQ/{i:05d}.jpg     RGB (JPEG, quality 95)
    OUT/DAVIS/Annotations/Full-Resolution/SEQ/{i:05d}.png    silhouette: 8-bit grey, 128 = object
    OUT/DAVIS/FlowFW/Full-Resolution/SEQ/flo-{i:05d}.pfm     flow frame i → i+1 (i = 0 .. T−2)
    OUT/DAVIS/FlowFW/Full-Resolution/SEQ/occ-{i:05d}.pfm     its occlusion map
    OUT/DAVIS/FlowBW/Full-Resolution/SEQ/flo-{i:05d}.pfm     flow frame i → i−1 (i = 1 .. T−1)
    OUT/DAVIS/FlowBW/Full-Resolution/SEQ/occ-{i:05d}.pfm
    OUT/DAVIS/Cameras/Full-Resolution/SEQ/{i:05d}.txt        object → camera [R|T] and intrinsics
    OUT/DAVIS/CamerasWorld/Full-Resolution/SEQ/{i:05d}.txt   world → camera (an addition)
    OUT/configs/SEQ.config                                   the loader's config ([data], [meta])
    OUT/export.json                                          what was exported, with conventions
                                                             and ``licenses``: every asset the
                                                             images show and its licence

Camera rigs (``cameras=stereo|ring|random``): LASR reads one monocular video, so the export
takes one camera of the rig, ``camera=C`` (``--camera C``; default 0, the reference camera): its
RGB, segmentation, depth and flow layers (``NAME_*``), its intrinsics and its per-frame
extrinsics (``metadata.camera.rig.views[NAME]``); ``export.json`` records ``camera`` (the index)
and ``camera_name``. An index outside ``0 .. number of cameras − 1`` is one line naming it and
that range (exit status 2).

Conventions (what LASR's loaders expect; ours are in docs/conventions.md):

* **Flow** ``flo-*.pfm``: 3-channel PFM ``(Δx, Δy, valid)`` in pixels, x to the right (columns),
  y down (rows). Our flow layers are ``(Δrow, Δcol)``, so ``Δx = flow[..., 1]`` and
  ``Δy = flow[..., 0]``; the values are the scene's flow layer unchanged (no resampling). ``valid``
  is 1 where the pixel's ray hits a surface that is visible in the other frame, else 0.
* **Occlusion** ``occ-*.pfm``: 1-channel PFM, 1 where the surface point seen at the pixel is
  *not* visible at its flow target in the other frame (it leaves the image, another surface or
  another instance covers it), 0 where it is visible or no surface is hit. Decided from the
  layers alone by :func:`flow_occlusion`: a forward-backward consistency check (the backward
  flow at the target pixel must bring the point back: |f + b|² ≤ 0.01 (|f|² + |b|²) + 0.5, the
  rule of Sundaram et al. 2010) plus the segmentation label at the target. LASR's loader treats
  a pixel as valid when ``valid ≠ 0`` and ``occ < 10``.
* **Silhouette**: 128 where the segmentation shows one of the exported instances, 0 elsewhere
  (LASR reads it with OpenCV as grey, takes values > 0 as the object and 255 as an occluder).
* **Cameras** (``[R_3x3 | T_3x1]`` in rows 1–3, ``[fx, fy, px, py]`` in row 4, pixels): OpenCV
  axes (x right, y down, looking down +z), ``X_cam = R · X + T`` and the pixel is
  ``(fx · x / z + px, fy · y / z + py)`` with **pixel centres at integer coordinates** (pixel
  (row r, col c) is centred at (c, r), as LASR's flow warping uses), so ``px = cx − 0.5`` of our
  ``intrinsics_pixels`` (whose centres are at +0.5). In ``Cameras`` X is a point in the **root
  object's frame** (metres, the object's axes, origin at its ``position``): LASR's camera is the
  root body's pose relative to the camera. In ``CamerasWorld`` X is a world point.
"""

from __future__ import annotations

import io
import os
import pathlib
import shutil

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core.lenses import pinhole_refusal
from kubric.core.quaternion import Quaternion
from kubric.datasets.exports import licences
from kubric.datasets.exports.scenes import Scene, camera_views
from kubric.errors import InputError, UsageError
from kubric.io import json_io, png_io
from kubric.io.paths import atomic_write_bytes
from kubric.io.pfm_io import encode_pfm
from kubric.io.scene_dir import METADATA_FILE

FULL = "Full-Resolution"
SILHOUETTE_VALUE = 128
JPEG_QUALITY = 95
#: forward-backward consistency (Sundaram et al. 2010): |f + b|² ≤ A (|f|² + |b|²) + B
FB_ALPHA, FB_BETA = 0.01, 0.5
KINDS = ("JPEGImages", "Annotations", "FlowFW", "FlowBW", "Cameras", "CamerasWorld")


def lasr_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 ``(Δx, Δy, valid)`` from our (H, W, 2) ``(Δrow, Δcol)`` flow and a
    (H, W) boolean validity mask."""
    flow = np.asarray(flow, np.float32)
    return np.stack([flow[..., 1], flow[..., 0], np.asarray(valid, np.float32)], axis=-1)


def flow_targets(flow: np.ndarray):
    """Nearest target pixel (row, col) of every pixel and whether it lies inside the image:
    pixel (r, c) (centre (r + 0.5, c + 0.5)) moves to ``centre + flow``."""
    h, w = flow.shape[:2]
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    tr = rows + 0.5 + flow[..., 0]
    tc = cols + 0.5 + flow[..., 1]
    inside = (tr >= 0) & (tr < h) & (tc >= 0) & (tc < w)
    return (np.clip(np.floor(tr), 0, h - 1).astype(np.int64),
            np.clip(np.floor(tc), 0, w - 1).astype(np.int64), inside)


def flow_occlusion(flow: np.ndarray, flow_back: np.ndarray, labels: np.ndarray,
                   labels_other: np.ndarray, hit: np.ndarray, hit_other: np.ndarray) -> np.ndarray:
    """(H, W) bool: the surface seen at a pixel is not visible at its flow target in the other
    frame. ``flow``: (H, W, 2) (Δrow, Δcol) to the other frame; ``flow_back``: the other frame's
    flow back to this one; ``labels`` / ``labels_other``: (H, W) segmentation of both frames;
    ``hit`` / ``hit_other``: (H, W) where a ray hits a surface. Occluded = hit and (target
    outside the image, or the target pixel hits nothing or another label, or the
    forward-backward check fails). Pixels that hit nothing are never occluded."""
    flow = np.asarray(flow, np.float64)
    back = np.asarray(flow_back, np.float64)
    tr, tc, inside = flow_targets(flow)
    b = back[tr, tc]
    err = np.sum((flow + b) ** 2, axis=-1)
    bound = FB_ALPHA * (np.sum(flow ** 2, axis=-1) + np.sum(b ** 2, axis=-1)) + FB_BETA
    same = hit_other[tr, tc] & (labels_other[tr, tc] == labels)
    return hit & ~(inside & same & (err <= bound))


def opencv_world_to_camera(matrix_world: np.ndarray) -> np.ndarray:
    """(4, 4) world → camera in OpenCV axes from a camera → world matrix in Blender axes."""
    m = np.asarray(matrix_world, np.float64)
    out = np.eye(4)
    out[:3, :3] = geo.CAMERA_TO_OPENCV @ m[:3, :3].T
    out[:3, 3] = -out[:3, :3] @ m[:3, 3]
    return out


def pose_matrix(position, quaternion) -> np.ndarray:
    """(4, 4) object → world rigid transform (no scale) from a position and a WXYZ quaternion."""
    out = np.eye(4)
    out[:3, :3] = Quaternion(np.asarray(quaternion, np.float64)).rotation_matrix
    out[:3, 3] = np.asarray(position, np.float64)
    return out


def rtk_matrix(to_camera: np.ndarray, intrinsics_pixels: np.ndarray) -> np.ndarray:
    """LASR's 4×4 camera file: rows 1–3 ``[R | T]`` of ``to_camera`` (OpenCV axes), row 4
    ``[fx, fy, px, py]`` with pixel centres at integer coordinates."""
    k = np.asarray(intrinsics_pixels, np.float64)
    out = np.zeros((4, 4))
    out[:3] = np.asarray(to_camera, np.float64)[:3]
    out[3] = [k[0, 0], k[1, 1], k[0, 2] - 0.5, k[1, 2] - 0.5]
    return out


def project_rtk(rtk: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(..., 2) pixel (x, y) of points (..., 3) under a LASR camera (integer pixel centres)."""
    rtk = np.asarray(rtk, np.float64)
    cam = np.asarray(points, np.float64) @ rtk[:3, :3].T + rtk[:3, 3]
    fx, fy, px, py = rtk[3]
    return np.stack([fx * cam[..., 0] / cam[..., 2] + px, fy * cam[..., 1] / cam[..., 2] + py],
                    axis=-1)


def default_root(instances: list[dict], chosen: list[int]) -> int:
    """The instance whose frame the ``Cameras`` files use: the only chosen one, or the only
    chosen one that is not a link of an articulated object (no ``articulated_link`` key)."""
    if len(chosen) == 1:
        return chosen[0]
    roots = [k for k in chosen if "articulated_link" not in instances[k]]
    if len(roots) != 1:
        raise InputError(f"cannot tell the root object among instances {chosen} "
                         f"({len(roots)} are not articulated links): pass root=")
    return roots[0]


def config_text(sequence: str) -> str:
    """``configs/<sequence>.config`` as LASR / ViSER read it."""
    block = (f"datapath = database/DAVIS/JPEGImages/{FULL}/{sequence}/\n"
             "dframe = 1\ninit_frame = 0\nend_frame = -1\ncan_frame = -1\n")
    return f"[data]\n{block}\n[data_0]\n{block}sym_angle = 0\n\n[meta]\nnumvid = 1\n"


def _jpeg(rgb: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, np.uint8), "RGB").save(
        buf, format="JPEG", quality=JPEG_QUALITY)
    return buf.getvalue()


def _savetxt(matrix: np.ndarray) -> bytes:
    return "".join(" ".join(f"{v:.10g}" for v in row) + "\n" for row in matrix).encode()


def camera_view(scene_dir: pathlib.Path, camera) -> Scene:
    """Camera ``camera`` (an index, 0 = the reference) of the scene as a
    :class:`~kubric.datasets.exports.scenes.Scene` reading that camera's layers and records;
    one line naming the index and the allowed range when the scene has no such camera."""
    scene = Scene(scene_dir, "", json_io.read_json(scene_dir / METADATA_FILE))
    rig = scene.metadata["camera"].get("rig") or {}
    names = rig.get("cameras") or ["the scene's camera"]
    if isinstance(camera, bool) or not isinstance(camera, (int, np.integer)) \
            or not 0 <= camera < len(names):
        raise UsageError(f"export_lasr: camera {camera!r} is not a camera of this scene; "
                         f"allowed: 0..{len(names) - 1} ({', '.join(names)})")
    return camera_views(scene)[int(camera)] if rig else scene


def export_lasr(scene_dir, out_dir, sequence: str | None = None,
                instances: list[int] | None = None, root: int | None = None,
                camera: int = 0) -> dict:
    """Write the LASR tree (module doc) for the scene directory ``scene_dir`` into ``out_dir``.

    Args:
      scene_dir: a scene directory with rgba, depth, segmentation, forward_flow, backward_flow
        and metadata.json.
      out_dir: a folder that does not exist yet (written through a temporary sibling, then
        renamed: it appears complete or not at all).
      sequence: the sequence name (default ``<recipe>_<seed:08d>`` from the flags).
      instances: indices (0-based) into ``metadata.json["instances"]`` that make the object
        (silhouette); default: every instance.
      root: the instance whose frame ``Cameras`` uses (default :func:`default_root`).
      camera: the camera of a camera-rig scene whose images, layers and cameras are exported
        (its index in ``metadata.camera.rig.cameras``; 0 = the reference camera, the one
        camera of a one-camera scene).

    Returns the content of ``export.json``.
    """
    scene_dir, out_dir = pathlib.Path(scene_dir), pathlib.Path(out_dir)
    if out_dir.exists():
        raise FileExistsError(f"export_lasr: {str(out_dir)!r} already exists")
    view = camera_view(scene_dir, camera)
    meta = view.metadata
    refusal = pinhole_refusal(meta["camera"], "export_lasr: LASR's [fx, fy, px, py] camera")
    if refusal:
        raise InputError(refusal)
    infos = meta["instances"]
    chosen = list(range(len(infos))) if instances is None else [int(k) for k in instances]
    bad = [k for k in chosen if not 0 <= k < len(infos)]
    if bad or not chosen:
        raise InputError(f"export_lasr: instances {chosen} must be 1 or more of 0..{len(infos) - 1}")
    root = default_root(infos, chosen) if root is None else int(root)
    if root not in chosen:
        raise InputError(f"export_lasr: root {root} is not one of the instances {chosen}")
    flags = meta.get("flags", {})
    if sequence is None:
        sequence = f"{flags['recipe']}_{int(flags['seed']):08d}" if "recipe" in flags \
            else scene_dir.name
    if not sequence or any(c in sequence for c in "/\\\0") or sequence in (".", ".."):
        raise InputError(f"export_lasr: sequence name {sequence!r} is not a folder name")
    data = {name: view.read_layer(name) for name in ("rgba", "depth", "segmentation",
                                                     "forward_flow", "backward_flow")}
    labels = data["segmentation"][..., 0].astype(np.int64)
    hit = data["depth"][..., 0] < geo.BACKGROUND_DEPTH
    fw, bw = data["forward_flow"], data["backward_flow"]
    cam = meta["camera"]
    k_pix = np.asarray(cam["intrinsics_pixels"], np.float64)
    count = labels.shape[0]
    silhouette = np.isin(labels, np.asarray(chosen) + 1)

    tmp = out_dir.with_name(f".{out_dir.name}.incomplete-{os.getpid()}")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        def folder(kind: str) -> pathlib.Path:
            return tmp / "DAVIS" / kind / FULL / sequence

        for i in range(count):
            atomic_write_bytes(_jpeg(data["rgba"][i, ..., :3]), folder("JPEGImages") / f"{i:05d}.jpg")
            mask = (silhouette[i] * SILHOUETTE_VALUE).astype(np.uint8)[..., None]
            atomic_write_bytes(png_io.encode_png(mask), folder("Annotations") / f"{i:05d}.png")
            world = opencv_world_to_camera(cam["matrices_world"][i])
            pose = pose_matrix(infos[root]["positions"][i], infos[root]["quaternions"][i])
            atomic_write_bytes(_savetxt(rtk_matrix(world @ pose, k_pix)), folder("Cameras") / f"{i:05d}.txt")
            atomic_write_bytes(_savetxt(rtk_matrix(world, k_pix)), folder("CamerasWorld") / f"{i:05d}.txt")
        occluded = {}
        for kind, flows, back, step in (("FlowFW", fw, bw, 1), ("FlowBW", bw, fw, -1)):
            frames = range(count - 1) if step == 1 else range(1, count)
            for i in frames:
                j = i + step
                occ = flow_occlusion(flows[i], back[j], labels[i], labels[j], hit[i], hit[j])
                occluded[(kind, i)] = int(occ.sum())
                atomic_write_bytes(encode_pfm(lasr_flow(flows[i], hit[i] & ~occ)),
                      folder(kind) / f"flo-{i:05d}.pfm")
                atomic_write_bytes(encode_pfm(occ.astype(np.float32)), folder(kind) / f"occ-{i:05d}.pfm")
        atomic_write_bytes(config_text(sequence).encode(), tmp / "configs" / f"{sequence}.config")
        summary = {
            "sequence": sequence, "num_frames": int(count),
            "resolution": [int(labels.shape[2]), int(labels.shape[1])],
            "instances": chosen, "root_instance": root, "camera": int(camera),
            **({"camera_name": view.camera_name} if view.camera_name else {}),
            "silhouette_value": SILHOUETTE_VALUE, "jpeg_quality": JPEG_QUALITY,
            "occluded_pixels": {"FlowFW": [occluded[("FlowFW", i)] for i in range(count - 1)],
                                "FlowBW": [occluded[("FlowBW", i)] for i in range(1, count)]},
            "conventions": "flo-*.pfm: (dx, dy, valid) px, x right, y down (ours: (drow, dcol)); "
                           "occ-*.pfm: 1 = not visible at the flow target; Cameras: root "
                           "object -> camera, CamerasWorld: world -> camera, OpenCV axes, rows "
                           "[R|T] then [fx, fy, px, py], pixel centres at integers",
            licences.KEY: licences.as_json(licences.scene_licences(meta)),
        }
        json_io.write_json(summary, tmp / "export.json")
        os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return summary

