"""The MOVi recipes' exposure options: depth of field (``dof``) and the exposure coverage of
motion blur (``coverage_samples``); the ground truth is :mod:`kubric.annotations.exposure`
(docs/conventions.md, "Time inside a frame").

* ``dof=True``: the camera gets a thin lens, f-number U(min_fstop, max_fstop) and focus
  distance U(min_focus_distance, max_focus_distance) metres along the view axis, drawn from an
  rng derived from the seed (so the rest of the scene is the seed's without DoF); the renderer
  must render depth of field (Blender: Cycles' thin lens); the scene gets the ``defocus`` layer
  and ``metadata.depth_of_field`` {use_dof, aperture_fstop, focus_distance}; with a camera rig
  every camera has that lens and its own ``NAME_defocus`` layer.
* ``coverage_samples=K`` (> 0): ``coverage.npz``, the fraction of the exposure (the shutter of
  ``metadata.motion_blur`` frames, centred on the frame) at which each pixel shows each instance,
  from K raycast sub-frame renders per frame (with any backend: the raycast backend supplies the
  sub-frames), and the ``exposure_flow`` layer: the seen surface point's motion from shutter open
  to close.
* ``rolling_shutter=d`` (> 0): the camera reads rows top to bottom over d frames
  (:mod:`kubric.core.rolling_shutter`); RGB, every layer and the tracks are at each row's time;
  raycast renders it all, blender renders RGB with Cycles' rolling shutter and takes the exact
  layers from raycast (:mod:`kubric.renderer.blender_rolling`; refused with motion blur or
  ``dof``); recorded in ``metadata.rolling_shutter``.
* ``events=True``: ``events.h5`` (DSEC's layout, :mod:`kubric.io.event_h5`), the event stream of
  the sensor model of :mod:`kubric.annotations.event_camera` (``event_threshold`` ±
  ``event_threshold_spread`` per pixel, drawn from an rng derived from the seed;
  ``event_refractory_us``, ``event_noise_rate``), t = 0 µs at frame_start; intensity from K
  samples per frame (``event_subframes=K``, default 8: the cheapest setting within the error
  stated in docs/render-cost.md): raycast sub-frame renders anchored at the rendered frames
  (``event_interpolation=raycast``: exact motion inside each frame interval, shifted per pixel
  so that every frame time has the delivered RGB's intensity —
  :func:`anchored_subframe_log_intensity`) or the rendered frames warped along the exact flow
  with its occlusions (``event_interpolation=flow``,
  :mod:`kubric.annotations.flow_interpolation`: the renderer's own shading, no extra render),
  or the rendered frames alone (``event_subframes=0``: log intensity linear between frame
  times); recorded in ``metadata.event_camera``. With a camera rig (``cameras=stereo|ring|
  random``) every camera is an event camera: each further camera's stream from its own frames in
  ``events_NAME.h5`` (e.g. ``events_right.h5``) with thresholds of its own, listed in
  ``metadata.event_camera.cameras``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kubric.annotations.exposure import COVERAGE_FILE, coverage_archive, defocus
from kubric.annotations.segmentation import adjust_segmentation_idxs
from kubric.pipeline import Option, OptionError

#: when row y (pixel height; centres at r + 0.5) of frame f is read (kubric.core.rolling_shutter)
ROW_TIME = "t = f + duration * (y / H - 1/2); y = r + 0.5 for row r"
#: tags of the rngs the lens and the event thresholds are drawn from (derived from the seed:
#: RandomState([seed, tag]))
LENS_RNG_TAG, EVENTS_RNG_TAG = 0x6C656E73, 0x65767473


class ExposureOptions:
    """Mixin of the exposure options (module doc) for a recipe with a ``renderer`` option."""

    dof = Option(False, "depth of field: a thin-lens camera (f-number and focus distance drawn "
                 "from the ranges below); writes the defocus layer")
    min_fstop = Option(1.4, "smallest f-number with dof=True", low=0.1, high=64.0)
    max_fstop = Option(5.6, "largest f-number with dof=True", low=0.1, high=64.0)
    min_focus_distance = Option(6.0, "nearest focus distance with dof=True (m, along the view "
                                "axis)", low=0.1, high=1000.0)
    max_focus_distance = Option(14.0, "farthest focus distance with dof=True (m)", low=0.1,
                                high=1000.0)
    coverage_samples = Option(0, "sub-frame raycast renders per frame for coverage.npz, the "
                              "fraction of the exposure each pixel shows each instance "
                              "(0 = none)", low=0, high=256)
    rolling_shutter = Option(0.0, "rolling-shutter readout time from the image's top edge to "
                             "its bottom edge (frames; 0 = global shutter; not with motion "
                             "blur or dof)", low=0.0, high=10.0)
    events = Option(False, "write events.h5: an event-camera stream (DSEC layout; with a camera "
                    "rig also events_NAME.h5 per further camera)")
    event_subframes = Option(8, "event intensity samples per frame: 0 = the rendered frames, "
                             "log intensity linear between them; K = K sub-frames (see "
                             "event_interpolation); 8 is the cheapest within the stated error "
                             "(docs/render-cost.md)",
                             low=0, high=64)
    event_interpolation = Option("raycast", "how event_subframes=K makes the samples between "
                                 "two frames: raycast = sub-frame renders by the raycast backend "
                                 "(exact motion, its Lambert shading) anchored at the rendered "
                                 "frames; flow = the rendered "
                                 "frames warped along the exact flow with its occlusions (the "
                                 "renderer's own shading, no extra render)",
                                 choices=("raycast", "flow"))
    event_threshold = Option(0.2, "event contrast threshold C± (log intensity)", low=0.01,
                             high=5.0)
    event_threshold_spread = Option(0.03, "per-pixel standard deviation of the thresholds",
                                    low=0.0, high=1.0)
    event_refractory_us = Option(100.0, "event refractory period (µs)", low=0.0, high=1e6)
    event_noise_rate = Option(0.0, "noise events per pixel per second (Poisson, random "
                              "polarity; 0 = none)", low=0.0, high=1e5)

    def exposure_requests(self) -> dict[str, str]:
        """Renderer capabilities the exposure options ask for (see ``renderer_requests``)."""
        out = {"depth_of_field": "dof=True"} if self.dof else {}
        if self.rolling_shutter:
            out["rolling_shutter"] = f"rolling_shutter={self.rolling_shutter}"
        return out

    def set_rolling_shutter(self, scene) -> None:
        """With ``rolling_shutter`` > 0: the camera's readout time, recorded in
        ``scene.metadata["rolling_shutter"]`` {duration (frames), row_time (the convention)}."""
        if not self.rolling_shutter:
            return
        scene.camera.rolling_shutter_duration = float(self.rolling_shutter)
        scene.metadata["rolling_shutter"] = {"duration": float(self.rolling_shutter),
                                             "row_time": ROW_TIME}

    def check_exposure(self) -> None:
        """``coverage_samples`` needs a shutter: a recipe with ``max_motion_blur`` > 0; a
        rolling shutter goes with neither motion blur nor ``dof``."""
        if self.coverage_samples and getattr(self, "max_motion_blur", 0.0) <= 0:
            raise OptionError(f"{self.name}: option coverage_samples={self.coverage_samples} "
                              "needs a shutter: a recipe with max_motion_blur > 0 (movi_f)")
        blur = getattr(self, "max_motion_blur", 0.0)
        for asked, other in ((blur > 0, f"max_motion_blur={blur}"), (self.dof, "dof=True")):
            if self.rolling_shutter and asked:
                raise OptionError(f"{self.name}: option rolling_shutter={self.rolling_shutter} "
                                  f"with {other}: no renderer renders both; allowed: "
                                  "rolling_shutter=0 or the other off")

    def sample_lens(self, scene, seed: int) -> None:
        """With ``dof``: the camera's thin lens, from an rng derived from ``seed``; recorded in
        ``scene.metadata["depth_of_field"]``."""
        if not self.dof:
            return
        rng = np.random.RandomState([int(seed), LENS_RNG_TAG])
        camera = scene.camera
        camera.use_dof = True
        camera.aperture_fstop = float(rng.uniform(self.min_fstop, self.max_fstop))
        camera.focus_distance = float(rng.uniform(self.min_focus_distance,
                                                  self.max_focus_distance))
        scene.metadata["depth_of_field"] = {"use_dof": True,
                                            "aperture_fstop": camera.aperture_fstop,
                                            "focus_distance": camera.focus_distance}

    def add_exposure_layers(self, scene, layers: dict, shutter: float) -> None:
        """With ``dof``: ``layers["defocus"]`` from the rendered ``z`` layer; with
        ``coverage_samples``: ``layers["exposure_flow"]`` over the shutter (raycast)."""
        if self.dof:
            layers["defocus"] = defocus(scene.camera, layers["z"])
        if self.coverage_samples:
            from kubric.renderer.raycast_subframes import exposure_flow
            layers["exposure_flow"] = exposure_flow(scene, list(scene.frames), shutter)

    def subframe_labels(self, scene, shutter: float):
        """With ``coverage_samples``: (T, K, H, W) raw labels at the shutter's sub-frame times
        (None without)."""
        if not self.coverage_samples:
            return None
        from kubric.renderer.raycast_subframes import shutter_segmentation
        return shutter_segmentation(scene, scene.frames, shutter, self.coverage_samples)

    def event_files(self, scene, layers: dict, seed: int, camera: tuple | None = None) -> dict:
        """With ``events``: {events.h5: bytes}; the sensor in ``scene.metadata["event_camera"]``.

        ``camera``: (name, index ≥ 1) of a rig's further camera whose ``layers`` these are
        (``scene.camera`` is that camera): its stream goes to ``events_NAME.h5``, its thresholds
        are drawn from an rng of its own (``RandomState([seed, tag, index])``: the reference
        camera's stay those of the mono scene), and its file and event count are recorded in
        ``scene.metadata["event_camera"]["cameras"][NAME]``."""
        if not self.events:
            return {}
        from kubric.annotations import event_camera as ev
        from kubric.io.event_h5 import EVENTS_H5_FILE, encode_events, events_file
        model = ev.SensorModel(self.event_threshold, self.event_threshold,
                               self.event_threshold_spread,
                               refractory_us=self.event_refractory_us,
                               noise_rate_hz=self.event_noise_rate)
        frames = list(scene.frames)
        k = self.event_subframes if len(frames) > 1 else 0  # (one frame: no events either way)
        times = frames[0] + np.arange((len(frames) - 1) * k + 1) / max(k, 1)
        if k and self.event_interpolation == "flow":
            from kubric.annotations.flow_interpolation import interpolate_sequence
            log_i = ev.srgb_to_log_intensity(np.clip(interpolate_sequence(
                layers["rgba"][..., :3], layers["forward_flow"], layers["backward_flow"],
                layers["depth"], k), 0, 255), model.eps)
        elif k:
            log_i = anchored_subframe_log_intensity(scene, frames, k, layers["rgba"], model.eps)
        else:
            log_i = ev.srgb_to_log_intensity(np.clip(layers["rgba"][..., :3], 0, 255),
                                             model.eps)
        h, w = log_i.shape[1:3]
        rng = np.random.RandomState([int(seed), EVENTS_RNG_TAG, *([camera[1]] if camera else [])])
        thresholds = model.thresholds(h, w, rng)
        times_us = ev.frame_times_us(times, scene.frame_start, scene.frame_rate)
        events = ev.simulate(log_i, times_us, thresholds, model)
        events = ev.add_noise(events, h, w, times_us[0], times_us[-1], model, rng)
        name = events_file(camera[0]) if camera else EVENTS_H5_FILE
        sensor = {**dataclasses.asdict(model), "file": name,
                  "source": EVENT_SOURCES[self.event_interpolation].format(k=k)
                  if k else "rendered frames", "num_events": len(events["t"])}
        if camera:
            record = scene.metadata.setdefault("event_camera", {}).setdefault("cameras", {})
            record[camera[0]] = {"file": name, "num_events": sensor["num_events"]}
        else:
            scene.metadata["event_camera"] = {**scene.metadata.get("event_camera", {}), **sensor}
        attrs = {k: v for k, v in sensor.items() if k != "num_events"}
        return {name: encode_events(events, thresholds, attrs)}

    @staticmethod
    def coverage_files(scene, labels, instances, shutter: float) -> dict:
        """{coverage.npz: arrays} with ``labels`` relabelled to ``instances`` ({} for None)."""
        if labels is None:
            return {}
        t, k, h, w = labels.shape
        relabelled = adjust_segmentation_idxs(labels.reshape(t * k, h, w), scene.assets,
                                              instances).reshape(t, k, h, w)
        return {COVERAGE_FILE: coverage_archive(relabelled, shutter)}


#: metadata.event_camera.source per event_interpolation (k: samples per frame)
EVENT_SOURCES = {"raycast": "raycast sub-frames K={k}, anchored at the rendered frames",
                 "flow": "flow sub-frames K={k}"}


def anchored_subframe_log_intensity(scene, frames: list, k: int, rgba, eps: float):
    """Log intensity ((T − 1)·k + 1, H, W) at ``frames[0] + i / k``: the raycast backend's
    sub-frame renders, shifted per pixel by a correction linear in time between frame times
    that makes them equal the rendered ``rgba`` frames (T, H, W, ≥3) at every frame time. So the
    motion inside a frame interval (edges crossing, shadows moving) is the raycast render's and
    the change from frame to frame is exactly the delivered RGB's (with the raycast backend the
    correction is zero: its frames are those sub-frames)."""
    from kubric.annotations.event_camera import srgb_to_log_intensity
    from kubric.renderer.raycast_subframes import subframe_layers
    sub = subframe_layers(scene, frames[:-1], np.arange(k) / k, ("rgba",))["rgba"]
    sub = np.concatenate([sub.reshape((-1,) + sub.shape[2:]),
                          subframe_layers(scene, frames[-1:], [0.0], ("rgba",))["rgba"][0]])
    log_sub = srgb_to_log_intensity(np.clip(sub[..., :3], 0, 255), eps)
    log_frames = srgb_to_log_intensity(np.clip(rgba[..., :3], 0, 255), eps)
    offset = log_frames - log_sub[::k]  # (T, H, W): the frames minus the raycast at frame times
    s = (np.arange(len(log_sub)) % k / k)[:, None, None]
    a = np.arange(len(log_sub)) // k
    upper = np.minimum(a + 1, len(offset) - 1)
    return log_sub + (1 - s) * offset[a] + s * offset[upper]
