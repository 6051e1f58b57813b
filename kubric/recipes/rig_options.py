"""The recipes' camera-rig options (``cameras``, ``baseline``, ``num_cameras``): several
synchronized cameras of one simulated scene (:mod:`kubric.core.rig`; docs/conventions.md).

* ``cameras=mono`` (default): one camera, the scene unchanged.
* ``cameras=stereo``: the recipe's camera is the **left** camera; a **right** one is mounted
  ``baseline`` metres along its +x (a rectified pinhole pair). Adds the ``disparity`` layer of
  the left image (pixels, :func:`kubric.annotations.rig_views.disparity`).
* ``cameras=ring``: ``num_cameras`` cameras ``cam0`` (the recipe's) … on a horizontal circle
  about the point of the recipe's camera's view axis nearest the world origin (MOVi's cameras
  look at the origin), each looking at it.
* ``cameras=random``: ``num_cameras`` cameras ``cam0`` (the recipe's) … at random about that same
  point (:func:`kubric.core.rig.random_rig`: distance 0.8–1.2 × the recipe camera's, elevation
  10°–70°, each looking at it), drawn with an rng of their own derived from the seed
  (:data:`RIG_STREAM`).

No random number is drawn from the scene's rng, so a rig scene's objects, lights and reference
camera are those of the mono scene of the same seed. Every further camera renders every layer
the reference does (the same backend, swapping ``scene.camera``); its files are the standard
ones prefixed with its name (``right_rgba_00000.png``, ``right_depth_00000.tiff``,
``tracks_right.npz`` …), its packed features the scene schema's prefixed with ``cameras/NAME/``
(``instances/cameras/NAME/`` for per-instance ones: visibility, boxes, image positions,
keypoints), its camera record under ``metadata.json["camera"]["rig"]["views"][NAME]``. Instances
are sorted by their visible pixels summed over the cameras; point tracks are the reference
camera's surface points seen by each camera (:func:`kubric.annotations.rig_views.view_tracks`).
"""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np

import kubric as kb
from kubric.annotations.keypoints import annotate_keypoints
from kubric.annotations.rig_views import check_rectified, disparity, view_instances, view_tracks
from kubric.annotations.segmentation import instance_labels, pixel_counts
from kubric.annotations.track_files import tracks_archive
from kubric.core import rig as rigs
from kubric.io.event_h5 import EVENTS_H5_FILE, events_file
from kubric.io.layers import LayerFormat
from kubric.io.scene_dir import TRACKS_FILE
from kubric.io.schema import Feature, Schema
from kubric.pipeline import Option, OptionError
from kubric.recipes import extra_layers as extra

RIGS = ("mono", "stereo", "ring", "random")
#: cameras=random: the rig's own rng is ``RandomState([seed, RIG_STREAM])``
RIG_STREAM = 0x72696721
#: metres between the stereo cameras when ``baseline`` is not given
DEFAULT_BASELINE = 0.5
#: per-instance fields each camera of a rig has its own of (``metadata["cameras"][NAME]``)
VIEW_INSTANCE_FIELDS = ("visibility", "bboxes", "bbox_frames", "image_positions",
                        "keypoints_2d", "keypoints_camera", "keypoints_depth",
                        "keypoints_visibility", "keypoint_occlusion_reason", "amodal_area",
                        "amodal_bboxes", "visible_fraction")
DISPARITY = Feature("disparity", "float32", ("T", "H", "W", 1), "layer:disparity", "zlib",
                    unit="px", doc="stereo: x_left − x_right of the surface point seen at the "
                    "left pixel centre (= f·B/Z for the rectified pair); 0 where nothing is hit")
BASELINE = Feature("camera/rig/baseline", "float32", (), "camera:rig.baseline", unit="m",
                   doc="stereo: distance between the left and right camera centres")
#: the rig's cameras along a camera axis R (the reference first): every rig scene has them
CAMERA_AXIS = (
    Feature("camera/rig/camera_names", "str", ("R",), "camera:rig.cameras", "text",
            doc="the rig's camera names, the reference first"),
    Feature("camera/rig/matrices_world", "float32", ("R", "T", 4, 4),
            "camera:rig.matrices_world", doc="camera → world per camera and frame (Blender "
            "camera axes)"),
    Feature("camera/rig/extrinsics_opencv", "float32", ("R", "T", 4, 4),
            "camera:rig.extrinsics_opencv", doc="world → OpenCV camera per camera and frame"),
    Feature("camera/rig/intrinsics_pixels", "float32", ("R", 3, 3),
            "camera:rig.intrinsics_pixels", doc="OpenCV pixel intrinsics per camera"),
    Feature("camera/rig/distortion_coefficients", "float32", ("R", 8),
            "camera:rig.distortion_coefficients", doc="OpenCV's order per camera (zeros: "
            "pinhole)"),
    Feature("camera/rig/mounts", "float32", ("R", 4, 4), "camera:rig.mount_matrices",
            doc="camera → rig (the reference camera's frame), Blender camera axes, metres"),
)


def camera_layer(camera: str, layer: str) -> str:
    """The scene-directory layer name of ``layer`` seen by rig camera ``camera``."""
    return f"{camera}_{layer}"


def tracks_file(camera: str) -> str:
    """The point-track archive of rig camera ``camera`` (the fields of ``tracks.npz``)."""
    return f"tracks_{camera}.npz"


def view_feature(f: Feature, camera: str) -> Feature | None:
    """``f``'s copy for rig camera ``camera`` (module doc), None for a feature that is the same
    for every camera (scene metadata, instance physics, collisions)."""
    kind, arg = f.source_kind, f.source_arg
    if kind in ("layer", "range"):
        source = f"{kind}:{camera}_{arg}"
    elif kind == "camera" and not arg.startswith("rig."):
        source = f"camera:rig.views.{camera}.{arg}"
    elif kind == "instance" and arg.split(".")[0] in VIEW_INSTANCE_FIELDS:
        source = f"instance:cameras.{camera}.{arg}"
    elif kind == "npz" and arg.startswith(TRACKS_FILE + ":"):
        source = f"npz:{tracks_file(camera)}:{arg.split(':', 1)[1]}"
    elif kind == "npz" and arg.startswith(EVENTS_H5_FILE + ":"):
        source = f"npz:{events_file(camera)}:{arg.split(':', 1)[1]}"
    else:
        return None
    name = (f"instances/cameras/{camera}/{f.name[len('instances/'):]}"
            if f.sequence == "instances/" else f"cameras/{camera}/{f.name}")
    return dataclasses.replace(f, name=name, source=source)


def rig_schema(schema: Schema, rig, extra_features=(), layer_names=None) -> Schema:
    """``schema`` (plus ``extra_features``, e.g. the tracks) with every per-camera feature for
    each further camera of ``rig``, their layers (``layer_names``: every layer a camera
    writes; default those the features read) and, for stereo, ``disparity``."""
    base = schema.extend(schema.name, tuple(f for f in extra_features if f.name not in schema))
    table = base.layer_formats
    layers, features = {}, []
    for camera in rig.names[1:]:
        for f in base.features:
            copy = view_feature(f, camera)
            if copy is not None:
                features.append(copy)
        for name in layer_names or base.image_layers():
            fmt = table[name]
            layers[camera_layer(camera, name)] = LayerFormat(
                camera_layer(camera, fmt.template), fmt.channels, fmt.kind)
    features += [f for f in CAMERA_AXIS if f.name not in base]
    if rig.kind == "stereo":
        features += [DISPARITY, BASELINE]
    names = ", ".join(rig.names)
    return base.extend(base.name, features, layers,
                       description=f"{base.description} Camera rig {rig.kind} ({names}).")


def ring_distance(camera, frame) -> float:
    """Metres along ``camera``'s view axis (at ``frame``) to its point nearest the origin."""
    with camera.at_frame(frame):
        m = camera.matrix_world
    return float(max(-m[:3, 3] @ -m[:3, 2], 1e-3))


@contextlib.contextmanager
def _own_fields(camera: str, assets):
    """Around an annotation that writes the reference camera's per-instance fields
    (:data:`VIEW_INSTANCE_FIELDS`) into ``asset.metadata``: what it writes goes to
    ``metadata["cameras"][camera]`` instead, the reference camera's values stay."""
    before = [dict(a.metadata) for a in assets]
    yield
    for asset, old in zip(assets, before, strict=True):
        mine = {k: v for k, v in asset.metadata.items() if k in VIEW_INSTANCE_FIELDS
                and (k not in old or v is not old[k])}
        if mine:
            views = dict(old.get("cameras", {}))
            views[camera] = {**views.get(camera, {}), **mine}
            asset.metadata = {**old, "cameras": views}


class RigOptions:
    """Mixin of a MOVi-like recipe: the camera-rig options (module doc)."""

    cameras = Option("mono", "camera rig: mono; stereo (left + right, a rectified pair baseline "
                     "metres apart, with a disparity layer); ring (num_cameras around the "
                     "look-at point); random (num_cameras at random about it, each looking at "
                     "it)", choices=RIGS)
    baseline = Option(DEFAULT_BASELINE, "cameras=stereo: metres between the two camera centres",
                      low=1e-3, high=100.0)
    num_cameras = Option(4, "cameras=ring|random: how many cameras", low=2, high=16)

    def check_rig(self) -> None:
        """Options a rig does not combine with fail here, in one line."""
        if self.cameras == "mono":
            return
        clash = next(((k, v) for k, v in (
            ("rolling_shutter", self.rolling_shutter),
            ("coverage_samples", self.coverage_samples),
            ("lens", self.lens if self.cameras == "stereo" and self.lens != "none" else None),
        ) if v), None)
        if clash:
            raise OptionError(f"{self.name}: cameras={self.cameras} does not combine with "
                              f"{clash[0]}={clash[1]} (a rig renders pinhole-time layers per "
                              "camera; stereo is a rectified pinhole pair); drop one")

    def build_rig(self, scene, seed: int = 0) -> None:
        """Mount the rig's cameras on the scene's (final) camera; nothing for mono (``seed``:
        the scene's, for ``cameras=random``)."""
        self._rig = None
        if self.cameras == "mono":
            return
        ref = scene.camera
        if self.cameras == "stereo":
            rig = rigs.stereo(ref, self.baseline)
        elif self.cameras == "random":
            rig = rigs.random_rig(ref, self.num_cameras, ring_distance(ref, scene.frame_start),
                                  np.random.RandomState([int(seed), RIG_STREAM]),
                                  scene.frame_start)
        else:
            rig = rigs.ring(ref, self.num_cameras, ring_distance(ref, scene.frame_start),
                            scene.frame_start)
        rig.build(scene)
        self._rig = rig

    def render_views(self, scene, renderer) -> dict:
        """{camera name: its layers} of every further camera (the renderer's own labels)."""
        rig, views = getattr(self, "_rig", None), {}
        if rig is None:
            return views
        for name, camera in list(rig.cameras.items())[1:]:
            scene.camera = camera
            views[name] = renderer.render()
        scene.camera = rig.reference
        return views

    def view_exposure_layers(self, scene, views) -> None:
        """With ``dof``: each further camera's ``defocus`` layer from its own ``z`` (every camera
        has the reference's thin lens, :data:`kubric.core.rig.SHARED_INTRINSICS`)."""
        if not self.dof:
            return
        from kubric.annotations.exposure import defocus
        for _, camera, view in self._each_view(scene, views):
            view["defocus"] = defocus(camera, view["z"])

    def view_event_files(self, scene, views, seed: int) -> dict:
        """With ``events``: {events_NAME.h5: bytes} of every further camera (its own frames and
        sub-frames; :meth:`~kubric.recipes.exposure_options.ExposureOptions.event_files`)."""
        files = {}
        for index, (name, _, view) in enumerate(self._each_view(scene, views), start=1):
            files.update(self.event_files(scene, view, seed, camera=(name, index)))
        return files

    def rig_order(self, scene, views):
        """annotate_instances' ``order`` (None for mono): visible pixels over every camera."""
        if not views:
            return None
        labels = instance_labels(scene.assets)
        other = sum(pixel_counts(v["segmentation"], labels).sum(axis=1) for v in views.values())
        totals = {a.uid: int(n) for a, n in zip(scene.assets, other, strict=True)}

        def order(candidates):
            total = [int(np.sum(a.metadata["visibility"])) + totals[a.uid] for a in candidates]
            ranked = sorted(range(len(candidates)), key=lambda i: -total[i])
            return [candidates[i] for i in ranked if total[i] > 0]
        return order

    def _each_view(self, scene, views):
        for name, view in views.items():
            scene.camera = self._rig.cameras[name]
            try:
                yield name, scene.camera, view
            finally:
                scene.camera = self._rig.reference

    def views_before_relabel(self, scene, layers, views, files) -> None:
        """Per camera, what needs the renderer's labels: extra layers, keypoints, tracks (the
        reference's surface points, ``files[tracks.npz]`` when written)."""
        frames = list(scene.frames)
        for name, camera, view in self._each_view(scene, views):
            extra.add_before_relabel(scene, view, self.extra_layers)
            with _own_fields(name, scene.assets):  # this camera's keypoints
                annotate_keypoints(scene, view)
            if TRACKS_FILE in files:
                files[tracks_file(name)] = tracks_archive(view_tracks(
                    files[TRACKS_FILE], camera, frames, view["depth"], view["segmentation"],
                    layers["segmentation"]))

    def views_after_relabel(self, scene, layers, views, instances) -> None:
        """Per camera: segmentation relabelled to ``instances``, per-instance boxes and
        positions, amodal layers; every layer into ``layers`` under its prefixed name; for
        stereo the disparity layer."""
        frames = list(scene.frames)
        for name, camera, view in self._each_view(scene, views):
            view["segmentation"] = kb.adjust_segmentation_idxs(view["segmentation"],
                                                               scene.assets, instances)
            view_instances(name, camera, view["segmentation"], instances, frames,
                           scene.resolution)
            with _own_fields(name, instances):  # this camera's amodal boxes
                extra.add_after_relabel(scene, view, self.extra_layers, instances)
            layers.update({camera_layer(name, k): v for k, v in view.items()})
        rig = getattr(self, "_rig", None)
        if rig is not None and rig.kind == "stereo":
            check_rectified(rig)
            layers["disparity"] = disparity(rig.reference, rig.cameras["right"],
                                            layers["depth"], frames)

    def rig_metadata(self, scene, document: dict) -> None:
        """``document["camera"]["rig"]``: the rig and each further camera's record."""
        rig = getattr(self, "_rig", None)
        if rig is None:
            return
        record = rig.metadata()
        infos = [document["camera"]] + [kb.get_camera_info(cam)
                                        for cam in list(rig.cameras.values())[1:]]
        record["views"] = dict(zip(rig.names[1:], infos[1:], strict=True))
        for key in ("matrices_world", "extrinsics_opencv", "intrinsics_pixels",
                    "distortion_coefficients"):  # along the camera axis
            record[key] = np.stack([np.asarray(info[key]) for info in infos])
        record["mount_matrices"] = np.stack(list(rig.mounts.values()))
        document["camera"]["rig"] = record
