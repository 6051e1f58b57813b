"""The NeRF export: "blender" ``transforms_{split}.json`` files, written by the multi-view recipes
into every scene and copied with the views they name by ``kubric export nerf`` (:func:`export_nerf`);
for a video scene (one camera or a camera rig), one nerfstudio / D-NeRF ``transforms.json`` of
every (camera, frame) image (:func:`video_transforms`, "Video scenes" below).

Every multi-view scene is one render whose frames are the views (view ``i`` = frame
``frame_start + i`` = the files ``*_{i:05d}.*``). The views are split into ``train`` / ``val`` /
``test`` by :func:`view_splits`, a deterministic function of the view index and the recipe's
``split_ratio`` option, and each split gets one file ``transforms_{split}.json`` beside the
scene's images, readable unchanged by the original NeRF code, instant-ngp and nerfstudio:

* ``camera_angle_x``: horizontal field of view (radians), as the NeRF "blender" loader reads it;
  ``camera_angle_y`` likewise vertically;
* ``fl_x``, ``fl_y``, ``cx``, ``cy``, ``w``, ``h``: pinhole intrinsics in pixels as instant-ngp and
  nerfstudio read them (origin at the top-left image corner, pixel (row r, col c) centred at
  ``(c + 0.5, r + 0.5)``, so ``cx = w / 2`` for an unshifted camera);
* the lens, nerfstudio's fields: ``camera_model`` ``OPENCV`` with ``k1``, ``k2``, ``k3``,
  ``p1``, ``p2`` (OpenCV's Brown–Conrady; all 0 for a pinhole camera) or ``OPENCV_FISHEYE`` with
  ``k1`` … ``k4`` (OpenCV's fisheye) — :mod:`kubric.core.lenses`; a rational lens (k4–k6 of
  Brown–Conrady) has no nerfstudio model and is refused;
* ``frames``: one entry per view of the split, in view order, with ``file_path`` (the RGBA image
  without its ``.png`` extension, relative to the JSON file: ``./rgba_00007``, as in the NeRF
  "blender" data sets, whose loaders append ``.png``), ``transform_matrix`` (4×4 camera → world,
  Blender camera axes: x right, y up, looking down −z — the NeRF / OpenGL convention), and our
  per-view additions: ``view`` (index), ``frame`` (scene frame), ``split``, and the file names of the
  view's other layers (``depth_file``, ``segmentation_file``, ...: see each recipe).

Reading a pixel's ray from the JSON alone (what the tests do): for pixel (row i, col j),
``d_cam = ((j + 0.5 − cx) / fl_x, −(i + 0.5 − cy) / fl_y, −1)``, ``d = R · d_cam / |d_cam|`` with
``R = transform_matrix[:3, :3]``, origin ``transform_matrix[:3, 3]`` (with a lens, ``d_cam``
comes from undistorting the pixel with the recorded coefficients, as ``cv2.undistortPoints``);
the surface point is ``origin + depth[i, j] · d`` (depth is the Euclidean distance to the camera centre).
:func:`iter_views` does exactly this for every view of a split (rays, RGB and depth per view).

Video scenes (MOVi, ``pose_estimation``, ``vbr``, ...; ``cameras=mono|stereo|ring|random``):
``kubric export nerf`` writes ``OUT/SCENE/transforms.json`` as nerfstudio's ``nerfstudio-data``
parser reads it, with D-NeRF's ``time``, and copies the files it names:

* ``frames``: every (camera, frame) image, camera by camera in rig order (``cameras``, the
  reference first), each with ``file_path`` **with** its extension (``./cam1_rgba_00003.png``,
  as nerfstudio opens it), ``transform_matrix`` (camera → world, NeRF / OpenGL axes as above:
  ``metadata.json``'s ``matrices_world`` of that camera at that frame), ``time`` =
  ``frame / (T − 1)`` in [0, 1] (D-NeRF; 0 for one frame), our ``camera`` (index in
  ``cameras``; 0 for a one-camera scene), ``camera_name`` (rigs only) and ``frame`` (0-based, the
  files' index), and ``depth_file`` / ``segmentation_file`` (our float TIFF of the Euclidean
  distance in metres along the pixel's ray — not nerfstudio's ``depth_file_path``, which holds
  z-depth in millimetres — and our label PNG);
* the camera fields above (``fl_x`` … ``h``, ``camera_angle_x/y``, ``k1`` … ``p2``) from each
  camera's ``intrinsics_pixels``, ``distortion_model`` and ``distortion_coefficients``, grouped
  as nerfstudio reads them (:data:`FIELD_GROUPS`): a group every camera shares is written once at
  the top level, a group where cameras differ goes into every frame (nerfstudio takes a frame's
  value only when the top level lacks the field); ``camera_model`` is top-level only in
  nerfstudio, so a rig whose cameras have different models is refused in one line, as is a
  Brown–Conrady lens with k4–k6 (no nerfstudio model: one line naming the coefficients);
* top level also: ``cameras`` (the rig's camera names; ``[]`` for one camera), ``num_frames``,
  ``frame_rate``, ``conventions`` and ``licenses``.
"""

from __future__ import annotations

import json
import math
import os
import pathlib
import shutil
from collections.abc import Mapping, Sequence

import numpy as np

from kubric.core import camera_geometry as geo
from kubric.core import lenses
from kubric.datasets.exports import licences
from kubric.datasets.exports.scenes import ExportError, camera_views, load_scene
from kubric.errors import InputError
from kubric.io import layers as layer_io
from kubric.io import png_io, tiff_io
from kubric.io import scene_dir as scene_dirs
from kubric.io.schema import VIEW_SPLITS
from kubric.io.stored_schema import stored_schema

SPLITS = VIEW_SPLITS  # declared with the schema conversion that indexes them
#: the transforms file of an exported video scene (nerfstudio's name)
VIDEO_TRANSFORMS = "transforms.json"
#: the layers whose files a video scene's frame entries name (``depth_file``, ...) when present
VIDEO_LAYERS = ("depth", "segmentation")
#: the camera fields of a video transforms file, grouped as nerfstudio reads them: a group goes
#: to the top level when every camera has the same values, else into every frame (nerfstudio
#: takes a field from the frames only when the top level lacks it; any one of the distortion
#: fields at the top level fixes them all)
FIELD_GROUPS = (("fl_x", "camera_angle_x"), ("fl_y", "camera_angle_y"), ("cx",), ("cy",),
                ("w",), ("h",), ("k1", "k2", "k3", "k4", "p1", "p2"))
VIDEO_CONVENTIONS = ("transform_matrix: camera -> world, NeRF / OpenGL camera axes (x right, y "
                     "up, looking down -z), metres; fl_x, fl_y, cx, cy pixels, pixel centres at "
                     "+0.5; k1..k4, p1, p2: OpenCV's order (camera_model OPENCV or "
                     "OPENCV_FISHEYE); time = frame / (num_frames - 1); depth_file: float "
                     "TIFF, metres along the pixel's ray (not z); camera: index in cameras "
                     "(0 = the reference)")


def split_ratio(value) -> tuple[int, int, int]:
    """Converter for the ``split_ratio`` option: three integers ``train,val,test`` ≥ 0 with a
    positive train weight, e.g. ``"8,1,1"`` or ``(8, 1, 1)``."""
    if isinstance(value, str):
        value = value.replace(":", ",").split(",")
    try:
        parts = [int(str(v).strip()) for v in value]
    except (TypeError, ValueError):
        raise InputError("expected three integers train,val,test") from None
    if len(parts) != 3 or min(parts) < 0 or parts[0] < 1:
        raise InputError("expected three integers train,val,test ≥ 0 with train ≥ 1")
    return tuple(parts)


split_ratio.allowed = "three integers train,val,test (train ≥ 1, others ≥ 0), e.g. 8,1,1"


def view_splits(num_views: int, ratio: Sequence[int]) -> list[str]:
    """The split of every view: view ``v`` at position ``p = v mod (a + b + c)`` of the ratio
    ``a:b:c`` is ``train`` for ``p < a``, ``val`` for ``a ≤ p < a + b``, else ``test`` (so the
    held-out views are spread evenly over the view sequence, e.g. an orbit)."""
    a, b, c = (int(v) for v in ratio)
    period = a + b + c
    out = []
    for v in range(int(num_views)):
        p = v % period
        out.append("train" if p < a else "val" if p < a + b else "test")
    return out


def min_views_for(ratio: Sequence[int]) -> int:
    """The fewest views for which every split with a positive weight gets at least one view."""
    a, b, c = (int(v) for v in ratio)
    return a + b + 1 if c else a + 1 if b else 1


def check_views(recipe: str, num_views: int, ratio: Sequence[int]) -> str | None:
    """A one-line message when ``num_views`` cannot fill every split of ``ratio``, else None."""
    need = min_views_for(ratio)
    if num_views < need:
        named = ",".join(str(v) for v in ratio)
        return (f"{recipe}: option num_views={num_views} is too few for split_ratio={named}: "
                f"every split with a positive weight needs a view, so at least {need} views "
                "(raise num_views or set a split weight to 0)")
    return None


def intrinsics_entry(camera, resolution) -> dict:
    """The shared camera fields of a transforms file (see module doc)."""
    w, h = (int(v) for v in resolution)
    return pixel_fields(geo.pixel_intrinsics(camera, (w, h)), w, h, geo.lens_of(camera))


def pixel_fields(intrinsics_pixels, w: int, h: int, lens) -> dict:
    """The camera fields of a transforms file (see module doc) from numbers: OpenCV pixel
    intrinsics (3, 3; pixel centres at +0.5), the image size ``w`` × ``h`` (pixels) and ``lens``
    (:mod:`kubric.core.lenses`)."""
    k = np.asarray(intrinsics_pixels, np.float64)
    fl_x, fl_y, cx, cy = float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2])
    return {
        "camera_angle_x": 2.0 * math.atan(0.5 * w / fl_x),
        "camera_angle_y": 2.0 * math.atan(0.5 * h / fl_y),
        "fl_x": fl_x, "fl_y": fl_y, "cx": cx, "cy": cy, "w": int(w), "h": int(h),
        **lens_entry(lens),
    }


def lens_entry(lens) -> dict:
    """nerfstudio's distortion fields of ``lens`` (see module doc)."""
    if isinstance(lens, lenses.Fisheye):
        return {**{f"k{i}": float(v) for i, v in enumerate(lens.coefficients, 1)},
                "camera_model": "OPENCV_FISHEYE"}
    k1, k2, p1, p2, k3, k4, k5, k6 = lens.coefficients if not lens.is_pinhole else (0.0,) * 8
    if k4 or k5 or k6:
        raise InputError(f"NeRF transforms: nerfstudio's OPENCV model has no k4..k6, got "
                         f"{[k4, k5, k6]} (use k1, k2, p1, p2, k3 only)")
    entry = {"k1": k1, "k2": k2, "p1": p1, "p2": p2, "camera_model": "OPENCV"}
    return {**entry, "k3": k3} if k3 else entry


def lens_of_entry(data: Mapping):
    """The lens of a transforms file's fields (the inverse of :func:`lens_entry`)."""
    get = [float(data.get(k, 0.0)) for k in ("k1", "k2", "p1", "p2", "k3", "k4")]
    if data.get("camera_model", "OPENCV") == "OPENCV_FISHEYE":
        return lenses.Fisheye(get[0], get[1], get[4], get[5])
    return lenses.BrownConrady(*get[:5])


def nerf_transforms(camera, frames: Sequence[int], resolution, splits: Sequence[str],
                    view_files: Mapping[str, str] | None = None,
                    extra: Mapping[str, object] | None = None) -> dict[str, dict]:
    """``{split: transforms dict}`` for the views ``frames`` (view ``i`` = ``frames[i]``).

    Args:
      camera: the (keyframed) scene camera.
      frames: scene frame of each view.
      resolution: (width, height).
      splits: split name of each view (:func:`view_splits`).
      view_files: ``{key: file template}`` added to every frame entry formatted with the view index,
        e.g. ``{"depth_file": "depth_{:05d}.tiff"}``.
      extra: fields added at the top level of every file (e.g. ``split_ratio``).
    """
    if len(frames) != len(splits):
        raise InputError(f"nerf_transforms: {len(frames)} frames but {len(splits)} split names")
    unknown = sorted(set(splits) - set(SPLITS))
    if unknown:
        raise InputError(f"nerf_transforms: unknown split(s) {unknown}; allowed: {list(SPLITS)}")
    shared = intrinsics_entry(camera, resolution)
    out = {s: {**shared, **dict(extra or {}), "split": s, "frames": []} for s in SPLITS}
    matrices = geo.camera_to_world_matrices(camera, list(frames))
    for view, (frame, split) in enumerate(zip(frames, splits, strict=True)):
        entry = {"file_path": f"./rgba_{view:05d}",
                 "transform_matrix": matrices[view].tolist(),
                 "view": view, "frame": int(frame), "split": split}
        for key, template in dict(view_files or {}).items():
            entry[key] = template.format(view)
        out[split]["frames"].append(entry)
    return out


def pixel_rays_from_transforms(data: Mapping, entry: Mapping):
    """(origins (H, W, 3), unit directions (H, W, 3)) of every pixel-centre ray of one frame
    entry of a transforms file, built from the file's fields alone (see module doc)."""
    w, h = int(data["w"]), int(data["h"])
    k = [[data["fl_x"], 0.0, data["cx"]], [0.0, data["fl_y"], data["cy"]], [0.0, 0.0, 1.0]]
    lens = lens_of_entry(data)
    return geo.pinhole_rays(k, entry["transform_matrix"], geo.pixel_centres(h, w),
                            None if lens == lenses.BrownConrady() else lens)


def iter_views(scene_dir, split: str = "train"):
    """Yield one dict per view of ``split`` of a multi-view scene directory: ``view``, ``rgb``
    (H, W, 3) uint8, ``depth`` (H, W) metres, ``origins`` / ``directions`` (H, W, 3) world rays and
    ``transform_matrix`` (4, 4) — what a NeRF data loader needs, from the files alone."""
    if split not in SPLITS:
        raise InputError(f"iter_views: unknown split {split!r}; allowed: {list(SPLITS)}")
    scene_dir = pathlib.Path(scene_dir)
    data = read_transforms(scene_dir, split, "iter_views")
    for entry in data["frames"]:
        origins, directions = pixel_rays_from_transforms(data, entry)
        rgb = png_io.read_png(scene_dir / (entry["file_path"] + ".png"))[..., :3]
        depth = tiff_io.read_tiff(scene_dir / entry["depth_file"])[..., 0]
        yield {"view": int(entry["view"]), "rgb": rgb, "depth": depth, "origins": origins,
               "directions": directions,
               "transform_matrix": np.asarray(entry["transform_matrix"], np.float64)}


def read_transforms(scene_dir: pathlib.Path, split: str, who: str) -> dict:
    """The parsed ``transforms_{split}.json`` of a scene; FileNotFoundError (one line) naming it
    when the scene has none (not a multi-view scene)."""
    path = scene_dir / f"transforms_{split}.json"
    if not path.is_file():
        raise FileNotFoundError(f"{who}: {path} does not exist (not a multi-view scene: the "
                                "multi-view recipes write transforms_*.json)")
    return json.loads(path.read_text())


def view_files(data: Mapping) -> list[str]:
    """The files a transforms dict names: each view's RGBA PNG and its ``*_file`` layers."""
    out = []
    for entry in data["frames"]:
        image = entry["file_path"].removeprefix("./")
        out.append(image if image.endswith(".png") else image + ".png")  # video: with .png
        out += [v for k, v in sorted(entry.items()) if k.endswith("_file")]
    return out


def video_transforms(scene_path) -> dict:
    """The ``transforms.json`` dict of a video scene (one camera, or a camera rig): every
    (camera, frame) image of the scene, camera by camera in rig order (module doc, "Video
    scenes"). One-line :class:`~kubric.datasets.exports.scenes.ExportError` for a camera
    without pinhole intrinsics, a lens nerfstudio cannot express, or a rig whose cameras have
    different lens models."""
    scene_path = pathlib.Path(scene_path)
    scene = load_scene(scene_path, scene_path)
    views, count = camera_views(scene), scene.num_frames
    formats = views[0].formats
    if formats is None:
        stored = stored_schema(scene_path)
        formats = None if stored is None else stored.layers
    table = layer_io.layer_table(formats)
    rig = len(views) > 1
    fields = []
    for view in views:
        record, label = view.metadata["camera"], view.camera_name or "camera"
        if "intrinsics_pixels" not in record:
            raise ExportError(f"{scene_path.name}: {label} has no intrinsics_pixels in "
                              "metadata.json (NeRF transforms need a perspective camera)")
        w, h = record.get("resolution", scene.resolution)
        try:
            fields.append(pixel_fields(record["intrinsics_pixels"], w, h,
                                       lenses.from_camera_record(record)))
        except InputError as err:
            raise ExportError(f"{scene_path.name}: {label}: {err}") from None
    models = sorted({f["camera_model"] for f in fields})
    if len(models) > 1:
        raise ExportError(f"{scene_path.name}: the rig's cameras have the lens models {models}; "
                          "nerfstudio reads one camera_model per transforms file")
    shared, own = {"camera_model": models[0]}, [{} for _ in views]
    for group in FIELD_GROUPS:
        values = [{k: f[k] for k in group if k in f} for f in fields]
        if all(v == values[0] for v in values):
            shared.update(values[0])
        else:
            for mine, value in zip(own, values, strict=True):
                mine.update(value)
    frames = []
    for c, view in enumerate(views):
        matrices = np.asarray(view.metadata["camera"]["matrices_world"], np.float64)
        if matrices.shape != (count, 4, 4):
            raise ExportError(f"{scene_path.name}: camera {c} has matrices_world of shape "
                              f"{list(matrices.shape)}, expected [{count}, 4, 4]")
        for t in range(count):
            entry = {"file_path": "./" + _frame_file(table, view, "rgba", t, required=True),
                     "transform_matrix": matrices[t].tolist(),
                     "time": t / (count - 1) if count > 1 else 0.0,
                     "camera": c, **({"camera_name": view.camera_name} if rig else {}),
                     "frame": t, **own[c]}
            for layer in VIDEO_LAYERS:
                name = _frame_file(table, view, layer, t)
                if name:
                    entry[f"{layer}_file"] = name
            frames.append(entry)
    names = [v.camera_name for v in views] if rig else []
    return {**shared, "cameras": names, "num_frames": count,
            "frame_rate": scene.metadata["metadata"].get("frame_rate"),
            "conventions": VIDEO_CONVENTIONS, "frames": frames}


def _frame_file(table, view, layer: str, frame: int, required: bool = False) -> str | None:
    """The file name of ``frame`` of ``view``'s ``layer`` when the scene has it (else None, or a
    one-line error when ``required``)."""
    name = view.prefix + layer
    if name in table:
        file = layer_io.frame_filename(table[name].template, frame)
        if (view.path / file).is_file():
            return file
    if required:
        raise ExportError(f"{view.path.name}: no {layer} file of frame {frame}"
                          + (f" of camera {view.camera_name!r}" if view.camera_name else ""))
    return None


def export_nerf(root, out) -> tuple[pathlib.Path, int]:
    """Copy every complete scene under ``root`` (or ``root`` itself) into ``out/<scene name>/``:
    a multi-view scene's ``transforms_{train,val,test}.json``, a video scene's
    ``transforms.json`` (:func:`video_transforms`), each with the field ``licenses`` added
    (every asset the images show and its licence: :mod:`kubric.datasets.exports.licences`),
    and the files their frames name, nothing else (a folder NeRF, instant-ngp and nerfstudio
    read as it is). ``out`` must
    not exist; it is written through a temporary sibling and appears complete or not at all.
    Returns (out, number of scenes)."""
    scenes = scene_dirs.scenes_under(root)
    out = pathlib.Path(out)
    if out.exists():
        raise FileExistsError(f"{str(out)!r} already exists (choose a new folder)")
    tmp = out.with_name(f".{out.name}.incomplete-{os.getpid()}")
    try:
        for scene in scenes:
            (tmp / scene.name).mkdir(parents=True)
            assets = licences.as_json(licences.scene_licences(
                json.loads((scene / scene_dirs.METADATA_FILE).read_text())))
            multi_view = any((scene / f"transforms_{s}.json").exists() for s in SPLITS)
            files = {f"transforms_{split}.json": read_transforms(scene, split, scene.name)
                     for split in SPLITS} if multi_view else \
                {VIDEO_TRANSFORMS: video_transforms(scene)}
            for file, data in files.items():
                (tmp / scene.name / file).write_text(
                    json.dumps({**data, licences.KEY: assets}, indent=1) + "\n")
                for name in view_files(data):
                    shutil.copy2(scene / name, tmp / scene.name / name)
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out, len(scenes)
