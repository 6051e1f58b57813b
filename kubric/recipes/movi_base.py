"""The MOVi pipeline shared by the recipes ``movi_a`` … ``movi_f`` (docs/recipes.md).

One scene = one seed: every random number comes from ``numpy.random.RandomState(seed)`` in a fixed
order. Steps (each a method the variants override):

1. ``open_sources``: asset sources (KuBasic; for C–F the mesh collection and the HDRIs);
2. ``build_background``: floor / dome, lamps, ambient light, backdrop;
3. ``build_camera``: fixed, random in a half-sphere shell, or moving on a straight line; its
   lens (``lens=``, :mod:`kubric.recipes.lens_options`) is set after step 4;
4. ``add_objects``: objects placed without overlap by the simulator (D–F: static objects first
   settle for ``settle_frames`` frames with friction 1 and restitution 0, then are stopped);
5. simulate frames ``0 .. frame_end + 1`` (so flow is defined at both ends of the rendered range);
6. render ``frame_start .. frame_end`` with Blender (linked after the simulation, so it sees the
   final trajectories only); with ``cameras=stereo|ring|random`` the rig's further cameras are mounted
   on the camera after the simulation and render every layer too (:mod:`kubric.recipes.rig_options`);
7. annotations: visibility → instance list sorted by visible pixels → segmentation relabelled →
   2D boxes; write the layers, ``metadata.json`` and ``events.json``; with ``tracks=N`` or
   ``track_queries`` also ``tracks.npz`` (:mod:`kubric.annotations.tracks`, docs/tracks.md).

Physics constants (upstream MOVi's): dynamic objects spawn in (−5,−5,1)–(5,5,5) with velocity
U([−4,−4,0],[4,4,0]) − [x, y, 0]; static objects in (−7,−7,0)–(7,7,10); floor μ 0.3, e 0.5.
"""

from __future__ import annotations

import abc
import logging
import pathlib
import tempfile

import numpy as np

import kubric as kb
from kubric.annotations.track_files import tracks_archive
from kubric.annotations.tracks import scene_tracks
from kubric.io.scene_dir import BLEND_FILE, BULLET_FILE, TRACKS_FILE
from kubric.io.scene_writer import write_scene
from kubric.pipeline import Option, OptionError, Recipe, resolution
from kubric.recipes import extra_layers as extra
from kubric.recipes.common import (
    annotate_instances,
    check_min_max,
    check_source_options,
    kubasic_sources,
    scene_documents,
    source_location,
)
from kubric.recipes.exposure_options import ExposureOptions
from kubric.recipes.exposure_schema import DOF_FEATURES, EVENT_FEATURES
from kubric.recipes.lens_options import LensOptions
from kubric.recipes.movi_schema import TRACK_FEATURES
from kubric.recipes.render_quality import RenderQuality
from kubric.recipes.rig_options import RigOptions, rig_schema

DYNAMIC_SPAWN_REGION = ((-5.0, -5.0, 1.0), (5.0, 5.0, 5.0))
STATIC_SPAWN_REGION = ((-7.0, -7.0, 0.0), (7.0, 7.0, 10.0))
VELOCITY_RANGE = ((-4.0, -4.0, 0.0), (4.0, 4.0, 0.0))
FLOOR_FRICTION, FLOOR_RESTITUTION = 0.3, 0.5
#: every MOVi camera: focal length and sensor width (mm), as upstream's MOVi workers.
CAMERA_FOCAL_LENGTH, CAMERA_SENSOR_WIDTH = 35.0, 32.0
#: (inner, outer) radius (m) of the half-sphere shell of a random camera (MOVi-B–D) and of a moving
#: camera's path (MOVi-E/F); a camera is at least CAMERA_MIN_HEIGHT (m) above the floor.
CAMERA_SHELL, MOVING_CAMERA_SHELL, CAMERA_MIN_HEIGHT = (7.0, 9.0), (8.0, 12.0), 0.1
logger = logging.getLogger(__name__)


def new_camera():
    """The MOVi camera (CAMERA_FOCAL_LENGTH, CAMERA_SENSOR_WIDTH), not yet placed."""
    return kb.PerspectiveCamera(name="camera", focal_length=CAMERA_FOCAL_LENGTH,
                                sensor_width=CAMERA_SENSOR_WIDTH)




def place_without_overlap(obj, simulator, region, rng, max_trials: int = 1000) -> bool:
    """:func:`kubric.move_until_no_overlap` (random rotation, bounding box inside ``region``, no
    overlap), except that an object with no free place after ``max_trials`` is removed from the
    scene and counted in ``scene.metadata["dropped_objects"]`` instead of making the seed unusable.
    Returns True when placed.
    """
    try:
        kb.move_until_no_overlap(obj, simulator, spawn_region=region, max_trials=max_trials,
                                 rng=rng)
        return True
    except RuntimeError as err:
        logger.warning("%s: dropped (%s)", obj.uid, err)
    for scene in list(obj.scenes):
        scene.remove(obj)
        scene.metadata["dropped_objects"] = scene.metadata.get("dropped_objects", 0) + 1
    return False


class MoviBase(ExposureOptions, RenderQuality, Recipe, LensOptions, RigOptions):
    """Common options and steps of the MOVi recipes (not registered itself).

    ``schema``: the variant's output contract (:mod:`kubric.recipes.movi_schema`).
    """

    schema = None

    resolution = Option((256, 256), "(width, height) in pixels: N or WxH", type=resolution)
    frame_start = Option(1, "first rendered frame", low=0, limit=10000)
    frame_end = Option(24, "last rendered frame (simulation runs to frame_end + 1)", low=1, limit=10000)
    frame_rate = Option(12, "frames per second", low=1, limit=1000)
    step_rate = Option(240, "physics steps per second (a multiple of frame_rate)", low=1, limit=100000)
    kubasic_source = Option(None, "KuBasic asset source folder or URL (default: built locally)",
                            type=source_location)
    save_state = Option(False, "also write scene.blend (animated) and scene.bullet (initial "
                        "physics state)")
    tracks = Option(0, "point tracks to sample and write to tracks.npz (0 = none; docs/tracks.md)",
                    low=0)
    track_queries = Option(None, "file of given track queries, rows (t, y, x) in pixels (.npy, "
                           ".json or text); instead of sampling", type=pathlib.Path,
                           must_exist=True)
    track_stride = Option(4, "grid stride (frames and pixels) of the track query sampling", low=1)
    extra_layers = Option((), "opt-in ground truth: comma-separated "
                          f"{', '.join(extra.EXTRA_LAYERS)} (docs/conventions.md)",
                          type=extra.extra_layers)
    track_max_fraction = Option(0.1, "most tracks per object or background, as a fraction of "
                                "its grid points (TAP-Vid: 0.1)", low=0.0, high=1.0)

    # ------------------------------------------------------------------ checks
    def check(self) -> None:
        if self.frame_end < self.frame_start:
            raise OptionError(f"{self.name}: option frame_end={self.frame_end} must be ≥ "
                              f"frame_start={self.frame_start}")
        if self.step_rate % self.frame_rate:
            raise OptionError(f"{self.name}: option step_rate={self.step_rate} must be a multiple "
                              f"of frame_rate={self.frame_rate}")
        check_source_options(self)
        self.check_lens()
        if self.lens != "none" and self.dof:
            raise OptionError(f"{self.name}: lens={self.lens} with dof=True: a lens-model camera "
                              "is a pinhole aperture (no depth of field); drop one")
        self.check_renderer()
        self.check_tracks()
        check_min_max(self)
        self.check_exposure()
        self.check_rig()

    def renderer_requests(self) -> dict[str, str]:
        out = super().renderer_requests()
        if self.save_state:
            out["save_state"] = "save_state=True"
        if getattr(self, "max_motion_blur", 0.0) > 0:
            out["motion_blur"] = f"max_motion_blur={self.max_motion_blur}"
        return {**out, **self.exposure_requests(), **self.lens_requests()}

    def check_tracks(self) -> None:
        """Bad track options fail here, before anything renders (one line)."""
        from kubric.annotations import tracks as tr
        w, h = self.resolution
        num_frames = self.frame_end - self.frame_start + 1
        if self.track_queries is not None:
            if self.tracks:
                raise OptionError(f"{self.name}: give either tracks={self.tracks} or "
                                  "track_queries, not both")
            try:
                self._queries = tr.check_queries(tr.load_queries(self.track_queries),
                                                 num_frames, w, h)
            except ValueError as err:
                raise OptionError(f"{self.name}: option track_queries: {err}") from None
            return
        available = tr.grid_points_available(num_frames, h, w, self.track_stride)
        if self.tracks > available:
            raise OptionError(f"{self.name}: option tracks={self.tracks} is more than the "
                              f"{available} query points available ({num_frames} frames × "
                              f"{h}×{w} px on a grid of stride {self.track_stride})")

    def prepare(self) -> None:
        """Build / open the asset sources once before parallel workers start."""
        self.open_sources()

    # ------------------------------------------------------------------ steps
    def open_sources(self) -> dict:
        return kubasic_sources(self.kubasic_source)

    @abc.abstractmethod
    def build_background(self, scene, rng, sources) -> str:
        """Add floor / lights; return the background description for the metadata."""

    @abc.abstractmethod
    def add_objects(self, scene, simulator, rng, sources) -> None:
        """Add the objects (placed without overlap, with their initial velocities)."""

    def build_camera(self, scene, rng) -> None:
        """Default: random position in the half-sphere shell r ∈ CAMERA_SHELL ([7, 9]), looking at
        the origin."""
        camera = new_camera()
        camera.position = kb.sample_point_in_half_sphere_shell(*CAMERA_SHELL, CAMERA_MIN_HEIGHT,
                                                               rng=rng)
        camera.look_at((0.0, 0.0, 0.0))
        scene.camera = camera

    def finish_scene(self, scene, seed: int) -> None:
        """After the scene is populated, before the simulation (default: nothing)."""

    def motion_blur(self, rng) -> float:
        """Shutter length in frames (0 = none)."""
        return 0.0

    def add_dome(self, scene, sources, material):
        dome = sources["kubasic"].create("dome", name="dome", static=True, background=True,
                                         friction=FLOOR_FRICTION,
                                         restitution=FLOOR_RESTITUTION)
        dome.material = material
        scene.add(dome)
        return dome

    @staticmethod
    def initial_velocity(obj, rng) -> None:
        """Random horizontal velocity, biased towards the centre (upstream MOVi's rule)."""
        low, high = (np.asarray(v) for v in VELOCITY_RANGE)
        x, y, _ = obj.position
        obj.velocity = rng.uniform(low, high) - np.array([x, y, 0.0])

    # ------------------------------------------------------------------ the pipeline
    def make_scene(self):
        scene = kb.Scene(resolution=self.resolution, frame_start=self.frame_start,
                         frame_end=self.frame_end)
        scene.set_rates(self.frame_rate, self.step_rate)
        scene.metadata["dropped_objects"] = 0
        return scene

    def populate(self, scene, simulator, rng, sources) -> tuple[str, float]:
        """Steps 2–4 (background, camera, motion blur, objects placed): everything before the
        simulation runs. Returns (background description, shutter length in frames)."""
        background = self.build_background(scene, rng, sources)
        self.build_camera(scene, rng)
        blur = self.motion_blur(rng)
        self.add_objects(scene, simulator, rng, sources)
        return background, blur

    def generate(self, seed: int, out_dir: pathlib.Path) -> None:
        rng = np.random.RandomState(seed)
        sources = self.open_sources()
        scene = self.make_scene()
        with tempfile.TemporaryDirectory(prefix="kubric_movi_") as scratch:
            simulator = kb.simulator.PyBullet(scene, scratch)
            background, blur = self.populate(scene, simulator, rng, sources)
            self.finish_scene(scene, seed)  # material_source= (MOVi-C–F)
            self.sample_lens(scene, seed)  # dof=True (an rng derived from the seed)
            self.set_rolling_shutter(scene)  # rolling_shutter=d
            scene.camera.lens = self.make_lens(rng)  # drawn after the rest (lens_options)
            state = pathlib.Path(scratch) / "state"  # saved here, moved in by write_scene
            files = {}
            if self.save_state:  # the initial state, before the simulation (as upstream)
                files[BULLET_FILE] = simulator.save_state(state / BULLET_FILE)
            _, collisions = simulator.run(frame_start=0, frame_end=scene.frame_end + 1)
            self.build_rig(scene, seed)  # cameras=stereo|ring|random (rig_options): on the camera
            renderer = kb.renderer.create(self.renderer, scene, scratch,
                                          **self.renderer_settings(motion_blur=blur))
            layers = renderer.render()
            self._views = self.render_views(scene, renderer)  # the rig's other cameras
            self.add_exposure_layers(scene, layers, blur)  # dof, coverage_samples
            self.view_exposure_layers(scene, self._views)  # dof on every camera of a rig
            self._subframes = (self.subframe_labels(scene, blur), blur)
            files.update(self.event_files(scene, layers, seed))  # events=True
            files.update(self.view_event_files(scene, self._views, seed))  # … on every camera
            if self.save_state:
                files[BLEND_FILE] = renderer.save_state(state / BLEND_FILE)
            render_settings = self.render_metadata(renderer)
            self.write_outputs(scene, layers, collisions, seed, out_dir, background,
                               render_settings, files=files)
            simulator.close()

    def track_archive(self, scene, layers, visible, seed) -> dict:
        """The point tracks of ``tracks.npz`` (computed before the segmentation is relabelled);
        queries sampled with an rng derived from the seed, so adding tracks changes nothing else
        in the scene."""
        rng = np.random.RandomState([int(seed), 0x7472616B])
        tracks = scene_tracks(scene, layers, visible, rng, num_tracks=self.tracks,
                              queries=getattr(self, "_queries", None), stride=self.track_stride,
                              max_fraction=self.track_max_fraction)
        return tracks_archive(tracks)

    def write_outputs(self, scene, layers, collisions, seed, out_dir, background,
                      render_settings, files=None) -> list:
        """Annotations + files (``files``: more of the scene's files, e.g. the saved state, as
        :func:`~kubric.io.scene_writer.write_scene` takes them); returns the instance list
        (sorted by visible pixels)."""
        candidates = [a for a in scene.foreground_assets if isinstance(a, kb.PhysicalObject)]
        if "uv" in layers:
            render_settings = {**render_settings, "uv": "wrapped modulo 1 (textures repeat)"}
        files = dict(files or {})
        views = getattr(self, "_views", {})  # cameras=stereo|ring: {camera: its layers}
        with_tracks = bool(self.tracks or self.track_queries is not None)

        def before_relabel(visible):
            if with_tracks:
                files[TRACKS_FILE] = self.track_archive(scene, layers, visible, seed)
            self.views_before_relabel(scene, layers, views, files)
        extra.add_before_relabel(scene, layers, self.extra_layers)
        visible = annotate_instances(scene, layers, candidates, order=self.rig_order(scene, views),
                                     before_relabel=before_relabel)
        subframes, shutter = getattr(self, "_subframes", (None, 0.0))  # coverage_samples=K
        files.update(self.coverage_files(scene, subframes, visible, shutter))
        extra.add_after_relabel(scene, layers, self.extra_layers, visible)
        self.views_after_relabel(scene, layers, views, visible)
        metadata, events = scene_documents(self, scene, seed, visible, collisions,
                                           background=background, renderer=render_settings)
        self.rig_metadata(scene, metadata)
        schema = extra.schema_with(self.schema, self.extra_layers)
        if views:
            schema = rig_schema(schema, self._rig, (*(TRACK_FEATURES if with_tracks else ()),
                                                    *(EVENT_FEATURES if self.events else ()),
                                                    *(DOF_FEATURES if self.dof else ())),
                                list(next(iter(views.values()))))
        write_scene(schema, out_dir, layers, metadata, events, files=files)
        return visible
